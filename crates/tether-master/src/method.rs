//! The coupling methods and their parameters.

use serde::{Deserialize, Serialize};

use crate::MasterError;

/// How corrected coupling unknowns are computed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Method {
    /// Method 1 (paper Sect. 2.1, eq. 68): one Newton step on the
    /// Baumgarte-stabilised condition `g + β ġ + γ g̈ = 0`.
    /// β = γ = 0 is index 3, β > 0 = γ index 2, β, γ > 0 index 1.
    Baumgarte {
        /// Weight of the velocity-level condition.
        #[serde(default)]
        beta: f64,
        /// Weight of the acceleration-level condition.
        #[serde(default)]
        gamma: f64,
    },
    /// Method 2 (paper Sect. 2.2, eq. 76): the position-, velocity- and
    /// acceleration-level conditions are solved separately and averaged with
    /// weights 1, a, b. a = b = 0 is index 3, a > 0 = b index 2, a, b > 0 index 1.
    Weighted {
        /// Weight of the velocity-level solution.
        #[serde(default)]
        a: f64,
        /// Weight of the acceleration-level solution.
        #[serde(default)]
        b: f64,
    },
    /// Explicit index-1 baseline with constant approximation (our
    /// reconstruction of the paper's ref. \[16\], see docs/algorithm.md):
    /// λ_N solves `μ² g̈ + 2μ ġ + g = 0` at T_N and is held over the step.
    Explicit {
        /// Stabilisation time constant μ_B (> 0).
        mu: f64,
    },
}

impl Default for Method {
    fn default() -> Self {
        Method::Baumgarte {
            beta: 0.0,
            gamma: 0.0,
        }
    }
}

impl Method {
    /// Short name as used on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Method::Baumgarte { .. } => "baumgarte",
            Method::Weighted { .. } => "weighted",
            Method::Explicit { .. } => "explicit",
        }
    }

    /// The DAE index level the parameters select (1, 2 or 3).
    pub fn index(&self) -> u8 {
        match *self {
            Method::Baumgarte { beta, gamma } => level(beta, gamma),
            Method::Weighted { a, b } => level(a, b),
            Method::Explicit { .. } => 1,
        }
    }

    /// Whether velocity-level conditions are evaluated.
    pub fn needs_velocity(&self) -> bool {
        match *self {
            Method::Baumgarte { beta, .. } => beta > 0.0,
            Method::Weighted { a, .. } => a > 0.0,
            Method::Explicit { .. } => true,
        }
    }

    /// Whether acceleration-level conditions are evaluated.
    pub fn needs_acceleration(&self) -> bool {
        match *self {
            Method::Baumgarte { gamma, .. } => gamma > 0.0,
            Method::Weighted { b, .. } => b > 0.0,
            Method::Explicit { .. } => true,
        }
    }

    /// Whether the method repeats macro steps (and so needs FMU state rollback).
    pub fn needs_rollback(&self) -> bool {
        !matches!(self, Method::Explicit { .. })
    }

    /// Reject parameters outside the method's domain.
    pub fn validate(&self) -> Result<(), MasterError> {
        let check = |name: &str, v: f64, strictly_positive: bool| {
            let ok = v.is_finite() && if strictly_positive { v > 0.0 } else { v >= 0.0 };
            if ok {
                Ok(())
            } else {
                let want = if strictly_positive { "> 0" } else { ">= 0" };
                Err(MasterError::InvalidParameter {
                    name: name.to_string(),
                    value: v,
                    expected: format!("a finite number {want} for method {}", self.name()),
                })
            }
        };
        match *self {
            Method::Baumgarte { beta, gamma } => {
                check("beta", beta, false)?;
                check("gamma", gamma, false)?;
                if gamma > 0.0 && beta == 0.0 {
                    return Err(MasterError::InvalidParameter {
                        name: "beta".into(),
                        value: beta,
                        expected: "beta > 0 when gamma > 0 (index 1 needs both)".into(),
                    });
                }
            }
            Method::Weighted { a, b } => {
                check("a", a, false)?;
                check("b", b, false)?;
                if b > 0.0 && a == 0.0 {
                    return Err(MasterError::InvalidParameter {
                        name: "a".into(),
                        value: a,
                        expected: "a > 0 when b > 0 (index 1 needs both)".into(),
                    });
                }
            }
            Method::Explicit { mu } => check("mu", mu, true)?,
        }
        Ok(())
    }
}

fn level(velocity_weight: f64, acceleration_weight: f64) -> u8 {
    if acceleration_weight > 0.0 {
        1
    } else if velocity_weight > 0.0 {
        2
    } else {
        3
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Method::Baumgarte { beta, gamma } => write!(
                f,
                "baumgarte (index {}, beta = {beta:e}, gamma = {gamma:e})",
                self.index()
            ),
            Method::Weighted { a, b } => {
                write!(f, "weighted (index {}, a = {a}, b = {b})", self.index())
            }
            Method::Explicit { mu } => write!(f, "explicit (mu = {mu:e})"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters_select_the_index_level() {
        assert_eq!(
            Method::Baumgarte {
                beta: 0.0,
                gamma: 0.0
            }
            .index(),
            3
        );
        assert_eq!(
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 0.0
            }
            .index(),
            2
        );
        assert_eq!(
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6
            }
            .index(),
            1
        );
        assert_eq!(Method::Weighted { a: 0.0, b: 0.0 }.index(), 3);
        assert_eq!(Method::Weighted { a: 1.0, b: 0.0 }.index(), 2);
        assert_eq!(Method::Weighted { a: 1.0, b: 1.0 }.index(), 1);
    }

    #[test]
    fn rejects_negative_or_non_finite_parameters() {
        assert!(Method::Baumgarte {
            beta: -1.0,
            gamma: 0.0
        }
        .validate()
        .is_err());
        assert!(Method::Baumgarte {
            beta: f64::NAN,
            gamma: 0.0
        }
        .validate()
        .is_err());
        assert!(Method::Weighted {
            a: 1.0,
            b: f64::INFINITY
        }
        .validate()
        .is_err());
        assert!(Method::Explicit { mu: 0.0 }.validate().is_err());
        assert!(Method::Baumgarte {
            beta: 0.0,
            gamma: 1e-6
        }
        .validate()
        .is_err());
        assert!(Method::Weighted { a: 1.0, b: 1.0 }.validate().is_ok());
    }
}
