//! References for error measurements: a closed form, a CSV, or the finest run.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use tether_master::{StartValue, SystemSpec};

use crate::{StudyError, Table};

/// Where the reference solution of a convergence study comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ReferenceSpec {
    /// `"finest"` (the run with the smallest H) or `"two-mass-oscillator"`
    /// (the closed form of the paper's oscillator, see [`TwoMassOscillator`]).
    Named(String),
    /// `{ csv = "reference.csv" }`: a results CSV, linearly interpolated in time.
    Csv {
        /// The file (relative to the study file).
        csv: PathBuf,
    },
}

impl ReferenceSpec {
    /// The command-line form: `finest`, `two-mass-oscillator`, or the path
    /// of a results CSV (made absolute against the current directory).
    pub fn parse_cli(text: &str) -> Result<ReferenceSpec, StudyError> {
        Ok(match text {
            "finest" | "two-mass-oscillator" => ReferenceSpec::Named(text.to_string()),
            file => ReferenceSpec::Csv {
                csv: std::path::absolute(file).map_err(|e| StudyError::Io {
                    path: PathBuf::from(file),
                    source: e,
                })?,
            },
        })
    }
}

/// A reference ready for lookups.
#[derive(Debug, Clone)]
pub enum Reference {
    /// Tabulated values (a CSV or the finest run).
    Table(Table),
    /// The closed form of the coupled two-mass oscillator.
    Oscillator(TwoMassOscillator),
}

impl Reference {
    /// Build from a specification; `finest` must already be run and is passed here.
    pub fn resolve(
        spec: &ReferenceSpec,
        system: &SystemSpec,
        base: &Path,
        finest: Option<Table>,
    ) -> Result<Reference, StudyError> {
        match spec {
            ReferenceSpec::Csv { csv } => Ok(Reference::Table(Table::read_csv(&base.join(csv))?)),
            ReferenceSpec::Named(n) if n == "finest" => finest
                .map(Reference::Table)
                .ok_or_else(|| StudyError::Invalid("the finest run has no results".into())),
            ReferenceSpec::Named(n) if n == "two-mass-oscillator" => {
                Ok(Reference::Oscillator(TwoMassOscillator::from_system(system)?))
            }
            ReferenceSpec::Named(n) => Err(StudyError::Invalid(format!(
                "reference '{n}': expected \"finest\", \"two-mass-oscillator\" or {{ csv = \"FILE\" }}"
            ))),
        }
    }

    /// Where it comes from, for messages.
    pub fn describe(&self) -> String {
        match self {
            Reference::Table(t) => t.source.clone(),
            Reference::Oscillator(_) => "the closed form of the two-mass oscillator".into(),
        }
    }

    /// Check that every column exists in the reference; returns their lookup keys.
    pub fn columns(&self, names: &[String]) -> Result<Vec<usize>, StudyError> {
        match self {
            Reference::Table(t) => names.iter().map(|n| t.column(n)).collect(),
            Reference::Oscillator(o) => {
                let known = o.column_names();
                names
                    .iter()
                    .map(|n| {
                        known
                            .iter()
                            .position(|k| k == n)
                            .ok_or_else(|| StudyError::unknown_column(n, &self.describe(), &known))
                    })
                    .collect()
            }
        }
    }

    /// The reference value of column `key` (from [`Reference::columns`]) at `t`.
    pub fn at(&self, key: usize, t: f64) -> Option<f64> {
        match self {
            Reference::Table(table) => table.interpolate(key, t),
            Reference::Oscillator(o) => Some(o.values(t)[key]),
        }
    }
}

/// The paper's two-mass oscillator (Sect. 2, eq. 1–3) in closed form: two
/// masses with springs and dampers to ground, rigidly linked, move as one
/// oscillator with m = m1 + m2, c = c1 + c2, d = d1 + d2; the link force is
/// λ = m1 m2/(m1 + m2)·[(c1/m1 − c2/m2) x + (d1/m1 − d2/m2) v].
///
/// Read from a system whose first two instances are the masses (parameters
/// `m`, `c`, `d`, `x0`, `v0` given in the system file, equal `x0` and `v0`)
/// and whose first constraint is the link driving `+λ` into the first mass.
#[derive(Debug, Clone, PartialEq)]
pub struct TwoMassOscillator {
    /// Instance names of mass 1 and mass 2.
    pub names: [String; 2],
    /// The link constraint's name.
    pub constraint: String,
    /// m, c, d of each mass.
    pub mass: [(f64, f64, f64); 2],
    /// Initial position and velocity.
    pub x0: f64,
    /// Initial velocity.
    pub v0: f64,
}

impl TwoMassOscillator {
    /// Read masses, springs, dampers and the initial state from the system file.
    pub fn from_system(spec: &SystemSpec) -> Result<Self, StudyError> {
        let invalid = |reason: String| {
            StudyError::Invalid(format!("reference two-mass-oscillator: {reason}"))
        };
        if spec.instances.len() < 2 || spec.constraints.is_empty() {
            return Err(invalid(
                "the system needs two instances (the masses) and a constraint (the link)".into(),
            ));
        }
        let get = |i: usize, p: &str| -> Result<f64, StudyError> {
            let inst = &spec.instances[i];
            match inst.parameters.get(p) {
                Some(StartValue::Real(v)) => Ok(*v),
                Some(StartValue::Integer(v)) => Ok(*v as f64),
                _ => Err(invalid(format!(
                    "instance '{}' must set the number {p} in the system file",
                    inst.name
                ))),
            }
        };
        let mut mass = [(0.0, 0.0, 0.0); 2];
        for (i, slot) in mass.iter_mut().enumerate() {
            *slot = (get(i, "m")?, get(i, "c")?, get(i, "d")?);
        }
        let (x0, v0) = (get(0, "x0")?, get(0, "v0")?);
        if get(1, "x0")? != x0 || get(1, "v0")? != v0 {
            return Err(invalid(
                "both masses must start at the same x0 and v0 (the link holds)".into(),
            ));
        }
        let (m, c) = (mass[0].0 + mass[1].0, mass[0].1 + mass[1].1);
        if m <= 0.0 || c < 0.0 || mass.iter().any(|p| p.2 < 0.0) {
            return Err(invalid(
                "masses must be > 0, springs and dampers ≥ 0".into(),
            ));
        }
        Ok(TwoMassOscillator {
            names: [
                spec.instances[0].name.clone(),
                spec.instances[1].name.clone(),
            ],
            constraint: spec.constraints[0].name.clone(),
            mass,
            x0,
            v0,
        })
    }

