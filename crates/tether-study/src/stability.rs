//! Stability maps: a grid over two quantities, each cell run and classified.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tether_master::{Overrides, StartValue, SystemSpec};

use crate::axis::Axis;
use crate::runner::{self, Outcome, RunResult};
use crate::{StudyError, Variant};

/// What a stability map sweeps and how cells are judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stability {
    /// The horizontal axis.
    pub x: Axis,
    /// The vertical axis.
    pub y: Axis,
    /// Optional growth criterion: a completed run is unstable if a monitored
    /// column's peak magnitude over the last tenth of the macro points
    /// exceeds `growth` times its peak over the first tenth. For passive
    /// systems (springs, dampers, no driving) `growth = 1` is natural.
    #[serde(default)]
    pub growth: Option<f64>,
    /// Columns the growth criterion watches (default: every column except
    /// the position residuals `<constraint>.g`, which start at zero).
    #[serde(default)]
    pub monitor: Vec<String>,
}

/// The class of one cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Class {
    /// Reached the stop time without diverging (and passed the growth criterion).
    Stable,
    /// Stopped by the master's divergence check, or failed the growth criterion.
    Unstable,
    /// Stopped by another error (singular Jacobian, FMU error, bad value).
    Failed,
}

impl Class {
    /// `stable`, `unstable` or `failed`.
    pub fn word(&self) -> &'static str {
        match self {
            Class::Stable => "stable",
            Class::Unstable => "unstable",
            Class::Failed => "failed",
        }
    }
}

/// One grid cell.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// Value on the x axis.
    pub x: f64,
    /// Value on the y axis.
    pub y: f64,
    /// Its class.
    pub class: Class,
    /// The last time reached.
    pub reached: f64,
    /// Why it is unstable or failed (empty when stable).
    pub reason: String,
}

/// The map of one variant.
#[derive(Debug, Clone)]
pub struct StabilityMap {
    /// The variant's label.
    pub label: String,
    /// Cells, x varying fastest.
    pub cells: Vec<Cell>,
}

impl Stability {
    /// Check the axes and the growth factor.
    pub fn validate(&self) -> Result<(Vec<f64>, Vec<f64>), StudyError> {
        if let Some(g) = self.growth {
            if !g.is_finite() || g <= 0.0 {
                return Err(StudyError::Invalid(format!(
                    "stability: growth = {g}: expected a finite number > 0"
                )));
            }
        }
        Ok((self.x.values()?, self.y.values()?))
    }
}

/// Set one axis target to a number: `step` (the macro-step size H), `stop`,
/// or an FMU parameter `instance.parameter` (checked when applied).
fn set_target(set: &mut Overrides, target: &str, value: f64) {
    match target {
        "step" => set.step = Some(value),
        "stop" => set.stop = Some(value),
        _ => {
            set.parameters
                .insert(target.to_string(), StartValue::Real(value));
        }
    }
}

