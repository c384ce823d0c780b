//! Adaptive macro steps (`[step_control]`, beyond the paper): the settings and
//! the PI step-size controller (Hairer & Wanner, Solving ODEs II, Sect. IV.2;
//! Gustafsson's PI form). The error norm it is fed comes from
//! [`crate::algorithm::error_estimate`].

use serde::{Deserialize, Serialize};

use crate::MasterError;

/// `[step_control]`: the macro step follows a local error estimate instead of
/// the fixed `[experiment] step`. Absent (the default): fixed steps.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepControl {
    /// Relative tolerance of the local error estimate.
    #[serde(default = "default_rtol")]
    pub rtol: f64,
    /// Absolute tolerance of the local error estimate.
    #[serde(default = "default_atol")]
    pub atol: f64,
    /// Smallest macro step; a step rejected at it stops the run. Default
    /// 1e-10·(stop − start).
    #[serde(default)]
    pub h_min: Option<f64>,
    /// Largest macro step. Default (stop − start)/10.
    #[serde(default)]
    pub h_max: Option<f64>,
    /// First macro step. Default `[experiment] step`.
    #[serde(default)]
    pub h_initial: Option<f64>,
}

fn default_rtol() -> f64 {
    1e-4
}

fn default_atol() -> f64 {
    1e-6
}

impl Default for StepControl {
    fn default() -> Self {
        StepControl {
            rtol: default_rtol(),
            atol: default_atol(),
            h_min: None,
            h_max: None,
            h_initial: None,
        }
    }
}

/// The step sizes of a run, defaults filled in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Limits {
    pub h_min: f64,
    pub h_max: f64,
    pub h_initial: f64,
}

impl StepControl {
    /// The limits for a run over `[start, stop]` with `[experiment] step`,
    /// checked.
    pub(crate) fn limits(&self, start: f64, stop: f64, step: f64) -> Result<Limits, MasterError> {
        let span = stop - start;
        let param = |name: &str, value: f64, expected: &str| MasterError::InvalidParameter {
            name: format!("step_control.{name}"),
            value,
            expected: expected.into(),
        };
        for (name, v) in [("rtol", self.rtol), ("atol", self.atol)] {
            if !v.is_finite() || v < 0.0 {
                return Err(param(name, v, "a finite tolerance >= 0"));
            }
        }
        if self.rtol == 0.0 && self.atol == 0.0 {
            return Err(param("rtol", 0.0, "rtol > 0 or atol > 0"));
        }
        let limits = Limits {
            h_min: self.h_min.unwrap_or(1e-10 * span),
            h_max: self.h_max.unwrap_or(span / 10.0),
            h_initial: self.h_initial.unwrap_or(step),
        };
        for (name, v) in [
            ("h_min", limits.h_min),
            ("h_max", limits.h_max),
            ("h_initial", limits.h_initial),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return Err(param(name, v, "a finite step size > 0"));
            }
        }
        if limits.h_max < limits.h_min {
            return Err(param("h_max", limits.h_max, "h_max >= h_min"));
        }
        Ok(limits)
    }
}

/// Safety factor on the optimal step.
const SAFETY: f64 = 0.9;
/// The step changes at most by these factors from one step to the next.
const SHRINK_MOST: f64 = 0.2;
const GROW_MOST: f64 = 5.0;

/// The PI controller: the next step from this step's error norm (≤ 1 is
/// accepted) and the last accepted one's,
/// `h·safety·err^(−0.7/p)·err_prev^(0.4/p)`, limited to a factor in
/// [0.2, 5] and to [h_min, h_max]; after a rejection the step does not grow.
#[derive(Debug, Clone)]
pub(crate) struct Controller {
    pub limits: Limits,
    /// The order p of the local error (k + 2 for polynomials of degree k).
    order: f64,
    /// The last accepted step's error norm.
    previous: f64,
    /// Whether the last attempt was rejected.
    rejected: bool,
}

impl Controller {
    pub fn new(limits: Limits, degree: usize) -> Controller {
        Controller {
            limits,
            order: degree as f64 + 2.0,
            previous: 1.0,
            rejected: false,
        }
    }

    /// The step after one of size `h` with error norm `err`, and whether `h`
    /// is accepted (a NaN norm is a rejection).
    pub fn next(&mut self, h: f64, err: f64) -> (f64, bool) {
        if err.is_nan() {
            self.rejected = true;
            let next = h * SHRINK_MOST;
            return (next.clamp(self.limits.h_min, self.limits.h_max), false);
        }
        let err = err.max(1e-10);
        let p = self.order;
        let accepted = err <= 1.0;
        let factor = if accepted {
            let f = SAFETY * err.powf(-0.7 / p) * self.previous.powf(0.4 / p);
            let f = if self.rejected { f.min(1.0) } else { f };
            self.previous = err;
            f
        } else {
            SAFETY * err.powf(-1.0 / p)
        };
        self.rejected = !accepted;
        let next = h * factor.clamp(SHRINK_MOST, GROW_MOST);
        (next.clamp(self.limits.h_min, self.limits.h_max), accepted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn controller() -> Controller {
        let limits = StepControl::default().limits(0.0, 1.0, 1e-3).unwrap();
        Controller::new(limits, 0)
    }

    #[test]
    fn step_control_defaults_are_valid_and_limits_are_refused() {
        let l = StepControl::default().limits(0.0, 2.0, 1e-3).unwrap();
        assert_eq!((l.h_min, l.h_max, l.h_initial), (2e-10, 0.2, 1e-3));
        let bad = StepControl {
            h_max: Some(1e-12),
            ..StepControl::default()
        };
        assert!(bad.limits(0.0, 2.0, 1e-3).is_err());
        let bad = StepControl {
            rtol: 0.0,
            atol: 0.0,
            ..StepControl::default()
        };
        assert!(bad.limits(0.0, 2.0, 1e-3).is_err());
    }

    #[test]
    fn grows_on_small_errors_and_shrinks_on_rejection() {
        let mut c = controller();
        let (h, ok) = c.next(1e-3, 1e-6);
        assert!(ok && h == 5e-3, "{h}");
        let (h2, ok) = c.next(h, 4.0);
        assert!(!ok && h2 < h && h2 >= SHRINK_MOST * h, "{h2}");
        // After a rejection the accepted step does not grow.
        let (h3, ok) = c.next(h2, 1e-3);
        assert!(ok && h3 <= h2, "{h3}");
        // Errors of 1 in a row keep the step (less the safety factor).
        let mut c = controller();
        let (h4, ok) = c.next(1e-3, 1.0);
        assert!(ok && (h4 - 0.9e-3).abs() < 1e-15, "{h4}");
    }
}