    /// The columns this reference provides, in the order of [`Self::values`].
    pub fn column_names(&self) -> Vec<String> {
        let mut names = Vec::new();
        for n in &self.names {
            for v in ["x", "v", "a"] {
                names.push(format!("{n}.{v}"));
            }
        }
        names.push(format!("{}.lambda", self.constraint));
        names.push(format!("{}.g", self.constraint));
        names
    }

    /// x, v, a of both masses, then λ and the residual g = 0, at time t.
    pub fn values(&self, t: f64) -> [f64; 8] {
        let [(m1, c1, d1), (m2, c2, d2)] = self.mass;
        let (m, c, d) = (m1 + m2, c1 + c2, d1 + d2);
        let (x, v) = damped_oscillator(m, c, d, self.x0, self.v0, t);
        let a = -(c * x + d * v) / m;
        let lambda = m1 * m2 / m * ((c1 / m1 - c2 / m2) * x + (d1 / m1 - d2 / m2) * v);
        [x, v, a, x, v, a, lambda, 0.0]
    }
}

/// x(t), v(t) of m x'' + d x' + c x = 0 with x(0) = x0, v(0) = v0, for
/// under-, critically and over-damped cases.
pub fn damped_oscillator(m: f64, c: f64, d: f64, x0: f64, v0: f64, t: f64) -> (f64, f64) {
    let delta = d / (2.0 * m);
    let disc = delta * delta - c / m;
    if disc.abs() <= 1e-12 * (delta * delta).max(c / m).max(f64::MIN_POSITIVE) {
        let e = (-delta * t).exp();
        let b = v0 + delta * x0;
        return ((x0 + b * t) * e, (v0 - delta * b * t) * e);
    }
    if disc < 0.0 {
        let w = (-disc).sqrt();
        let (s, co, e) = ((w * t).sin(), (w * t).cos(), (-delta * t).exp());
        let x = e * (x0 * co + (v0 + delta * x0) / w * s);
        let v = e * (v0 * co - (delta * v0 + (delta * delta + w * w) * x0) / w * s);
        (x, v)
    } else {
        let r = disc.sqrt();
        let (s1, s2) = (-delta + r, -delta - r);
        let a = (v0 - s2 * x0) / (s1 - s2);
        let b = x0 - a;
        let (e1, e2) = ((s1 * t).exp(), (s2 * t).exp());
        (a * e1 + b * e2, a * s1 * e1 + b * s2 * e2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every damping case satisfies the ODE (checked by central differences)
    /// and the initial conditions.
    #[test]
    fn closed_form_solves_the_ode_in_every_damping_case() {
        let (m, c) = (3.0f64, 2000.0f64);
        let critical = 2.0 * (c * m).sqrt();
        for d in [0.0, 20.0, critical, 3.0 * critical] {
            let f = |t| damped_oscillator(m, c, d, 0.5, 100.0, t);
            let (x0, v0) = f(0.0);
            assert!(
                (x0 - 0.5).abs() < 1e-12 && (v0 - 100.0).abs() < 1e-10,
                "d = {d}"
            );
            for t in [0.013, 0.2, 0.7] {
                let h = 1e-5;
                let (xp, vp) = f(t + h);
                let (xm, vm) = f(t - h);
                let (x, v) = f(t);
                let (dx, dv) = ((xp - xm) / (2.0 * h), (vp - vm) / (2.0 * h));
                let scale = v.abs().max(1.0);
                assert!((dx - v).abs() < 1e-5 * scale, "d = {d}, t = {t}");
                let a = -(c * x + d * v) / m;
                assert!(
                    (dv - a).abs() < 1e-5 * a.abs().max(1.0) * 10.0,
                    "d = {d}, t = {t}"
                );
            }
        }
    }

    #[test]
    fn paper_oscillator_starts_with_lambda_1000_over_3() {
        let text = r#"
            [experiment]
            stop = 1.0
            step = 1e-3
            [[instance]]
            name = "mass1"
            fmu = "osc.fmu"
            parameters = { m = 1.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0 }
            [[instance]]
            name = "mass2"
            fmu = "osc.fmu"
            parameters = { m = 2.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0 }
            [[constraint]]
            name = "link"
            position = "mass2.x - mass1.x"
            drives = "mass1.F - mass2.F"
        "#;
        let spec = SystemSpec::from_toml(text).unwrap();
        let osc = TwoMassOscillator::from_system(&spec).unwrap();
        let v = osc.values(0.0);
        assert!((v[6] - 1000.0 / 3.0).abs() < 1e-12, "{v:?}");
        let no_d = text.replacen("d = 10.0, ", "", 1);
        let e = TwoMassOscillator::from_system(&SystemSpec::from_toml(&no_d).unwrap());
        assert!(e.unwrap_err().to_string().contains("mass1"));
    }
}
