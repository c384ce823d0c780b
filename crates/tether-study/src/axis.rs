//! An axis of a study: the values one quantity takes, set on one or more targets.

use serde::{Deserialize, Serialize};

use crate::StudyError;

/// Linear or logarithmic spacing (and plot axis).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scale {
    /// Evenly spaced values.
    #[default]
    Linear,
    /// Evenly spaced logarithms (all values > 0).
    Log,
}

/// Values for one axis: either a list or `from`/`to`/`points` with a scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// What the value is set on: `instance.parameter`, or `step` (H). All
    /// targets get the same value, e.g. `["mass1.c", "mass2.c"]`.
    pub targets: Vec<String>,
    /// Axis title (default: the targets).
    #[serde(default)]
    pub label: Option<String>,
    /// Explicit values.
    #[serde(default)]
    pub values: Option<Vec<f64>>,
    /// First value of a range.
    #[serde(default)]
    pub from: Option<f64>,
    /// Last value of a range.
    #[serde(default)]
    pub to: Option<f64>,
    /// Number of values in a range (≥ 2).
    #[serde(default)]
    pub points: Option<usize>,
    /// Spacing of a range and scale of the plot axis.
    #[serde(default)]
    pub scale: Scale,
}

impl Axis {
    /// The axis title.
    pub fn title(&self) -> String {
        self.label
            .clone()
            .unwrap_or_else(|| self.targets.join(" = "))
    }

    /// The values, checked: finite, and positive on a log axis.
    pub fn values(&self) -> Result<Vec<f64>, StudyError> {
        let name = self.title();
        let bad = |reason: String| StudyError::Invalid(format!("axis '{name}': {reason}"));
        if self.targets.is_empty() {
            return Err(bad("no targets".into()));
        }
        let values = match (&self.values, self.from, self.to, self.points) {
            (Some(v), None, None, None) => v.clone(),
            (None, Some(from), Some(to), Some(points)) => {
                if points < 2 {
                    return Err(bad(format!("points = {points}: need at least 2")));
                }
                let n = (points - 1) as f64;
                match self.scale {
                    Scale::Linear => (0..points)
                        .map(|i| from + (to - from) * i as f64 / n)
                        .collect(),
                    Scale::Log => {
                        if from <= 0.0 || to <= 0.0 {
                            return Err(bad("a log range needs from, to > 0".into()));
                        }
                        let (a, b) = (from.log10(), to.log10());
                        (0..points)
                            .map(|i| 10f64.powf(a + (b - a) * i as f64 / n))
                            .collect()
                    }
                }
            }
            _ => {
                return Err(bad(
                    "give either values = [...] or from, to and points".into()
                ))
            }
        };
        if values.is_empty() {
            return Err(bad("no values".into()));
        }
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(bad(format!("value {v} is not finite")));
        }
        if self.scale == Scale::Log {
            if let Some(v) = values.iter().find(|v| **v <= 0.0) {
                return Err(bad(format!("value {v} on a log axis: must be > 0")));
            }
        }
        Ok(values)
    }

    /// Read the command-line form `TARGET[,TARGET…]=FROM..TO:POINTS[:log]` or
    /// `TARGET[,TARGET…]=V1,V2,…` (append `:log` to a list for a log axis).
    pub fn parse_cli(text: &str) -> Result<Axis, StudyError> {
        let bad = |reason: &str| {
            StudyError::Invalid(format!(
                "axis '{text}': {reason} (expected TARGETS=FROM..TO:POINTS[:log] or TARGETS=V1,V2,…)"
            ))
        };
        let (targets, spec) = text.split_once('=').ok_or_else(|| bad("no '='"))?;
        let targets: Vec<String> = targets.split(',').map(|t| t.trim().to_string()).collect();
        let (spec, scale) = match spec.strip_suffix(":log") {
            Some(s) => (s, Scale::Log),
            None => (spec.strip_suffix(":linear").unwrap_or(spec), Scale::Linear),
        };
        let number = |s: &str| {
            s.trim()
                .parse::<f64>()
                .map_err(|_| bad(&format!("'{s}' is not a number")))
        };
        let mut axis = Axis {
            targets,
            label: None,
            values: None,
            from: None,
            to: None,
            points: None,
            scale,
        };
        if let Some((range, points)) = spec.split_once(':') {
            let (from, to) = range.split_once("..").ok_or_else(|| bad("no '..'"))?;
            axis.from = Some(number(from)?);
            axis.to = Some(number(to)?);
            axis.points = Some(
                points
                    .trim()
                    .parse()
                    .map_err(|_| bad(&format!("'{points}' is not a number of points")))?,
            );
        } else {
            axis.values = Some(spec.split(',').map(number).collect::<Result<_, _>>()?);
        }
        axis.values()?;
        Ok(axis)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_and_linear_ranges_hit_their_ends() {
        let a = Axis::parse_cli("mass1.c,mass2.c=1e2..1e5:4:log").unwrap();
        assert_eq!(a.targets, ["mass1.c", "mass2.c"]);
        let v = a.values().unwrap();
        for (got, want) in v.iter().zip([1e2, 1e3, 1e4, 1e5]) {
            assert!((got / want - 1.0).abs() < 1e-12, "{v:?}");
        }
        let b = Axis::parse_cli("mass1.d=0..10:3").unwrap();
        assert_eq!(b.values().unwrap(), [0.0, 5.0, 10.0]);
        let c = Axis::parse_cli("step=1e-3,2e-3").unwrap();
        assert_eq!(c.values().unwrap(), [1e-3, 2e-3]);
    }

    #[test]
    fn bad_axes_are_refused_with_the_reason() {
        for (text, word) in [
            ("mass1.c", "'='"),
            ("mass1.c=0..10:3:log", "> 0"),
            ("mass1.c=1..10:1", "at least 2"),
            ("mass1.c=1,x", "'x'"),
        ] {
            let e = Axis::parse_cli(text).unwrap_err().to_string();
            assert!(e.contains(word), "{text}: {e}");
        }
    }
}
