//! Linear expressions over FMU variables, as written in the system file.
//!
//! A constraint's position, velocity and acceleration levels and the inputs a
//! multiplier drives are written as signed sums of `instance.variable` terms:
//!
//! ```text
//! mass2.x - mass1.x
//! 0.5*body.r - 2 * other.r + der(link.v)
//! ```
//!
//! `der(instance.variable)` and `der(instance.variable, 2)` read the first or
//! second time derivative of an output through `fmi2GetRealOutputDerivatives`.

use std::fmt;

/// One `coefficient · instance.variable` term of a [`LinearExpr`].
#[derive(Debug, Clone, PartialEq)]
pub struct Term {
    /// Multiplies the variable's value (the sign of the term included).
    pub coefficient: f64,
    /// Name of the FMU instance in the system file.
    pub instance: String,
    /// Variable name as it appears in the FMU's `modelDescription.xml`.
    pub variable: String,
    /// 0 for the value itself, 1 or 2 for an output derivative read with
    /// `fmi2GetRealOutputDerivatives`.
    pub derivative_order: u32,
}

/// A signed sum of terms.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LinearExpr {
    /// The terms, in the order they were written.
    pub terms: Vec<Term>,
}

/// Why a linear expression could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot read expression {}: {reason} at column {column}", quote(text, Some(*column), "'", "'"))]
pub struct ExprError {
    /// The whole expression (quoted in the message as [`quote`] cuts it).
    pub text: String,
    /// 1-based column of the offending character.
    pub column: usize,
    /// What was expected there.
    pub reason: String,
}

/// The most characters of a user's text (an expression, a value) that a
/// message quotes.
pub const QUOTE_LIMIT: usize = 200;

/// `text` between `open` and `close`, as a message quotes it: whole up to
/// [`QUOTE_LIMIT`] characters. A longer text is cut to the [`QUOTE_LIMIT`]
/// characters around `column` (1-based; the start without one), with `…` where
/// it is cut, `»` before the character at `column`, and its length after.
pub fn quote(text: &str, column: Option<usize>, open: &str, close: &str) -> String {
    let n = text.chars().count();
    if n <= QUOTE_LIMIT {
        return format!("{open}{text}{close}");
    }
    let at = column.map(|c| c.saturating_sub(1).min(n));
    let start = at.map_or(0, |a| a.saturating_sub(QUOTE_LIMIT * 3 / 4));
    let end = (start + QUOTE_LIMIT).min(n);
    let mut shown = String::with_capacity(QUOTE_LIMIT * 4 + 8);
    if start > 0 {
        shown.push('…');
    }
    for (i, c) in text.chars().enumerate().take(end).skip(start) {
        if Some(i) == at {
            shown.push('»');
        }
        shown.push(c);
    }
    if at == Some(n) {
        shown.push('»');
    }
    if end < n {
        shown.push('…');
    }
    let marked = if at.is_some() {
        ", » marks the column"
    } else {
        ""
    };
    format!("{open}{shown}{close} ({n} characters{marked})")
}

impl LinearExpr {
    /// Parse `a.b - 2*c.d + der(e.f, 2)`.
    pub fn parse(text: &str) -> Result<Self, ExprError> {
        Parser { text, pos: 0 }.expression()
    }
}

impl fmt::Display for Term {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let var = format!("{}.{}", self.instance, self.variable);
        match self.derivative_order {
            0 => write!(f, "{var}"),
            1 => write!(f, "der({var})"),
            n => write!(f, "der({var}, {n})"),
        }
    }
}

impl fmt::Display for LinearExpr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, t) in self.terms.iter().enumerate() {
            let (sign, mag) = if t.coefficient < 0.0 {
                ("-", -t.coefficient)
            } else {
                ("+", t.coefficient)
            };
            if i == 0 {
                if sign == "-" {
                    write!(f, "-")?;
                }
            } else {
                write!(f, " {sign} ")?;
            }
            if mag != 1.0 {
                write!(f, "{mag}*")?;
            }
            write!(f, "{t}")?;
        }
        Ok(())
    }
}

struct Parser<'a> {
    text: &'a str,
    pos: usize,
}

