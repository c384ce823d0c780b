//! Writing study results: CSV files, text summaries and plots.

use std::fmt::Write as _;
use std::path::Path;

use crate::convergence::{Convergence, ConvergenceCurve};
use crate::plot::{self, ConvergencePlot, SeriesPlot, StabilityPlot};
use crate::runner::RunResult;
use crate::series::Series;
use crate::stability::{Class, Stability, StabilityMap};
use crate::StudyError;

fn writer(path: &Path) -> Result<csv::Writer<std::fs::File>, StudyError> {
    csv::Writer::from_path(path).map_err(|e| csv_error(path, e))
}

fn csv_error(path: &Path, e: impl std::fmt::Display) -> StudyError {
    StudyError::Csv {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

fn num(v: f64) -> String {
    format!("{v}")
}

/// Long format: `run,time,<columns…>`, the runs one after another.
pub fn write_series(path: &Path, runs: &[RunResult]) -> Result<(), StudyError> {
    let mut w = writer(path)?;
    let Some(first) = runs.first() else {
        return Ok(());
    };
    let mut header = vec!["run".to_string(), "time".to_string()];
    header.extend(first.table.columns.iter().cloned());
    w.write_record(&header).map_err(|e| csv_error(path, e))?;
    for run in runs {
        let t = &run.table;
        for (i, time) in t.times.iter().enumerate() {
            let mut row = vec![t.source.clone(), num(*time)];
            row.extend(t.values.iter().map(|c| num(c[i])));
            w.write_record(&row).map_err(|e| csv_error(path, e))?;
        }
    }
    w.flush().map_err(|e| csv_error(path, e))
}

/// Plot the chosen columns of every run.
pub fn plot_series(
    path: &Path,
    title: &str,
    study: &Series,
    runs: &[RunResult],
) -> Result<(), StudyError> {
    let columns = match runs.first() {
        None => Vec::new(),
        Some(r) if study.columns.is_empty() => r.table.columns.clone(),
        Some(r) => crate::series::expand_columns(&r.table, &study.columns)?,
    };
    let figure = SeriesPlot {
        title: title.to_string(),
        columns,
        runs: runs
            .iter()
            .map(|r| (r.table.source.clone(), &r.table))
            .collect(),
        units: Vec::new(),
    };
    plot::save(path, &figure)
}

/// `variant,step,outcome,error,<error of each column…>,order`.
pub fn write_convergence(
    path: &Path,
    study: &Convergence,
    curves: &[ConvergenceCurve],
) -> Result<(), StudyError> {
    let mut w = writer(path)?;
    let mut header = vec!["variant", "step", "outcome", "error"]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
    header.extend(study.columns.iter().map(|c| format!("error {c}")));
    header.push("order".into());
    w.write_record(&header).map_err(|e| csv_error(path, e))?;
    for c in curves {
        for p in &c.points {
            let mut row = vec![
                c.label.clone(),
                num(p.step),
                p.outcome.word().into(),
                num(p.error),
            ];
            row.extend(p.errors.iter().map(|&e| num(e)));
            row.push(c.order.map(num).unwrap_or_default());
            w.write_record(&row).map_err(|e| csv_error(path, e))?;
        }
    }
    w.flush().map_err(|e| csv_error(path, e))
}

/// A text table of the errors and the fitted orders.
pub fn convergence_table(study: &Convergence, curves: &[ConvergenceCurve]) -> String {
    let mut s = String::new();
    for c in curves {
        let order = c
            .order
            .map(|p| format!("{p:.2}"))
            .unwrap_or_else(|| "-".into());
        let _ = writeln!(s, "  {}: fitted order {order}", c.label);
        let _ = write!(s, "    {:>10}  {:>10}", "H", "error");
        for col in &study.columns {
            let _ = write!(s, "  {col:>12}");
        }
        s.push('\n');
        for p in &c.points {
            let _ = write!(s, "    {:>10.3e}  {:>10.3e}", p.step, p.error);
            for e in &p.errors {
                let _ = write!(s, "  {e:>12.3e}");
            }
            if let Some(m) = p.outcome.message() {
                let _ = write!(s, "  ({}: {m})", p.outcome.word());
            }
            s.push('\n');
        }
    }
    s
}

/// Plot error over H with slopes 1 and 2.
pub fn plot_convergence(
    path: &Path,
    title: &str,
    study: &Convergence,
    curves: &[ConvergenceCurve],
) -> Result<(), StudyError> {
    let figure = ConvergencePlot {
        title: title.to_string(),
        error_label: format!("global error max|{}|", study.columns.join("|, |")),
        x_label: "macro-step size H".into(),
        curves,
        slopes: vec![1, 2],
    };
    plot::save(path, &figure)
}

/// `variant,<x title>,<y title>,class,reached,reason`.
pub fn write_stability(
    path: &Path,
    study: &Stability,
    maps: &[StabilityMap],
) -> Result<(), StudyError> {
    let mut w = writer(path)?;
    w.write_record([
        "variant",
        &study.x.title(),
        &study.y.title(),
        "class",
        "reached",
        "reason",
    ])
    .map_err(|e| csv_error(path, e))?;
    for m in maps {
        for c in &m.cells {
            w.write_record([
                m.label.as_str(),
                &num(c.x),
                &num(c.y),
                c.class.word(),
                &num(c.reached),
                &c.reason,
            ])
            .map_err(|e| csv_error(path, e))?;
        }
    }
    w.flush().map_err(|e| csv_error(path, e))
}

/// Each map as text: `O` stable, `x` unstable, `!` failed; y grows upwards.
pub fn stability_text(study: &Stability, maps: &[StabilityMap]) -> Result<String, StudyError> {
    let (xs, ys) = study.validate()?;
    let mut s = String::new();
    for m in maps {
        let count = |k: Class| m.cells.iter().filter(|c| c.class == k).count();
        let _ = writeln!(
            s,
            "  {}: {} stable, {} unstable, {} failed  (rows: {} from top; columns: {} {:e} … {:e})",
            m.label,
            count(Class::Stable),
            count(Class::Unstable),
            count(Class::Failed),
            study.y.title(),
            study.x.title(),
            xs[0],
            xs[xs.len() - 1]
        );
        for j in (0..ys.len()).rev() {
            let row: String = (0..xs.len())
                .map(|i| match m.cells[j * xs.len() + i].class {
                    Class::Stable => 'O',
                    Class::Unstable => 'x',
                    Class::Failed => '!',
                })
                .collect();
            let _ = writeln!(s, "    {:>10.3e}  {row}", ys[j]);
        }
    }
    Ok(s)
}

/// Plot the maps side by side.
pub fn plot_stability(
    path: &Path,
    title: &str,
    study: &Stability,
    maps: &[StabilityMap],
) -> Result<(), StudyError> {
    let figure = StabilityPlot {
        title: title.to_string(),
        x: &study.x,
        y: &study.y,
        maps,
    };
    plot::save(path, &figure)
}
