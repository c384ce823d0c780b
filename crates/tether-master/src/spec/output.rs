//! `[output]`: which points and columns are recorded, and the column patterns.

use serde::{Deserialize, Serialize};

use crate::MasterError;

/// `[output]`: which points and which columns reach the observers (the
/// results file). The run itself, its divergence checks and the summary's
/// max |g| still see every macro point and every column.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Record every `interval / step`-th macro point (a whole multiple of the
    /// step), plus the last point of the run. Default: every macro point.
    #[serde(default)]
    pub interval: Option<f64>,
    /// Column patterns: `*` matches any characters, everything else is taken
    /// literally (`body.R[1,2]`, `link.*`). Default (empty): every column.
    #[serde(default)]
    pub variables: Vec<String>,
}

impl OutputSpec {
    /// Every point and every column (an `[output]` that changes nothing).
    pub fn is_default(&self) -> bool {
        *self == OutputSpec::default()
    }

    /// The macro steps between two recorded points: `interval / step`, which
    /// must be a whole number ≥ 1 (to a relative 1e-9).
    pub fn every(&self, step: f64) -> Result<u64, MasterError> {
        let Some(interval) = self.interval else {
            return Ok(1);
        };
        let ratio = interval / step;
        let whole = ratio.round();
        if !interval.is_finite() || whole < 1.0 || (ratio - whole).abs() > 1e-9 * whole {
            return Err(MasterError::InvalidParameter {
                name: "output interval".into(),
                value: interval,
                expected: format!(
                    "a whole multiple of the step H = {step} (the nearest is {}·H)",
                    whole.max(1.0)
                ),
            });
        }
        Ok(whole as u64)
    }

    /// The indices of the `columns` the patterns select, in column order;
    /// every column without patterns. A pattern that matches no column is an
    /// error naming it.
    pub fn select(&self, columns: &[String]) -> Result<Vec<usize>, MasterError> {
        if self.variables.is_empty() {
            return Ok((0..columns.len()).collect());
        }
        for pattern in &self.variables {
            if !columns.iter().any(|c| matches_pattern(pattern, c)) {
                let hint = crate::spec::names::suggest(pattern, columns.iter().map(String::as_str));
                return Err(MasterError::InvalidOutput(format!(
                    "[output] variables, pattern '{pattern}': matches no column{hint}"
                )));
            }
        }
        Ok((0..columns.len())
            .filter(|&i| {
                self.variables
                    .iter()
                    .any(|p| matches_pattern(p, &columns[i]))
            })
            .collect())
    }
}

/// Whether `name` matches `pattern`: `*` matches any run of characters
/// (also none), every other character only itself.
pub fn matches_pattern(pattern: &str, name: &str) -> bool {
    let mut parts = pattern.split('*');
    let first = parts.next().unwrap_or("");
    let Some(mut rest) = name.strip_prefix(first) else {
        return false;
    };
    let parts: Vec<&str> = parts.collect();
    let Some((last, middle)) = parts.split_last() else {
        return rest.is_empty(); // no '*': the whole name
    };
    for part in middle {
        match rest.find(part) {
            Some(i) => rest = &rest[i + part.len()..],
            None => return false,
        }
    }
    rest.len() >= last.len() && rest.ends_with(last)
}
