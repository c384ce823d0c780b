//! Units as FMUs declare them (`unit="m/s2"`, Modelica's unit syntax, or a
//! `UnitDefinitions` entry with a `BaseUnit`), reduced to SI base units so
//! that `N.m` and `J`, `m/s` and `m.s-1` compare equal and `mm` and `m`
//! differ by a factor. A unit that does not parse is not compared.

use tether_fmi::{ModelDescription, ScalarVariable};

/// A unit as SI exponents (kg, m, s, A, K, mol, cd, rad) with the factor and
/// offset to SI: value_SI = factor·value + offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dimension {
    exponents: [i32; 8],
    factor: f64,
    offset: f64,
}

const KG: usize = 0;
const M: usize = 1;
const S: usize = 2;
const AMP: usize = 3;
const KELVIN: usize = 4;
const MOL: usize = 5;
const CD: usize = 6;
const RAD: usize = 7;

impl Dimension {
    fn one() -> Self {
        Dimension {
            exponents: [0; 8],
            factor: 1.0,
            offset: 0.0,
        }
    }

    fn base(index: usize, power: i32, factor: f64) -> Self {
        let mut d = Self::one();
        d.exponents[index] = power;
        d.factor = factor;
        d
    }

    fn of(exps: &[(usize, i32)], factor: f64) -> Self {
        let mut d = Self::one();
        for &(i, p) in exps {
            d.exponents[i] = p;
        }
        d.factor = factor;
        d
    }

    fn times(self, other: Self) -> Self {
        let mut exponents = self.exponents;
        for (e, o) in exponents.iter_mut().zip(other.exponents) {
            *e += o;
        }
        Dimension {
            exponents,
            factor: self.factor * other.factor,
            offset: 0.0,
        }
    }

    fn power(self, p: i32) -> Self {
        Dimension {
            exponents: self.exponents.map(|e| e * p),
            factor: self.factor.powi(p),
            offset: 0.0,
        }
    }

    /// This unit per second to the `n`-th power (a time derivative).
    pub fn per_second(self, n: u32) -> Self {
        self.times(Self::base(S, -(n as i32), 1.0))
    }

    /// The same quantity in the same scale: no conversion between the two.
    pub fn same(&self, other: &Self) -> bool {
        self.exponents == other.exponents
            && (self.factor - other.factor).abs()
                <= 1e-12 * self.factor.abs().max(other.factor.abs())
            && (self.offset - other.offset).abs() <= 1e-12 * self.offset.abs().max(1.0)
    }

    /// The same quantity, possibly in another scale.
    pub fn same_quantity(&self, other: &Self) -> bool {
        self.exponents == other.exponents
    }

    /// No units at all (`1`, a ratio).
    pub fn is_dimensionless(&self) -> bool {
        self.exponents == [0; 8]
    }

    /// A force (kg·m/s²) or a torque (kg·m²/s², also per radian).
    pub fn is_force_or_torque(&self) -> bool {
        let [kg, m, s, a, k, mol, cd, _rad] = self.exponents;
        kg == 1 && s == -2 && (m == 1 || m == 2) && a == 0 && k == 0 && mol == 0 && cd == 0
    }

    /// Only lengths, angles and time: a position, velocity or acceleration.
    pub fn is_kinematic(&self) -> bool {
        let e = self.exponents;
        e[KG] == 0
            && e[AMP] == 0
            && e[KELVIN] == 0
            && e[MOL] == 0
            && e[CD] == 0
            && (e[M] != 0 || e[RAD] != 0 || e[S] != 0)
    }

    /// `to = gain·from + offset` that converts a value in `from` into `to`,
    /// for one quantity.
    pub fn conversion(from: &Self, to: &Self) -> Option<(f64, f64)> {
        from.same_quantity(to).then(|| {
            (
                from.factor / to.factor,
                (from.offset - to.offset) / to.factor,
            )
        })
    }
}

/// The unit of a Real variable, its name and its dimension where it parses.
pub fn unit_of<'a>(
    md: &ModelDescription,
    var: &'a ScalarVariable,
) -> Option<(&'a str, Option<Dimension>)> {
    let name = var.real()?.attributes.unit.as_deref()?;
    if name.trim().is_empty() {
        return None;
    }
    let declared = md
        .unit_definitions
        .iter()
        .find(|u| u.name == name)
        .and_then(|u| u.base_unit);
    let dimension = match declared {
        Some(b) => Some(Dimension {
            exponents: [b.kg, b.m, b.s, b.A, b.K, b.mol, b.cd, b.rad],
            factor: b.factor,
            offset: b.offset,
        }),
        None => parse(name),
    };
    Some((name, dimension))
}

/// A unit in Modelica's syntax (`kg.m2/s2`, `N.m`, `m.s-1`, `1/s`, `mm`,
/// `degC`), or `None`.
pub fn parse(text: &str) -> Option<Dimension> {
    let text = text.trim();
    if text == "degC" {
        return Some(Dimension {
            offset: 273.15,
            ..Dimension::base(KELVIN, 1, 1.0)
        });
    }
    let (numerator, denominator) = match text.split_once('/') {
        Some((n, d)) => (n, Some(d)),
        None => (text, None),
    };
    let mut d = if numerator == "1" {
        Dimension::one()
    } else {
        factors(numerator)?
    };
    if let Some(den) = denominator {
        let den = den
            .strip_prefix('(')
            .and_then(|x| x.strip_suffix(')'))
            .unwrap_or(den);
        d = d.times(factors(den)?.power(-1));
    }
    Some(d)
}

