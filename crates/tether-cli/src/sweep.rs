//! `tether sweep convergence|stability SYSTEM.toml …`: a study from flags.

use std::path::PathBuf;

use anyhow::Result;
use tether_master::SystemSpec;
use tether_study::{Axis, Convergence, Kind, ReferenceSpec, Stability, Study};

use crate::settings::Settings;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    kind: SweepKind,
}

#[derive(clap::Subcommand)]
enum SweepKind {
    /// Global error of chosen columns over a list of macro-step sizes H.
    Convergence(ConvergenceArgs),
    /// Stable / unstable over a grid of two quantities.
    Stability(StabilityArgs),
}

/// What every sweep shares: the system, its settings and where results go.
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct Common {
    /// The system file (TOML), see docs/system-file.md.
    system: PathBuf,
    #[command(flatten)]
    settings: Settings,
    /// Folder for the results (CSV, text summary, plots).
    #[arg(long, default_value = ".")]
    out_dir: PathBuf,
    /// File stem of the results (default: convergence / stability).
    #[arg(long)]
    name: Option<String>,
    /// Plot formats, comma separated: svg, png.
    #[arg(long, value_delimiter = ',', default_value = "svg")]
    format: Vec<String>,
    /// Do not show a progress bar or print the summary.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct ConvergenceArgs {
    #[command(flatten)]
    common: Common,
    /// Macro-step sizes H, comma separated (at least two).
    #[arg(long, value_delimiter = ',', required = true)]
    steps: Vec<f64>,
    /// Reference: finest (the run with the smallest H), two-mass-oscillator
    /// (closed form), or a results CSV file.
    #[arg(long, default_value = "finest")]
    reference: String,
    /// Columns whose error is measured: names separated by commas or spaces
    /// (commas inside brackets belong to the name: body.R[1,2]).
    #[arg(long, num_args = 1.., value_name = "NAME", required = true)]
    columns: Vec<String>,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct StabilityArgs {
    #[command(flatten)]
    common: Common,
    /// Horizontal axis: TARGETS=FROM..TO:POINTS[:log] or TARGETS=V1,V2,…;
    /// TARGETS are INSTANCE.PARAMETER (comma separated, all get the value) or step.
    #[arg(long)]
    x: String,
    /// Vertical axis, as --x.
    #[arg(long)]
    y: String,
    /// Also call a completed run unstable when a monitored column's peak over
    /// the last tenth exceeds GROWTH times its peak over the first tenth.
    #[arg(long)]
    growth: Option<f64>,
    /// Columns the growth criterion watches (default: all but residuals).
    #[arg(long, value_delimiter = ',')]
    monitor: Vec<String>,
}

pub fn main(args: Args) -> Result<()> {
    let (common, kind) = match args.kind {
        SweepKind::Convergence(c) => {
            let kind = Kind::Convergence(Convergence {
                steps: c.steps,
                reference: ReferenceSpec::parse_cli(&c.reference)?,
                columns: crate::columns::split(&c.columns),
            });
            (c.common, kind)
        }
        SweepKind::Stability(s) => {
            let kind = Kind::Stability(Box::new(Stability {
                x: Axis::parse_cli(&s.x)?,
                y: Axis::parse_cli(&s.y)?,
                growth: s.growth,
                monitor: s.monitor,
            }));
            (s.common, kind)
        }
    };
    // The flags act on the system file like `tether run`'s (errors show
    // here, before any run) and are the study's settings for every run.
    let mut spec = SystemSpec::from_file(&common.system)?;
    let set = common.settings.overrides()?;
    crate::settings::apply(&set, &mut spec)?;
    let study = Study::sweep(
        common.system.clone(),
        &spec,
        set,
        kind,
        common.name,
        common.format,
    )?;
    crate::study::run_one(&study, &common.out_dir, common.quiet)
}
