//! `tether run SYSTEM.toml`: the coupled co-simulation.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Result;
use tether_master::{CsvRecorder, MemoryRecorder, Observer, Simulation, SystemSpec};

use crate::settings::Settings;

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// The system file (TOML), see docs/system-file.md.
    system: PathBuf,
    #[command(flatten)]
    settings: Settings,
    /// Output CSV file (default: the system file's name with .csv, in the current directory).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Also plot the results over time into this file (.svg or .png).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Columns to plot, comma separated (default: all, or the multipliers and
    /// residuals when there are more than eight).
    #[arg(long, value_delimiter = ',', requires = "plot")]
    columns: Vec<String>,
    /// Time the phases of every macro step (predictor, Jacobian, solve,
    /// corrector, recording) and print them in the run summary. Costs five
    /// clock reads per macro step.
    #[arg(long)]
    timing: bool,
    /// Do not print the run summary, nor the FMUs' warnings (their errors still).
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

pub fn main(args: Args) -> Result<()> {
    crate::interrupt::install()?;
    let mut spec = SystemSpec::from_file(&args.system)?;
    crate::settings::apply(&args.settings.overrides()?, &mut spec)?;
    let out = match &args.out {
        Some(p) => p.clone(),
        None => PathBuf::from(
            args.system
                .file_stem()
                .map(|s| format!("{}.csv", s.to_string_lossy()))
                .unwrap_or_else(|| "results.csv".into()),
        ),
    };
    crate::output::not_an_input(
        &out,
        std::iter::once(args.system.as_path())
            .chain(spec.instances.iter().map(|i| i.fmu.as_path())),
    )?;
    if let Some(warning) = spec.grid_warning() {
        crate::say!("warning: {warning}");
    }
    let mut sim = Simulation::new(&spec)?;
    sim.time_phases(args.timing);
    let file = crate::output::create(&out)?;
    let mut recorder = CsvRecorder::file(file);
    let emergency = recorder.emergency();
    let steps = sim.total_steps();
    let bar = (std::io::stderr().is_terminal() && steps >= 20_000 && !args.quiet).then(|| {
        let bar = indicatif::ProgressBar::new(steps);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {eta} left")
                .expect("valid template"),
        );
        bar
    });
    let mut progress = |n: u64, _total: u64| {
        if let Some(bar) = &bar {
            if n.is_multiple_of(256) {
                bar.set_position(n);
            }
        }
    };
    let mut memory = MemoryRecorder::default();
    let mut watch = crate::interrupt::Watch;
    let mut observers: Vec<&mut dyn Observer> = vec![&mut recorder, &mut watch];
    if args.plot.is_some() {
        observers.push(&mut memory);
    }
    let guard = crate::exit_guard::arm(emergency, &out);
    let outcome = sim.run(&mut observers, &mut progress);
    drop(guard);
    // The last recorded row's time: after a failure the failing step's own
    // time may be one step later.
    let last = sim.last_recorded_time().unwrap_or(spec.experiment.start);
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    if !args.quiet {
        let name = spec.name.as_deref().unwrap_or("system");
        crate::say!(
            "{name}: {} with k = {}, H = {}, t = {} … {}",
            spec.method,
            spec.coupling.order,
            step_text(&spec),
            spec.experiment.start,
            last
        );
        crate::say!("{}", sim.stats());
    }
    if let Some(path) = &args.plot {
        let name = spec.name.clone().unwrap_or_else(|| "system".into());
        let table = tether_study::Table::from_recorder(&name, &memory);
        let title = format!(
            "{name}: {}, k = {}, H = {}",
            spec.method,
            spec.coupling.order,
            step_text(&spec)
        );
        crate::plot::draw(&[table], &args.columns, &title, path)?;
        if !args.quiet {
            crate::say!("plot: {}", path.display());
        }
    }
    match outcome {
        Ok(_) => {
            if !args.quiet {
                crate::say!("results: {}", out.display());
            }
            Ok(())
        }
        // The results file itself failed: nothing says what it holds.
        Err(e @ tether_master::MasterError::Recording(_)) => {
            Err(anyhow::Error::new(e).context(format!(
                "run stopped at t = {}: cannot write {}",
                sim.time(),
                out.display()
            )))
        }
        Err(e) => Err(anyhow::Error::new(e).context(format!(
            "run stopped; results up to t = {last} kept in {} (marked incomplete)",
            out.display()
        ))),
    }
}

/// The macro step for the summary: the fixed H, or the adaptive tolerances.
fn step_text(spec: &SystemSpec) -> String {
    match &spec.step_control {
        None => spec.experiment.step.to_string(),
        Some(c) => format!("adaptive (rtol = {:e}, atol = {:e})", c.rtol, c.atol),
    }
}
