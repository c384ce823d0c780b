//! Convergence: the global error of chosen columns over the macro-step size H.

use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::reference::{Reference, ReferenceSpec};
use crate::runner::{self, Outcome, RunResult};
use crate::{StudyError, Variant};

/// What a convergence study measures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Convergence {
    /// The macro-step sizes H (at least two, all > 0).
    pub steps: Vec<f64>,
    /// The reference solution.
    pub reference: ReferenceSpec,
    /// The columns whose error is measured, e.g. `["mass1.x", "mass1.v"]`.
    pub columns: Vec<String>,
}

/// One run of a convergence curve.
#[derive(Debug, Clone)]
pub struct ConvergencePoint {
    /// The macro-step size H.
    pub step: f64,
    /// How the run ended.
    pub outcome: Outcome,
    /// Per column: max over all macro points of |value − reference| (NaN if
    /// the run did not complete).
    pub errors: Vec<f64>,
    /// The global error: the largest of `errors`.
    pub error: f64,
}

/// The convergence curve of one variant.
#[derive(Debug, Clone)]
pub struct ConvergenceCurve {
    /// The variant's label.
    pub label: String,
    /// One point per H (without the finest run when it is the reference),
    /// in the order of the study's steps.
    pub points: Vec<ConvergencePoint>,
    /// Least-squares slope of log(error) over log(H) over the completed runs.
    pub order: Option<f64>,
}

impl Convergence {
    /// Check the settings that do not need the system.
    pub fn validate(&self) -> Result<(), StudyError> {
        let bad = |r: String| StudyError::Invalid(format!("convergence: {r}"));
        if self.steps.len() < 2 {
            return Err(bad("give at least two steps".into()));
        }
        if let Some(h) = self.steps.iter().find(|h| !h.is_finite() || **h <= 0.0) {
            return Err(bad(format!("step {h} must be finite and > 0")));
        }
        if self.columns.is_empty() {
            return Err(bad("no columns to measure".into()));
        }
        Ok(())
    }

    fn finest(&self) -> f64 {
        self.steps.iter().copied().fold(f64::INFINITY, f64::min)
    }

    fn uses_finest(&self) -> bool {
        matches!(&self.reference, ReferenceSpec::Named(n) if n == "finest")
    }
}

