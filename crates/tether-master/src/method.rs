//! The coupling methods and their parameters.

use serde::{Deserialize, Serialize};

use crate::MasterError;

/// How corrected coupling unknowns are computed.
///
/// In a system file `[method]` names the kind and either the weights (the
/// index follows from which are zero) or `index = 1 | 2 | 3` with the weights
/// it uses, those not given at the index's defaults ([`Method::at_index`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(
    tag = "kind",
    rename_all = "lowercase",
    deny_unknown_fields,
    try_from = "MethodFile"
)]
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

/// `[method]` as written: an explicit index and the weights given.
#[derive(Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum MethodFile {
    Baumgarte {
        index: Option<u8>,
        beta: Option<f64>,
        gamma: Option<f64>,
    },
    Weighted {
        index: Option<u8>,
        a: Option<f64>,
        b: Option<f64>,
    },
    Explicit {
        mu: f64,
    },
}

impl TryFrom<MethodFile> for Method {
    type Error = String;

    fn try_from(file: MethodFile) -> Result<Method, String> {
        let at = |kind, index, weights| {
            Method::at_index(kind, index, weights).map_err(|c| c.describe(false))
        };
        match file {
            MethodFile::Baumgarte { index, beta, gamma } => {
                at(IndexedKind::Baumgarte, index, [beta, gamma])
            }
            MethodFile::Weighted { index, a, b } => at(IndexedKind::Weighted, index, [a, b]),
            MethodFile::Explicit { mu } => Ok(Method::Explicit { mu }),
        }
    }
}

/// The methods with an index level: Method 1 and Method 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IndexedKind {
    /// Method 1, weights β, γ.
    Baumgarte,
    /// Method 2, weights a, b.
    Weighted,
}

impl IndexedKind {
    /// The names of the velocity- and acceleration-level weights.
    pub fn weight_names(self) -> [&'static str; 2] {
        match self {
            IndexedKind::Baumgarte => ["beta", "gamma"],
            IndexedKind::Weighted => ["a", "b"],
        }
    }

    /// The weights an explicit index gives when none are written: index 3
    /// none; Method 1 the paper's β = 2e-3 (index 2, Sect. 4.3) and
    /// γ = 1e-6 (index 1, Sect. 4.1); Method 2 a = 1 and b = 1 (Sect. 4.1.2).
    pub fn default_weights(self, index: u8) -> [f64; 2] {
        match (self, index) {
            (IndexedKind::Baumgarte, 1) => [2e-3, 1e-6],
            (IndexedKind::Baumgarte, 2) => [2e-3, 0.0],
            (IndexedKind::Weighted, 1) => [1.0, 1.0],
            (IndexedKind::Weighted, 2) => [1.0, 0.0],
            _ => [0.0, 0.0],
        }
    }

    fn method(self, [velocity, acceleration]: [f64; 2]) -> Method {
        match self {
            IndexedKind::Baumgarte => Method::Baumgarte {
                beta: velocity,
                gamma: acceleration,
            },
            IndexedKind::Weighted => Method::Weighted {
                a: velocity,
                b: acceleration,
            },
        }
    }
}

