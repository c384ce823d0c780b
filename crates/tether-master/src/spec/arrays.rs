//! Array blocks in the system file: an `[[instance]]`, `[[constraint]]`,
//! `[[joint]]` or `[[coupling_variable]]` block with `count = N` stands for
//! N blocks, i = 0 … N − 1, each with every `{expression}` in its strings
//! replaced by the expression's value at i (docs/system-file.md, "Many
//! instances"). Blocks without `count` are left as written.
//!
//! Expressions: integers and decimals, `i`, `+ - * / %`, parentheses and
//! `log2(x)` (the floor of the base-2 logarithm, for the depth of a node
//! of a binary tree). Integer operands give integer results (`/` rounds
//! down); a decimal anywhere makes the result a decimal. A string that is one
//! placeholder and nothing else becomes that number (for parameters).

use toml::{Table, Value};

/// The sections whose blocks can repeat.
const SECTIONS: [&str; 4] = ["instance", "constraint", "joint", "coupling_variable"];

/// The most instances a system may have (docs/system-file.md, "Limits"):
/// ten times the 1024-mass chain of the `scale` benchmark.
pub const MAX_INSTANCES: usize = 10_000;

/// The most constraints, joints, coupling variables or signal connections a
/// system may have, each (the rows and columns of the interface system grow
/// with them): ten times the instance limit.
pub const MAX_BLOCKS: usize = 100_000;

/// The most blocks a section may have: [`MAX_INSTANCES`] or [`MAX_BLOCKS`].
pub(crate) fn limit(section: &str) -> usize {
    if section == "instance" {
        MAX_INSTANCES
    } else {
        MAX_BLOCKS
    }
}

/// Whether the file has any array block (else it is read as it is, with
/// the TOML reader's line numbers in errors).
pub(crate) fn has_arrays(table: &Table) -> bool {
    SECTIONS.iter().any(|section| {
        table
            .get(*section)
            .and_then(Value::as_array)
            .is_some_and(|blocks| blocks.iter().any(|b| b.get("count").is_some()))
    })
}

/// Why an array block cannot be expanded: the message names the block and the
/// text; `section` and `block` (0-based) let the reader add the block's line.
#[derive(Debug)]
pub(crate) struct BlockError {
    pub section: &'static str,
    pub block: usize,
    pub message: String,
}

/// Expand every array block in place. Errors name the block and the text.
/// The counts are checked against the section's [`limit`] before anything
/// is expanded.
pub(crate) fn expand(table: &mut Table) -> Result<(), BlockError> {
    for section in SECTIONS {
        expand_section(table, section).map_err(|(block, message)| BlockError {
            section,
            block,
            message,
        })?;
    }
    Ok(())
}

/// The line (1-based) of the header `[[section]]` of block `block` (0-based)
/// in `text`, if the blocks are written with headers.
pub(crate) fn block_line(text: &str, section: &str, block: usize) -> Option<usize> {
    let header = format!("[[{section}]]");
    text.lines()
        .enumerate()
        .filter(|(_, line)| {
            let bare: String = line.chars().filter(|c| !c.is_whitespace()).collect();
            bare == header || bare.starts_with(&format!("{header}#"))
        })
        .nth(block)
        .map(|(n, _)| n + 1)
}

/// [`expand`] for one section; errors with the block's index.
fn expand_section(table: &mut Table, section: &'static str) -> Result<(), (usize, String)> {
    let Some(Value::Array(blocks)) = table.get_mut(section) else {
        return Ok(());
    };
    let limit = limit(section);
    let mut total = 0usize;
    for (b, block) in blocks.iter().enumerate() {
        let (where_, count) = match block.get("count") {
            None => (format!("[[{section}]] block {}", b + 1), 1),
            Some(count) => {
                let where_ = format!("[[{section}]] block {} (count = {count})", b + 1);
                let count = count
                    .as_integer()
                    .and_then(|c| usize::try_from(c).ok())
                    .ok_or_else(|| {
                        (
                            b,
                            format!("{where_}: count must be an integer from 0 to {limit}"),
                        )
                    })?;
                (where_, count)
            }
        };
        total = total.saturating_add(count);
        if total > limit {
            return Err((
                    b,
                    format!(
                        "{where_}: makes {total} [[{section}]] blocks, above the limit of {limit} (docs/system-file.md, \"Limits\")"
                    ),
                ));
        }
    }
    let mut expanded = Vec::with_capacity(total);
    for (b, block) in std::mem::take(blocks).into_iter().enumerate() {
        let Value::Table(mut block) = block else {
            expanded.push(block);
            continue;
        };
        let Some(count) = block.remove("count") else {
            expanded.push(Value::Table(block));
            continue;
        };
        let where_ = format!("[[{section}]] block {} (count = {count})", b + 1);
        let count = count
            .as_integer()
            .and_then(|c| usize::try_from(c).ok())
            .ok_or_else(|| {
                (
                    b,
                    format!("{where_}: count must be an integer from 0 to {limit}"),
                )
            })?;
        for i in 0..count {
            let mut copy = Value::Table(block.clone());
            substitute(&mut copy, i as i64).map_err(|e| (b, format!("{where_}, i = {i}: {e}")))?;
            expanded.push(copy);
        }
    }
    *blocks = expanded;
    Ok(())
}