/// Run every variant at every H in parallel and measure the errors.
/// `base` is the folder a reference CSV is relative to; `progress` is called
/// once per finished run.
pub fn convergence(
    variants: &[Variant],
    study: &Convergence,
    base: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<ConvergenceCurve>, StudyError> {
    convergence_check(variants, study)?;
    let jobs = convergence_jobs(variants.len(), study);
    let runs: Vec<RunResult> = jobs
        .par_iter()
        .map(|&(v, h)| {
            let result = convergence_run(&variants[v], h);
            progress();
            result
        })
        .collect();
    convergence_curves(variants, study, base, &jobs, &runs)
}

/// Check each variant once (at the first H), as `tether run` would before
/// its first step.
pub fn convergence_check(variants: &[Variant], study: &Convergence) -> Result<(), StudyError> {
    study.validate()?;
    for v in variants {
        let mut spec = v.spec.clone();
        spec.experiment.step = study.steps[0];
        runner::check(&spec)?;
    }
    Ok(())
}

/// The runs of `variants` variants as jobs `(variant, H)`, every variant's
/// steps in the study's order.
pub fn convergence_jobs(variants: usize, study: &Convergence) -> Vec<(usize, f64)> {
    (0..variants)
        .flat_map(|v| study.steps.iter().map(move |&h| (v, h)))
        .collect()
}

/// One run of a study: the variant at macro-step size `h`.
pub fn convergence_run(variant: &Variant, h: f64) -> RunResult {
    let mut spec = variant.spec.clone();
    spec.experiment.step = h;
    runner::run(&spec, &format!("{} H = {h:e}", variant.label))
}

/// The curves from the runs of every job of [`convergence_jobs`], in its
/// order: the errors against the reference and the fitted orders.
pub fn convergence_curves(
    variants: &[Variant],
    study: &Convergence,
    base: &Path,
    jobs: &[(usize, f64)],
    runs: &[RunResult],
) -> Result<Vec<ConvergenceCurve>, StudyError> {
    if jobs.len() != runs.len() {
        return Err(StudyError::Invalid(format!(
            "{} runs for {} jobs",
            runs.len(),
            jobs.len()
        )));
    }
    let finest = study.finest();
    let mut curves = Vec::new();
    for (v, variant) in variants.iter().enumerate() {
        let mine: Vec<(f64, &RunResult)> = jobs
            .iter()
            .zip(runs)
            .filter(|((j, _), _)| *j == v)
            .map(|((_, h), r)| (*h, r))
            .collect();
        let finest_table = if study.uses_finest() {
            let (_, run) = mine.iter().find(|(h, _)| *h == finest).expect("finest run");
            if let Some(m) = run.outcome.message() {
                return Err(StudyError::Invalid(format!(
                    "{}: the finest run (H = {finest:e}), the reference, did not complete: {m}",
                    variant.label
                )));
            }
            Some(run.table.clone())
        } else {
            None
        };
        let reference = Reference::resolve(&study.reference, &variant.spec, base, finest_table)?;
        let keys = reference.columns(&study.columns)?;
        let mut points = Vec::new();
        for (h, run) in mine {
            if study.uses_finest() && h == finest {
                continue;
            }
            let errors = if run.outcome == Outcome::Completed {
                column_errors(run, &study.columns, &keys, &reference)?
            } else {
                vec![f64::NAN; keys.len()]
            };
            let error = if errors.iter().any(|e| e.is_nan()) {
                f64::NAN
            } else {
                errors.iter().copied().fold(0.0, f64::max)
            };
            points.push(ConvergencePoint {
                step: h,
                outcome: run.outcome.clone(),
                errors,
                error,
            });
        }
        let fit: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.error.is_finite() && p.error > 0.0)
            .map(|p| (p.step, p.error))
            .collect();
        curves.push(ConvergenceCurve {
            label: variant.label.clone(),
            order: fitted_order(&fit),
            points,
        });
    }
    Ok(curves)
}

fn column_errors(
    run: &RunResult,
    columns: &[String],
    keys: &[usize],
    reference: &Reference,
) -> Result<Vec<f64>, StudyError> {
    let mut errors = Vec::with_capacity(columns.len());
    for (name, &key) in columns.iter().zip(keys) {
        let values = run.table.series(name)?;
        let mut worst: f64 = 0.0;
        for (&t, &y) in run.table.times.iter().zip(values) {
            let r = reference.at(key, t).ok_or_else(|| {
                StudyError::Invalid(format!(
                    "reference {} has no value of {name} at t = {t}",
                    reference.describe()
                ))
            })?;
            worst = worst.max((y - r).abs());
        }
        errors.push(worst);
    }
    Ok(errors)
}

/// Least-squares slope of log(error) over log(H); `None` below two distinct H.
pub fn fitted_order(points: &[(f64, f64)]) -> Option<f64> {
    if points.len() < 2 {
        return None;
    }
    let xs: Vec<f64> = points.iter().map(|p| p.0.ln()).collect();
    let ys: Vec<f64> = points.iter().map(|p| p.1.ln()).collect();
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fitted_order_recovers_a_power_law() {
        let pts: Vec<(f64, f64)> = [1e-2, 5e-3, 2e-3, 1e-3]
            .iter()
            .map(|&h| (h, 3.0 * h * h))
            .collect();
        assert!((fitted_order(&pts).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(fitted_order(&pts[..1]), None);
        assert_eq!(fitted_order(&[(1e-3, 1.0), (1e-3, 2.0)]), None);
    }
}