/// Run every cell of every variant in parallel and classify it.
pub fn stability(
    variants: &[Variant],
    study: &Stability,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<StabilityMap>, StudyError> {
    stability_check(variants, study)?;
    let jobs = stability_jobs(variants.len(), study)?;
    let cells: Vec<Result<Cell, StudyError>> = jobs
        .par_iter()
        .map(|&(v, x, y)| {
            let cell = stability_cell(&variants[v], study, x, y);
            progress();
            cell
        })
        .collect();
    stability_maps(
        variants,
        study,
        cells.into_iter().collect::<Result<_, _>>()?,
    )
}

/// Check names, capabilities and parameters once per variant (at its first
/// cell), as `tether run` would before its first step.
pub fn stability_check(variants: &[Variant], study: &Stability) -> Result<(), StudyError> {
    let (xs, ys) = study.validate()?;
    for v in variants {
        runner::check(&cell_spec(v, study, xs[0], ys[0])?)?;
    }
    Ok(())
}

/// The cells of the maps of `variants` variants as jobs `(variant, x, y)`,
/// every variant's x varying fastest.
pub fn stability_jobs(
    variants: usize,
    study: &Stability,
) -> Result<Vec<(usize, f64, f64)>, StudyError> {
    let (xs, ys) = study.validate()?;
    Ok((0..variants)
        .flat_map(|v| {
            let xs = &xs;
            ys.iter()
                .flat_map(move |&y| xs.iter().map(move |&x| (v, x, y)))
        })
        .collect())
}

/// The system of one cell: the variant with the axis values set.
fn cell_spec(v: &Variant, study: &Stability, x: f64, y: f64) -> Result<SystemSpec, StudyError> {
    let mut set = Overrides::default();
    for t in &study.x.targets {
        set_target(&mut set, t, x);
    }
    for t in &study.y.targets {
        set_target(&mut set, t, y);
    }
    let mut spec = v.spec.clone();
    set.apply(&mut spec)?;
    Ok(spec)
}

/// One cell: run the variant with the axis values `x`, `y` and classify it.
/// The same wherever it runs: the cell depends on nothing but its arguments.
pub fn stability_cell(
    variant: &Variant,
    study: &Stability,
    x: f64,
    y: f64,
) -> Result<Cell, StudyError> {
    let spec = cell_spec(variant, study, x, y)?;
    let run = runner::run(&spec, &variant.label);
    classify(&run, x, y, study)
}

/// The maps from the cells of every job of [`stability_jobs`], in its order.
pub fn stability_maps(
    variants: &[Variant],
    study: &Stability,
    mut cells: Vec<Cell>,
) -> Result<Vec<StabilityMap>, StudyError> {
    let (xs, ys) = study.validate()?;
    let per_map = xs.len() * ys.len();
    if cells.len() != per_map * variants.len() {
        return Err(StudyError::Invalid(format!(
            "{} cells for {} maps of {per_map}",
            cells.len(),
            variants.len()
        )));
    }
    Ok(variants
        .iter()
        .map(|v| StabilityMap {
            label: v.label.clone(),
            cells: cells.drain(..per_map).collect(),
        })
        .collect())
}

fn classify(run: &RunResult, x: f64, y: f64, study: &Stability) -> Result<Cell, StudyError> {
    let reached = run.table.times.last().copied().unwrap_or(f64::NAN);
    let cell = |class, reason: String| Cell {
        x,
        y,
        class,
        reached,
        reason,
    };
    match &run.outcome {
        Outcome::Diverged(m) => return Ok(cell(Class::Unstable, m.clone())),
        Outcome::Failed(m) => return Ok(cell(Class::Failed, m.clone())),
        Outcome::Completed => {}
    }
    let Some(growth) = study.growth else {
        return Ok(cell(Class::Stable, String::new()));
    };
    let table = &run.table;
    let monitored: Vec<usize> = if study.monitor.is_empty() {
        (0..table.columns.len())
            .filter(|&c| !table.columns[c].ends_with(".g"))
            .collect()
    } else {
        study
            .monitor
            .iter()
            .map(|m| table.column(m))
            .collect::<Result<_, _>>()?
    };
    let n = table.times.len();
    let w = (n / 10).max(1);
    let peak = |c: usize, range: std::ops::Range<usize>| {
        table.values[c][range]
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
    };
    for c in monitored {
        let (early, late) = (peak(c, 0..w), peak(c, n - w..n));
        if late > growth * early {
            return Ok(cell(
                Class::Unstable,
                format!(
                    "{} grew: peak {early:.3e} over the first tenth, {late:.3e} over the last",
                    table.columns[c]
                ),
            ));
        }
    }
    Ok(cell(Class::Stable, String::new()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_targets_become_settings() {
        let mut set = Overrides::default();
        set_target(&mut set, "step", 5e-3);
        set_target(&mut set, "stop", 2.0);
        set_target(&mut set, "mass1.c", 1e3);
        set_target(&mut set, "mass1.c", 2e3);
        assert_eq!((set.step, set.stop), (Some(5e-3), Some(2.0)));
        assert_eq!(set.parameters["mass1.c"], StartValue::Real(2e3));
        assert_eq!(set.parameters.len(), 1);
    }
}