/// `kg.m2.s-2`: operands joined by `.`, each with an optional integer power.
fn factors(text: &str) -> Option<Dimension> {
    let mut d = Dimension::one();
    for part in text.split('.') {
        let digits = part
            .char_indices()
            .find(|&(_, c)| c.is_ascii_digit() || c == '-' || c == '+')
            .map_or(part.len(), |(i, _)| i);
        let (symbol, power) = part.split_at(digits);
        let power: i32 = if power.is_empty() {
            1
        } else {
            power.parse().ok()?
        };
        d = d.times(operand(symbol)?.power(power));
    }
    Some(d)
}

/// A unit symbol, with or without an SI prefix.
fn operand(symbol: &str) -> Option<Dimension> {
    if let Some(d) = symbol_of(symbol) {
        return Some(d);
    }
    const PREFIXES: [(&str, f64); 20] = [
        ("Y", 1e24),
        ("Z", 1e21),
        ("E", 1e18),
        ("P", 1e15),
        ("T", 1e12),
        ("G", 1e9),
        ("M", 1e6),
        ("k", 1e3),
        ("h", 1e2),
        ("da", 1e1),
        ("d", 1e-1),
        ("c", 1e-2),
        ("m", 1e-3),
        ("u", 1e-6),
        ("µ", 1e-6),
        ("n", 1e-9),
        ("p", 1e-12),
        ("f", 1e-15),
        ("a", 1e-18),
        ("z", 1e-21),
    ];
    PREFIXES.iter().find_map(|&(prefix, scale)| {
        let rest = symbol.strip_prefix(prefix)?;
        let mut d = symbol_of(rest)?;
        d.factor *= scale;
        Some(d)
    })
}

fn symbol_of(symbol: &str) -> Option<Dimension> {
    Some(match symbol {
        "m" => Dimension::base(M, 1, 1.0),
        "s" => Dimension::base(S, 1, 1.0),
        "g" => Dimension::base(KG, 1, 1e-3),
        "A" => Dimension::base(AMP, 1, 1.0),
        "K" => Dimension::base(KELVIN, 1, 1.0),
        "mol" => Dimension::base(MOL, 1, 1.0),
        "cd" => Dimension::base(CD, 1, 1.0),
        "rad" => Dimension::base(RAD, 1, 1.0),
        "deg" => Dimension::base(RAD, 1, std::f64::consts::PI / 180.0),
        "rev" => Dimension::base(RAD, 1, 2.0 * std::f64::consts::PI),
        "rpm" => Dimension::of(&[(RAD, 1), (S, -1)], 2.0 * std::f64::consts::PI / 60.0),
        "min" => Dimension::base(S, 1, 60.0),
        "h" => Dimension::base(S, 1, 3600.0),
        "Hz" => Dimension::base(S, -1, 1.0),
        "N" => Dimension::of(&[(KG, 1), (M, 1), (S, -2)], 1.0),
        "J" => Dimension::of(&[(KG, 1), (M, 2), (S, -2)], 1.0),
        "W" => Dimension::of(&[(KG, 1), (M, 2), (S, -3)], 1.0),
        "Pa" => Dimension::of(&[(KG, 1), (M, -1), (S, -2)], 1.0),
        "bar" => Dimension::of(&[(KG, 1), (M, -1), (S, -2)], 1e5),
        "l" | "L" => Dimension::base(M, 3, 1e-3),
        "V" => Dimension::of(&[(KG, 1), (M, 2), (S, -3), (AMP, -1)], 1.0),
        "C" => Dimension::of(&[(S, 1), (AMP, 1)], 1.0),
        "Ohm" => Dimension::of(&[(KG, 1), (M, 2), (S, -3), (AMP, -2)], 1.0),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modelica_units_reduce_to_si() {
        let p = |t: &str| parse(t).unwrap_or_else(|| panic!("{t}"));
        assert!(p("N.m").same(&p("J")));
        assert!(p("m/s").same(&p("m.s-1")));
        assert!(p("m/s2").same(&p("m/s").per_second(1)));
        assert!(p("kg.m/s2").same(&p("N")));
        assert!(p("N").is_force_or_torque() && p("N.m").is_force_or_torque());
        assert!(p("m/s").is_kinematic() && p("rad").is_kinematic());
        assert!(!p("mm").same(&p("m")) && p("mm").same_quantity(&p("m")));
        assert_eq!(Dimension::conversion(&p("mm"), &p("m")), Some((1e-3, 0.0)));
        assert_eq!(Dimension::conversion(&p("km"), &p("m")), Some((1e3, 0.0)));
        assert!(Dimension::conversion(&p("m"), &p("s")).is_none());
        let (gain, offset) = Dimension::conversion(&p("degC"), &p("K")).unwrap();
        assert_eq!((gain, offset), (1.0, 273.15));
        assert!(p("1/s").same(&p("Hz")));
        assert!(parse("Nm").is_none() && parse("meter").is_none() && parse("m/").is_none());
    }
}
