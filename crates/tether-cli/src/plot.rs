//! `tether plot RESULTS.csv…`: time series of results files as SVG or PNG.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use tether_study::plot::{save, SeriesPlot};
use tether_study::Table;

#[derive(clap::Args)]
pub struct Args {
    /// Results files (CSV with a `time` column, as `tether run` writes them);
    /// several files are drawn over each other.
    #[arg(required = true)]
    results: Vec<PathBuf>,
    /// Columns to plot, one panel each: names separated by commas or spaces
    /// (commas inside brackets belong to the name: body.R[1,2]) (default:
    /// all, or the multipliers and residuals when there are more than eight).
    #[arg(long, num_args = 1.., value_name = "NAME")]
    columns: Vec<String>,
    /// Output file: .svg or .png.
    #[arg(long, short)]
    out: PathBuf,
    /// Figure title (default: the file names).
    #[arg(long)]
    title: Option<String>,
}

pub fn main(args: Args) -> Result<()> {
    let tables = args
        .results
        .iter()
        .map(|p| {
            if let Some(e) = crate::missing(p) {
                return Err(e);
            }
            let mut t = Table::read_csv(p)?;
            t.source = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| t.source.clone());
            Ok(t)
        })
        .collect::<Result<Vec<_>>>()?;
    let title = args.title.clone().unwrap_or_else(|| {
        tables
            .iter()
            .map(|t| t.source.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    });
    draw(
        &tables,
        &crate::columns::split(&args.columns),
        &[],
        &[],
        &title,
        &args.out,
    )?;
    crate::say!("plot: {}", args.out.display());
    Ok(())
}

/// Plot `columns` of every table into `out`, with the `units` of columns
/// where known; without `columns`, the `preferred` ones first (a run's
/// coupled outputs, multipliers and residuals), else the default choice.
pub fn draw(
    tables: &[Table],
    columns: &[String],
    preferred: &[String],
    units: &[(String, String)],
    title: &str,
    out: &Path,
) -> Result<()> {
    let Some(first) = tables.first() else {
        bail!("nothing to plot");
    };
    let columns = if columns.is_empty() {
        let chosen = if preferred.is_empty() || first.columns.len() <= DEFAULT_PANELS {
            default_columns(first)
        } else {
            preferred.iter().take(DEFAULT_PANELS).cloned().collect()
        };
        if chosen.len() < first.columns.len() {
            let note = format!(
                "note: {} plots {} of the {} columns ({}); choose others with --columns NAME,…",
                out.display(),
                chosen.len(),
                first.columns.len(),
                chosen.join(", ")
            );
            for line in tether_master::wrap(&note, tether_master::SUMMARY_WIDTH) {
                crate::say!("{line}");
            }
        }
        chosen
    } else {
        columns.to_vec()
    };
    for t in tables {
        for c in &columns {
            t.column(c)?;
        }
        if t.times.is_empty() {
            bail!("{}: no results to plot", t.source);
        }
    }
    let figure = SeriesPlot {
        title: title.to_string(),
        columns,
        runs: tables.iter().map(|t| (t.source.clone(), t)).collect(),
        units: units.to_vec(),
    };
    save(out, &figure)?;
    Ok(())
}

/// Panels of a plot whose columns are not chosen.
pub const DEFAULT_PANELS: usize = 8;

/// Small files: every column. Otherwise the multipliers and residuals of
/// constraints (`c.lambda`, `c.g`) and joints (`j.lambda[k]`, `j.g[k]`), plus
/// outputs named like angles or energies of mechanisms (`*.phi`, `*.E`), or
/// the first columns if none is named so; at most [`DEFAULT_PANELS`].
fn default_columns(t: &Table) -> Vec<String> {
    if t.columns.len() <= DEFAULT_PANELS {
        return t.columns.clone();
    }
    let base = |c: &str| -> String {
        match c.rfind('[') {
            Some(i) if c.ends_with(']') => c[..i].to_string(),
            _ => c.to_string(),
        }
    };
    let named: Vec<String> = t
        .columns
        .iter()
        .filter(|c| {
            let b = base(c);
            b.ends_with(".lambda") || b.ends_with(".g") || b.ends_with(".phi") || b.ends_with(".E")
        })
        .take(DEFAULT_PANELS)
        .cloned()
        .collect();
    if named.is_empty() {
        t.columns.iter().take(DEFAULT_PANELS).cloned().collect()
    } else {
        named
    }
}
