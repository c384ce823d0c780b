//! `tether study STUDY.toml…`: run study files (docs/studies.md).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use tether_study::Study;

#[derive(clap::Args)]
pub struct Args {
    /// Study files (TOML), run one after another; each runs its cases in parallel.
    #[arg(required = true)]
    studies: Vec<PathBuf>,
    /// Folder for the results (CSV, text summary, plots).
    #[arg(long, default_value = ".")]
    out_dir: PathBuf,
    /// Do not show a progress bar or print the summaries.
    #[arg(long, short)]
    quiet: bool,
}

pub fn main(args: Args) -> Result<()> {
    for path in &args.studies {
        let study = Study::from_file(path)?;
        if study.skip_if_missing && !study.system.exists() {
            crate::say!(
                "skipped {}: its system file {} does not exist",
                path.display(),
                study.system.display()
            );
            continue;
        }
        run_one(&study, &args.out_dir, args.quiet)
            .with_context(|| format!("study {}", path.display()))?;
    }
    Ok(())
}

/// Run one study with a progress bar and print its summary.
pub fn run_one(study: &Study, out_dir: &Path, quiet: bool) -> Result<()> {
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(study.runs()?)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} runs  {elapsed}")
            .expect("valid template"),
    );
    bar.set_message(study.output.clone());
    let tick = || bar.inc(1);
    let report = study.run(out_dir, &tick);
    bar.finish_and_clear();
    let report = report?;
    if !quiet {
        crate::stdout(format_args!("{}", report.summary))?;
        for f in &report.files {
            crate::say!("wrote {}", f.display());
        }
    }
    Ok(())
}