/// An explicit index that a weight given with it contradicts, or an index
/// that is not 1, 2 or 3.
#[derive(Debug, Clone, PartialEq)]
pub struct IndexConflict {
    /// The index as written.
    pub index: u8,
    /// The contradicting weight's name and value (none: the index itself is invalid).
    pub weight: Option<(&'static str, f64)>,
    /// The weights' names.
    pub names: [&'static str; 2],
}

impl IndexConflict {
    /// The message in the words of a system file (`index = 2 contradicts
    /// gamma = 0.000001`) or of the command line (`--index 2 contradicts
    /// --gamma 0.000001`).
    pub fn describe(&self, flags: bool) -> String {
        let key = |name: &str, value: String| {
            if flags {
                format!("--{name} {value}")
            } else {
                format!("{name} = {value}")
            }
        };
        let [v, a] = self.names;
        let index = key("index", self.index.to_string());
        let Some((name, value)) = self.weight else {
            return format!("{index}: expected 1, 2 or 3");
        };
        let means = match self.index {
            3 => format!("{v} = {a} = 0"),
            2 => format!("{v} > 0 and {a} = 0"),
            _ => format!("{v} > 0 and {a} > 0"),
        };
        format!(
            "{index} contradicts {}: index {} means {means}",
            key(name, value.to_string()),
            self.index
        )
    }
}

impl std::fmt::Display for IndexConflict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe(false))
    }
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

    /// Method 1 or 2 from the weights given (velocity, acceleration level)
    /// and an optional explicit index. Without an index, weights not given
    /// are 0 and the index follows from which are zero. With one, weights not
    /// given take [`IndexedKind::default_weights`], and a given weight the
    /// index does not allow (index 3: both 0; index 2: velocity > 0,
    /// acceleration 0; index 1: both > 0) is an error.
    pub fn at_index(
        kind: IndexedKind,
        index: Option<u8>,
        weights: [Option<f64>; 2],
    ) -> Result<Method, IndexConflict> {
        let Some(index) = index else {
            return Ok(kind.method(weights.map(|w| w.unwrap_or(0.0))));
        };
        let conflict = |weight| IndexConflict {
            index,
            weight,
            names: kind.weight_names(),
        };
        if !(1..=3).contains(&index) {
            return Err(conflict(None));
        }
        let defaults = kind.default_weights(index);
        let mut chosen = defaults;
        for (level, given) in weights.into_iter().enumerate() {
            let Some(w) = given else { continue };
            // Level 0 (velocity) is used by index ≤ 2, level 1 by index 1.
            let used = usize::from(index) <= 2 - level;
            let fits = if used { w > 0.0 } else { w == 0.0 };
            if !fits {
                return Err(conflict(Some((kind.weight_names()[level], w))));
            }
            chosen[level] = w;
        }
        Ok(kind.method(chosen))
    }

    /// A warning for a formulation that the paper's Sect. 4 and the stability
    /// maps of docs/paper-reproduction.md show unstable over most of their
    /// range, keyed by (method, index, k = `order`), with the recommended
    /// alternative. `None` for the others.
    pub fn stability_warning(&self, order: usize) -> Option<String> {
        let k = order;
        let index = self.index();
        match (self, index, k) {
            (Method::Explicit { .. }, _, _) | (_, _, 0) => None,
            (_, 3, _) => Some(format!(
                "{} index 3 with k = {k} is unstable over the whole stability map \
                 (0 of 121 cells at k = 1, docs/paper-reproduction.md); use k = 0, \
                 or index 1 with k = {k} (kind = \"baumgarte\", index = 1)",
                self.name()
            )),
            (Method::Baumgarte { .. }, 2, _) => Some(format!(
                "baumgarte index 2 with k = {k} is unstable over most of the range \
                 (33 of 121 cells stable at k = 1, only for d >= 1000, docs/paper-reproduction.md); \
                 use k = 0, or index 1 with k = {k} (index = 1: beta = 2e-3, gamma = 1e-6)"
            )),
            (Method::Weighted { .. }, 2, _) => Some(format!(
                "weighted index 2 with k = {k} is unstable in every cell of the H-c stability map \
                 (docs/paper-reproduction.md); use k = 0, or kind = \"baumgarte\", index = 1 with k = {k}"
            )),
            (Method::Weighted { .. }, 1, 2) => Some(
                "weighted index 1 with k = 2 is unstable for H below about 4e-3 \
                 (H-c stability map at a = b = 1, docs/paper-reproduction.md); \
                 use kind = \"baumgarte\", index = 1 with k = 2 (stable for H <= 1.4e-3)"
                    .to_string(),
            ),
            _ => None,
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

    #[test]
    fn an_explicit_index_takes_the_papers_weights_or_checks_the_given_ones() {
        let read = |text: &str| -> Result<Method, String> {
            #[derive(Deserialize)]
            struct File {
                method: Method,
            }
            toml::from_str::<File>(text)
                .map(|f| f.method)
                .map_err(|e| e.message().to_string())
        };
        let cases = [
            (
                "kind = 'baumgarte'\nindex = 1",
                "baumgarte (index 1, beta = 2e-3, gamma = 1e-6)",
            ),
            (
                "kind = 'baumgarte'\nindex = 2",
                "baumgarte (index 2, beta = 2e-3, gamma = 0e0)",
            ),
            (
                "kind = 'baumgarte'\nindex = 2\nbeta = 0.1",
                "baumgarte (index 2, beta = 1e-1, gamma = 0e0)",
            ),
            (
                "kind = 'baumgarte'\nindex = 3",
                "baumgarte (index 3, beta = 0e0, gamma = 0e0)",
            ),
            (
                "kind = 'weighted'\nindex = 1",
                "weighted (index 1, a = 1, b = 1)",
            ),
            (
                "kind = 'weighted'\nindex = 2\nb = 0.0",
                "weighted (index 2, a = 1, b = 0)",
            ),
            (
                "kind = 'weighted'\nb = 0.5\na = 2.0",
                "weighted (index 1, a = 2, b = 0.5)",
            ),
        ];
        for (text, shown) in cases {
            let method = read(&format!("[method]\n{text}")).unwrap();
            assert_eq!(method.to_string(), shown, "{text}");
        }
        assert_eq!(
            read("[method]\nkind = 'baumgarte'\nindex = 1\ngamma = 0.0").unwrap_err(),
            "index = 1 contradicts gamma = 0: index 1 means beta > 0 and gamma > 0"
        );
        assert_eq!(
            read("[method]\nkind = 'explicit'\nmu = 0.1\nindex = 1").unwrap_err(),
            "unknown field `index`, expected `mu`"
        );
        // Written back, a method is its weights (the form every version reads).
        let m = read("[method]\nkind = 'weighted'\nindex = 2").unwrap();
        let text = toml::to_string(&m).unwrap();
        assert_eq!(text, "kind = \"weighted\"\na = 1.0\nb = 0.0\n");
    }

    #[test]
    fn stability_warnings_are_keyed_by_method_index_and_degree() {
        let b = |beta, gamma| Method::Baumgarte { beta, gamma };
        let w = |a, b| Method::Weighted { a, b };
        let warned = |m: Method, k| m.stability_warning(k).is_some();
        assert!(
            !warned(b(2e-3, 1e-6), 0) && !warned(b(2e-3, 1e-6), 1) && !warned(b(2e-3, 1e-6), 2)
        );
        assert!(!warned(b(2e-3, 0.0), 0) && warned(b(2e-3, 0.0), 1) && warned(b(2e-3, 0.0), 2));
        assert!(!warned(b(0.0, 0.0), 0) && warned(b(0.0, 0.0), 1) && warned(w(0.0, 0.0), 2));
        assert!(!warned(w(1.0, 0.0), 0) && warned(w(1.0, 0.0), 1));
        assert!(!warned(w(1.0, 1.0), 1) && warned(w(1.0, 1.0), 2));
        assert!(!warned(Method::Explicit { mu: 1e-3 }, 0));
        assert_eq!(
            w(1.0, 1.0).stability_warning(2).unwrap(),
            "weighted index 1 with k = 2 is unstable for H below about 4e-3 \
             (H-c stability map at a = b = 1, docs/paper-reproduction.md); \
             use kind = \"baumgarte\", index = 1 with k = 2 (stable for H <= 1.4e-3)"
        );
    }
}