/// Replace the placeholders of every string in `value` (recursively).
fn substitute(value: &mut Value, i: i64) -> Result<(), String> {
    match value {
        Value::String(text) => {
            if let Some(inner) = sole_placeholder(text) {
                *value = match evaluate(inner, i)? {
                    Number::Integer(n) => Value::Integer(n),
                    Number::Real(x) => Value::Float(x),
                };
            } else {
                *text = fill(text, i)?;
            }
        }
        Value::Array(items) => {
            for item in items {
                substitute(item, i)?;
            }
        }
        Value::Table(table) => {
            for (_, item) in table.iter_mut() {
                substitute(item, i)?;
            }
        }
        _ => {}
    }
    Ok(())
}

/// `"{expr}"` alone: the expression.
fn sole_placeholder(text: &str) -> Option<&str> {
    let inner = text.strip_prefix('{')?.strip_suffix('}')?;
    (!inner.contains(['{', '}'])).then_some(inner)
}

/// `text` with each `{expr}` replaced by its value.
fn fill(text: &str, i: i64) -> Result<String, String> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let close = rest[open..]
            .find('}')
            .ok_or_else(|| format!("unclosed '{{' in \"{text}\""))?;
        out.push_str(&evaluate(&rest[open + 1..open + close], i)?.to_string());
        rest = &rest[open + close + 1..];
    }
    if rest.contains('}') {
        return Err(format!("unopened '}}' in \"{text}\""));
    }
    out.push_str(rest);
    Ok(out)
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Number {
    Integer(i64),
    Real(f64),
}

impl Number {
    fn real(self) -> f64 {
        match self {
            Number::Integer(n) => n as f64,
            Number::Real(x) => x,
        }
    }
}

impl std::fmt::Display for Number {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Number::Integer(n) => write!(f, "{n}"),
            Number::Real(x) => write!(f, "{x:?}"),
        }
    }
}

/// How deep parentheses, `log2(` and signs may nest in a placeholder: the parser
/// recurses once a level, and a hostile system file must get an error, not a stack
/// overflow.
const MAX_NESTING: usize = 64;

/// The value of `expr` at `i`.
fn evaluate(expr: &str, i: i64) -> Result<Number, String> {
    let mut parser = Parser {
        text: expr,
        bytes: expr.as_bytes(),
        pos: 0,
        i,
        depth: 0,
    };
    let value = parser.sum()?;
    parser.skip_spaces();
    if parser.pos != parser.bytes.len() {
        return Err(parser.error("an operator or the end"));
    }
    Ok(value)
}

struct Parser<'a> {
    text: &'a str,
    bytes: &'a [u8],
    pos: usize,
    i: i64,
    /// The nesting level of the factor being read.
    depth: usize,
}