impl<'a> Parser<'a> {
    fn fail<T>(&self, reason: impl Into<String>) -> Result<T, ExprError> {
        Err(ExprError {
            text: self.text.to_string(),
            column: self.text[..self.pos].chars().count() + 1,
            reason: reason.into(),
        })
    }

    fn rest(&self) -> &'a str {
        &self.text[self.pos..]
    }

    fn skip_ws(&mut self) {
        let trimmed = self.rest().trim_start();
        self.pos = self.text.len() - trimmed.len();
    }

    fn eat(&mut self, c: char) -> bool {
        self.skip_ws();
        if self.rest().starts_with(c) {
            self.pos += c.len_utf8();
            true
        } else {
            false
        }
    }

    fn expression(mut self) -> Result<LinearExpr, ExprError> {
        let mut terms = Vec::new();
        self.skip_ws();
        if self.rest().is_empty() {
            return self.fail("expected at least one term");
        }
        let mut sign = 1.0;
        if self.eat('-') {
            sign = -1.0;
        } else {
            self.eat('+');
        }
        loop {
            terms.push(self.term(sign)?);
            self.skip_ws();
            if self.rest().is_empty() {
                break;
            }
            sign = if self.eat('+') {
                1.0
            } else if self.eat('-') {
                -1.0
            } else {
                return self.fail("expected '+' or '-'");
            };
        }
        Ok(LinearExpr { terms })
    }

    fn term(&mut self, sign: f64) -> Result<Term, ExprError> {
        self.skip_ws();
        let mut coefficient = sign;
        if self
            .rest()
            .starts_with(|c: char| c.is_ascii_digit() || c == '.')
        {
            let at = self.pos;
            coefficient *= self.number()?;
            if !self.eat('*') {
                self.skip_ws();
                if self.rest().is_empty() || self.rest().starts_with(['+', '-']) {
                    let constant = self.text[at..self.pos].trim().to_string();
                    self.pos = at;
                    return self.fail(format!(
                        "a constant term ({constant}) is not allowed: an expression is a sum of \
                         terms coefficient*instance.variable (an offset belongs in an FMU output)"
                    ));
                }
                return self.fail("expected '*' after a coefficient");
            }
            self.skip_ws();
        }
        if self.rest().starts_with("der(") {
            self.pos += 4;
            let (instance, variable) = self.reference()?;
            let mut order = 1;
            if self.eat(',') {
                self.skip_ws();
                let at = self.pos;
                let n = self.number()?;
                if n != 1.0 && n != 2.0 {
                    self.pos = at;
                    return self.fail("derivative order must be 1 or 2");
                }
                order = n as u32;
            }
            if !self.eat(')') {
                return self.fail("expected ')'");
            }
            return Ok(Term {
                coefficient,
                instance,
                variable,
                derivative_order: order,
            });
        }
        let (instance, variable) = self.reference()?;
        Ok(Term {
            coefficient,
            instance,
            variable,
            derivative_order: 0,
        })
    }

    fn number(&mut self) -> Result<f64, ExprError> {
        let rest = self.rest();
        let mut end = 0;
        let bytes = rest.as_bytes();
        while end < bytes.len() {
            let c = bytes[end] as char;
            let exp_sign =
                (c == '-' || c == '+') && end > 0 && matches!(bytes[end - 1] as char, 'e' | 'E');
            if c.is_ascii_digit() || c == '.' || c == 'e' || c == 'E' || exp_sign {
                end += 1;
            } else {
                break;
            }
        }
        match rest[..end].parse::<f64>() {
            Ok(v) if v.is_finite() => {
                self.pos += end;
                Ok(v)
            }
            _ => self.fail("expected a number"),
        }
    }

    /// `instance.variable`, where the variable may itself contain dots and
    /// brackets (`body.r[1]`, `marker.p.x`, `ss.A[2,3]`: commas inside
    /// brackets), or be quoted (`inst.'a b'`).
    fn reference(&mut self) -> Result<(String, String), ExprError> {
        self.skip_ws();
        let rest = self.rest();
        let ident_len = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if ident_len == 0 || rest.starts_with(|c: char| c.is_ascii_digit()) {
            return self.fail("expected an instance name");
        }
        let instance = rest[..ident_len].to_string();
        self.pos += ident_len;
        if !self.rest().starts_with('.') {
            return self.fail(format!("expected '.' and a variable after '{instance}'"));
        }
        self.pos += 1;
        let rest = self.rest();
        let variable = if let Some(quoted) = rest.strip_prefix('\'') {
            match quoted.find('\'') {
                Some(end) => {
                    self.pos += end + 2;
                    quoted[..end].to_string()
                }
                None => return self.fail("unterminated quoted variable name"),
            }
        } else {
            let mut depth = 0;
            let len = rest
                .find(|c: char| {
                    match c {
                        '[' => depth += 1,
                        ']' => depth -= 1,
                        ',' | ' ' if depth > 0 => return false,
                        _ => {}
                    }
                    !(c.is_alphanumeric() || matches!(c, '_' | '.' | '[' | ']'))
                })
                .unwrap_or(rest.len());
            if len == 0 {
                return self.fail("expected a variable name");
            }
            self.pos += len;
            rest[..len].to_string()
        };
        Ok((instance, variable))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(c: f64, i: &str, v: &str, d: u32) -> Term {
        Term {
            coefficient: c,
            instance: i.into(),
            variable: v.into(),
            derivative_order: d,
        }
    }

    #[test]
    fn the_oscillator_constraint_parses_to_its_terms() {
        let e = LinearExpr::parse("mass2.x - mass1.x").unwrap();
        assert_eq!(
            e.terms,
            vec![t(1.0, "mass2", "x", 0), t(-1.0, "mass1", "x", 0)]
        );
    }

    #[test]
    fn reads_coefficients_derivatives_and_structured_names() {
        let e = LinearExpr::parse("-0.5*a.r[1] + 2e-1 * b.p.x - der(c.v) + der(c.x, 2)").unwrap();
        assert_eq!(
            e.terms,
            vec![
                t(-0.5, "a", "r[1]", 0),
                t(0.2, "b", "p.x", 0),
                t(-1.0, "c", "v", 1),
                t(1.0, "c", "x", 2)
            ]
        );
        assert_eq!(
            e.to_string(),
            "-0.5*a.r[1] + 0.2*b.p.x - der(c.v) + der(c.x, 2)"
        );
        let e = LinearExpr::parse("ss.A[2, 3] - der(ss.y[1], 2)").unwrap();
        assert_eq!(
            e.terms,
            vec![t(1.0, "ss", "A[2, 3]", 0), t(-1.0, "ss", "y[1]", 2)]
        );
    }

    #[test]
    fn long_text_is_quoted_around_the_column() {
        let short = "mass2.x - mass1.x";
        assert_eq!(quote(short, Some(3), "'", "'"), "'mass2.x - mass1.x'");
        let long = format!("{}$", "a".repeat(1000));
        let q = quote(&long, Some(1001), "'", "'");
        assert_eq!(
            q,
            format!(
                "'…{}»$' (1001 characters, » marks the column)",
                "a".repeat(150)
            )
        );
        let q = quote(&long, None, "", "");
        assert_eq!(q, format!("{}… (1001 characters)", "a".repeat(200)));
        let q = quote(&long, Some(500), "", "");
        let shown = q.split(" (").next().unwrap();
        assert_eq!(shown.chars().filter(|&c| c == 'a').count(), 200);
        assert!(q.starts_with('…') && q.contains("a»a"), "{q}");
    }

    #[test]
    fn quoted_variable_names_parse_with_their_brackets() {
        let e = LinearExpr::parse("m.'x (pos)'").unwrap();
        assert_eq!(e.terms, vec![t(1.0, "m", "x (pos)", 0)]);
    }

    #[test]
    fn rejects_malformed_text_with_the_column() {
        for (text, col) in [
            ("", 1),
            ("mass1", 6),
            ("mass1.x mass2.x", 9),
            ("2 mass1.x", 3),
            ("der(a.x, 3)", 10),
        ] {
            let err = LinearExpr::parse(text).unwrap_err();
            assert_eq!(err.column, col, "{text}: {err}");
            assert!(!err.to_string().contains('\n'));
        }
    }
}