impl Parser<'_> {
    fn error(&self, expected: &str) -> String {
        format!(
            "expected {expected} at {} in {}",
            self.pos + 1,
            self.quoted()
        )
    }

    /// The placeholder as the user wrote it, cut around the position read
    /// ([`crate::expr::quote`]).
    fn quoted(&self) -> String {
        let column = self
            .text
            .get(..self.pos)
            .map(|read| read.chars().count() + 2);
        crate::expr::quote(&format!("{{{}}}", self.text), column, "\"", "\"")
    }

    fn skip_spaces(&mut self) {
        while self
            .bytes
            .get(self.pos)
            .is_some_and(u8::is_ascii_whitespace)
        {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_spaces();
        self.bytes.get(self.pos).copied()
    }

    fn sum(&mut self) -> Result<Number, String> {
        let mut left = self.product()?;
        while let Some(op @ (b'+' | b'-')) = self.peek() {
            self.pos += 1;
            let right = self.product()?;
            left = self.apply(op, left, right)?;
        }
        Ok(left)
    }

    fn product(&mut self) -> Result<Number, String> {
        let mut left = self.factor()?;
        while let Some(op @ (b'*' | b'/' | b'%')) = self.peek() {
            self.pos += 1;
            let right = self.factor()?;
            left = self.apply(op, left, right)?;
        }
        Ok(left)
    }

    /// A factor, at most [`MAX_NESTING`] levels deep.
    fn factor(&mut self) -> Result<Number, String> {
        if self.depth == MAX_NESTING {
            return Err(format!(
                "nested more than {MAX_NESTING} deep (the limit) at {} in {}",
                self.pos + 1,
                self.quoted()
            ));
        }
        self.depth += 1;
        let value = self.nested_factor();
        self.depth -= 1;
        value
    }

    fn nested_factor(&mut self) -> Result<Number, String> {
        match self.peek() {
            Some(b'-') => {
                self.pos += 1;
                Ok(match self.factor()? {
                    Number::Integer(n) => Number::Integer(-n),
                    Number::Real(x) => Number::Real(-x),
                })
            }
            Some(b'(') => {
                self.pos += 1;
                let value = self.sum()?;
                if self.peek() != Some(b')') {
                    return Err(self.error("')'"));
                }
                self.pos += 1;
                Ok(value)
            }
            Some(b'0'..=b'9' | b'.') => {
                let start = self.pos;
                while self
                    .bytes
                    .get(self.pos)
                    .is_some_and(|b| b.is_ascii_digit() || *b == b'.')
                {
                    self.pos += 1;
                }
                let literal = &self.text[start..self.pos];
                if literal.contains('.') {
                    literal
                        .parse()
                        .map(Number::Real)
                        .map_err(|_| self.error("a number"))
                } else {
                    literal
                        .parse()
                        .map(Number::Integer)
                        .map_err(|_| self.error("a number"))
                }
            }
            Some(b'i')
                if !self
                    .bytes
                    .get(self.pos + 1)
                    .is_some_and(u8::is_ascii_alphanumeric) =>
            {
                self.pos += 1;
                Ok(Number::Integer(self.i))
            }
            Some(b'l') if self.text[self.pos..].starts_with("log2(") => {
                self.pos += "log2(".len();
                let argument = self.sum()?;
                if self.peek() != Some(b')') {
                    return Err(self.error("')'"));
                }
                self.pos += 1;
                let x = argument.real();
                if x.is_nan() || x < 1.0 {
                    return Err(format!("log2 of {x} in {} (needs ≥ 1)", self.quoted()));
                }
                Ok(Number::Integer(x.log2().floor() as i64))
            }
            _ => Err(self.error("a number, i, log2( or '('")),
        }
    }

    fn apply(&self, op: u8, a: Number, b: Number) -> Result<Number, String> {
        let zero = || format!("division by zero in \"{{{}}}\"", self.text);
        Ok(match (a, b) {
            (Number::Integer(x), Number::Integer(y)) => Number::Integer(match op {
                b'+' => x + y,
                b'-' => x - y,
                b'*' => x * y,
                b'/' => x.checked_div_euclid(y).ok_or_else(zero)?,
                _ => x.checked_rem_euclid(y).ok_or_else(zero)?,
            }),
            (a, b) => {
                let (x, y) = (a.real(), b.real());
                Number::Real(match op {
                    b'+' => x + y,
                    b'-' => x - y,
                    b'*' => x * y,
                    b'/' if y == 0.0 => return Err(zero()),
                    b'/' => x / y,
                    _ if y == 0.0 => return Err(zero()),
                    _ => x % y,
                })
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expressions_evaluate_with_integer_and_decimal_arithmetic() {
        let at = |e: &str, i| evaluate(e, i).unwrap();
        assert_eq!(at("i", 7), Number::Integer(7));
        assert_eq!(at("i + 1", 7), Number::Integer(8));
        assert_eq!(at("(i - 1) / 2", 6), Number::Integer(2));
        assert_eq!(at("i % 3 * 2", 7), Number::Integer(2));
        assert_eq!(at("log2(i + 1)", 6), Number::Integer(2));
        assert_eq!(at("log2(i + 1)", 7), Number::Integer(3));
        assert_eq!(at("0.5 + i", 2), Number::Real(2.5));
        assert_eq!(at("-i * 1.5", 2), Number::Real(-3.0));
        for bad in ["i +", "j", "(i", "i / 0", "log2(0)", "1.2.3"] {
            assert!(evaluate(bad, 1).is_err(), "{bad}");
        }
    }

    /// Parentheses, `log2(` and signs nested 10⁵ deep are one error naming the
    /// limit, the position and the start of the text, not a stack overflow; 63
    /// parentheses or signs around a number (64 levels) evaluate.
    #[test]
    fn nesting_beyond_the_limit_is_an_error() {
        let deep =
            |n: usize, open: &str, close: &str| format!("{}1{}", open.repeat(n), close.repeat(n));
        for (open, close) in [("(", ")"), ("log2(", ")"), ("-", "")] {
            let error = evaluate(&deep(100_000, open, close), 0).unwrap_err();
            assert!(
                error.starts_with("nested more than 64 deep (the limit) at ")
                    && error.ends_with(" characters, » marks the column)")
                    && error.len() < 1000,
                "{error}"
            );
        }
        for (open, close) in [("(", ")"), ("-", "")] {
            let at_limit = deep(MAX_NESTING - 1, open, close);
            assert!(evaluate(&at_limit, 0).is_ok(), "{open}");
        }
    }

    /// A count, or the blocks of a section in all, above the section's limit
    /// is refused before anything is expanded; at the limit it is expanded.
    #[test]
    fn counts_above_the_limits_are_refused() {
        let table = |text: &str| -> Table { toml::from_str(text).unwrap() };
        let mut huge = table("[[instance]]\nname = \"m{i}\"\ncount = 100000000");
        let error = expand(&mut huge).unwrap_err().message;
        assert_eq!(
            error,
            "[[instance]] block 1 (count = 100000000): makes 100000000 [[instance]] blocks, above the limit of 10000 (docs/system-file.md, \"Limits\")"
        );
        let mut total = table(
            "[[joint]]\nname = \"a{i}\"\ncount = 99999\n[[joint]]\nname = \"b\"\n[[joint]]\nname = \"c\"",
        );
        let error = expand(&mut total).unwrap_err().message;
        assert!(
            error.starts_with(
                "[[joint]] block 3: makes 100001 [[joint]] blocks, above the limit of 100000"
            ),
            "{error}"
        );
        let mut at_limit = table("[[instance]]\nname = \"m{i}\"\ncount = 10000");
        expand(&mut at_limit).unwrap();
        assert_eq!(
            at_limit["instance"].as_array().unwrap().len(),
            MAX_INSTANCES
        );
    }

    #[test]
    fn array_blocks_expand_and_other_blocks_stay() {
        let mut table: Table = toml::from_str(
            r#"
            [[instance]]
            name = "single"
            [[instance]]
            name = "m{i}"
            count = 3
            parameters = { x0 = "{0.5 * i}", n = "{i}", label = "body {i + 1}" }
            [[constraint]]
            name = "link{i}"
            count = 2
            position = "m{i+1}.x - m{i}.x"
            "#,
        )
        .unwrap();
        assert!(has_arrays(&table));
        expand(&mut table).unwrap();
        let instances = table["instance"].as_array().unwrap();
        assert_eq!(instances.len(), 4);
        assert_eq!(instances[0]["name"].as_str(), Some("single"));
        assert_eq!(instances[3]["name"].as_str(), Some("m2"));
        assert!(instances[3].get("count").is_none());
        let p = &instances[3]["parameters"];
        assert_eq!(p["x0"].as_float(), Some(1.0));
        assert_eq!(p["n"].as_integer(), Some(2));
        assert_eq!(p["label"].as_str(), Some("body 3"));
        let constraints = table["constraint"].as_array().unwrap();
        assert_eq!(constraints[1]["position"].as_str(), Some("m2.x - m1.x"));
        let mut bad: Table = toml::from_str("[[joint]]\nname = \"j{i\"\ncount = 1").unwrap();
        let err = expand(&mut bad).unwrap_err();
        assert_eq!((err.section, err.block), ("joint", 0));
        let err = err.message;
        assert!(
            err.contains("[[joint]] block 1") && err.contains("unclosed"),
            "{err}"
        );
        let text = "[experiment]\n\n[[joint]]\nname = 'a'\n[[ joint ]] # b\nname = 'b'";
        assert_eq!(block_line(text, "joint", 0), Some(3));
        assert_eq!(block_line(text, "joint", 1), Some(5));
        assert_eq!(block_line(text, "joint", 2), None);
    }
}
