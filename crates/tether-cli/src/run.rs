//! `tether run SYSTEM.toml`: the coupled co-simulation.

use std::path::PathBuf;

use anyhow::{Context, Result};
use tether_master::{CsvRecorder, MemoryRecorder, Observer, Simulation, SystemSpec};

use crate::settings::Settings;

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// The system file (TOML, docs/system-file.md), or SSP: an .ssp archive,
    /// a SystemStructure.ssd or a folder holding one (docs/ssp.md).
    system: PathBuf,
    #[command(flatten)]
    settings: Settings,
    /// Output CSV file (default: the system file's name with .csv, in the current directory).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Also plot the results over time into this file (.svg or .png).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Columns to plot: names separated by commas or spaces (commas inside
    /// brackets belong to the name: body.R[1,2]) (default: all, or the
    /// multipliers and residuals when there are more than eight).
    #[arg(long, num_args = 1.., value_name = "NAME", requires = "plot")]
    columns: Vec<String>,
    /// Record on a coarser grid: every DT (a whole multiple of the step H),
    /// and the last point (overrides [output] interval).
    #[arg(long, value_name = "DT", allow_hyphen_values = true)]
    output_interval: Option<f64>,
    /// Record only the columns matching PATTERN: `*` matches any characters,
    /// everything else is literal; several separated by commas as in
    /// --columns (commas inside brackets belong to the name: body.R[1,2]), or
    /// the flag repeated (overrides [output] variables).
    #[arg(long, value_name = "PATTERN")]
    output_variables: Vec<String>,
    /// Write the run summary as JSON to FILE (docs/run-summary.md), also when
    /// the run fails.
    #[arg(long, value_name = "FILE")]
    summary_json: Option<PathBuf>,
    /// Time the phases of every macro step (predictor, Jacobian, solve,
    /// corrector, recording) and print them in the run summary. Costs five
    /// clock reads per macro step.
    #[arg(long)]
    timing: bool,
    /// Run every FMU instance in a host process of its own (`isolation =
    /// "process"`): a crash, exit or hang of an FMU becomes an error of the run.
    #[arg(long)]
    isolate: bool,
    /// The longest an FMI call may take, in seconds, for every instance without
    /// its own `call_timeout`: an isolated instance is killed, an in-process
    /// one ends the run.
    #[arg(long, value_name = "SECONDS")]
    call_timeout: Option<f64>,
    /// Run every FMU instance on this host (`tether host`), `tcp://ADDR:PORT`,
    /// as the instance key `host` does (docs/remote.md); needs --token-file.
    #[arg(long, value_name = "tcp://ADDR:PORT", requires = "token_file")]
    host: Option<String>,
    /// The file holding the token of --host (mode 600).
    #[arg(long, value_name = "FILE", requires = "host")]
    token_file: Option<PathBuf>,
    /// Do not print the run summary, nor the FMUs' warnings (their errors still).
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

pub fn main(args: Args) -> Result<()> {
    crate::interrupt::install()?;
    let overrides = args.settings.overrides()?;
    // `_ssp` keeps an extracted archive's FMUs until the run ends.
    let (mut spec, _ssp) = tether_ssp::load(&args.system, overrides.step, overrides.stop)?;
    crate::settings::apply(&overrides, &mut spec)?;
    crate::isolation::apply(args.isolate, args.call_timeout, &mut spec)?;
    if let (Some(host), Some(token_file)) = (&args.host, &args.token_file) {
        for instance in &mut spec.instances {
            instance.host = Some(host.clone());
            instance.token_file = Some(token_file.clone());
        }
    }
    if let Some(dt) = args.output_interval {
        spec.output.interval = Some(dt);
    }
    if !args.output_variables.is_empty() {
        spec.output.variables = crate::columns::split(&args.output_variables);
    }
    let out = match &args.out {
        Some(p) => p.clone(),
        None => PathBuf::from(
            args.system
                .file_stem()
                .map(|s| format!("{}.csv", s.to_string_lossy()))
                .unwrap_or_else(|| "results.csv".into()),
        ),
    };
    let inputs = || {
        std::iter::once(args.system.as_path()).chain(spec.instances.iter().map(|i| i.fmu.as_path()))
    };
    crate::output::not_an_input(&out, inputs())?;
    if let Some(summary) = &args.summary_json {
        crate::output::not_an_input(summary, inputs())?;
    }
    spec.validate()?;
    spec.check_grid()?;
    let placed: Vec<&str> = spec
        .instances
        .iter()
        .filter(|i| !i.resources.is_empty())
        .map(|i| i.name.as_str())
        .collect();
    if !placed.is_empty() {
        crate::say!(
            "note: resources of {} place instances on Dask workers from Python (tether.run(system, client=…)); tether run runs them on this machine",
            placed.join(", ")
        );
    }
    let unstable = spec.method.stability_warning(spec.coupling.order);
    if let Some(warning) = &unstable {
        crate::say!("warning: {warning}");
    }
    let mut sim = Simulation::new(&spec)
        .map_err(|e| match e {
            // The patterns of --output-variables replaced the file's.
            tether_master::MasterError::InvalidOutput(text)
                if !args.output_variables.is_empty() =>
            {
                tether_master::MasterError::InvalidOutput(
                    text.replace("[output] variables,", "--output-variables,"),
                )
            }
            e => e.located(&spec, |instance, variable| {
                let target = format!("{instance}.{variable}");
                overrides
                    .parameters
                    .contains_key(&target)
                    .then(|| format!("--set {target}"))
            }),
        })
        .map_err(|e| match e {
            // A name of an SSP system appears in its SystemStructure.ssd.
            tether_master::MasterError::UnknownVariable(mut u)
                if _ssp.is_some() && !u.place.starts_with("--set") =>
            {
                u.place = format!("{}: {}", tether_ssp::ssd_name(&args.system), u.place);
                tether_master::MasterError::UnknownVariable(u)
            }
            e => e,
        })?;
    sim.time_phases(args.timing);
    let ssp_notes = _ssp.as_ref().map_or(&[][..], |l| &l.notes[..]);
    for note in ssp_notes.iter().chain(sim.notes()) {
        for line in tether_master::wrap(&format!("note: {note}"), tether_master::SUMMARY_WIDTH) {
            crate::say!("{line}");
        }
    }
    for warning in sim.warnings() {
        crate::say!("warning: {warning}");
    }
    // The plot's columns are checked now, not after the run.
    let plot_columns = crate::columns::split(&args.columns);
    for name in &plot_columns {
        if !sim.columns().contains(name) {
            anyhow::bail!(
                "--columns {name}: the run records no column '{name}'{}",
                crate::columns::hint(name, sim.columns())
            );
        }
    }
    if let Some(warning) = csv_size_warning(&spec, &sim) {
        crate::say!("warning: {warning}");
    }
    let file = crate::output::create(&out)?;
    let mut recorder = CsvRecorder::file_at(file, &out);
    let emergency = recorder.emergency();
    let mut progress = crate::progress::Progress::new(
        spec.experiment.start,
        spec.experiment.step,
        sim.total_steps(),
        !args.quiet,
    );
    let mut memory = MemoryRecorder::default();
    let mut watch = crate::interrupt::Watch;
    let mut observers: Vec<&mut dyn Observer> = vec![&mut recorder, &mut watch];
    if args.plot.is_some() {
        observers.push(&mut memory);
    }
    let guard = crate::exit_guard::arm(emergency, &out);
    let watchdog = crate::watchdog::start(&spec);
    let outcome = sim.run(&mut observers, &mut |n, _| progress.update(n));
    drop(watchdog);
    drop(guard);
    // The last recorded row's time: after a failure the failing step's own
    // time may be one step later.
    let last = tether_master::Time(sim.last_recorded_time().unwrap_or(spec.experiment.start));
    progress.finish();
    let stats = sim.stats();
    if let Some(path) = &args.summary_json {
        std::fs::write(path, stats.to_json() + "\n")
            .with_context(|| format!("cannot write the run summary {}", path.display()))?;
    }
    if !args.quiet {
        let name = spec.name.as_deref().unwrap_or("system");
        let mut parts = what_it_does(&spec);
        parts.push(format!("t = {} … {last}", spec.experiment.start));
        for line in wrap_parts(&format!("{name}: "), &parts) {
            crate::say!("{line}");
        }
        crate::say!("{stats}");
    }
    if let Some(path) = &args.plot {
        let name = spec.name.clone().unwrap_or_else(|| "system".into());
        // One run: the title names it, the legend only says where it stopped.
        let table = tether_study::Table::from_recorder("", &memory);
        let title = format!("{name}: {}", what_it_does(&spec).join(", "));
        let preferred = plotted_first(&spec, sim.columns());
        crate::plot::draw(
            &[table],
            &plot_columns,
            &preferred,
            &sim.units(),
            &title,
            path,
        )?;
        if !args.quiet {
            crate::say!("plot: {}", path.display());
        }
    }
    match outcome {
        Ok(_) => {
            if !args.quiet {
                crate::say!("results: {}", out.display());
                if let Some(path) = &args.summary_json {
                    crate::say!("summary: {}", path.display());
                }
            }
            Ok(())
        }
        // The results file itself failed: nothing says what it holds.
        Err(e @ tether_master::MasterError::Recording(_)) => {
            Err(anyhow::Error::new(e).context(format!(
                "run stopped at t = {}: cannot write {}",
                tether_master::Time(sim.time()),
                out.display()
            )))
        }
        // A divergence (or a constraint it broke) of a formulation known to be
        // unstable says so again.
        Err(
            e @ (tether_master::MasterError::Diverged { .. }
            | tether_master::MasterError::ResidualLimit { .. }),
        ) if unstable.is_some() => Err(anyhow::anyhow!("{e}; {}", unstable.unwrap_or_default())
            .context(format!(
                "run stopped; results up to t = {last} kept in {} (marked incomplete)",
                out.display()
            ))),
        Err(e) => Err(anyhow::Error::new(e).context(format!(
            "run stopped; results up to t = {last} kept in {} (marked incomplete)",
            out.display()
        ))),
    }
}

/// The columns a run's plot shows when none are chosen: the instances'
/// coupled outputs (the terms of the constraints' position levels, the
/// senders of connections), then the multipliers and residuals.
fn plotted_first(spec: &SystemSpec, columns: &[String]) -> Vec<String> {
    let mut chosen: Vec<String> = Vec::new();
    let mut take = |name: String| {
        if columns.contains(&name) && !chosen.contains(&name) {
            chosen.push(name);
        }
    };
    for c in &spec.constraints {
        if let Ok(expr) = tether_master::expr::LinearExpr::parse(&c.position) {
            for t in expr.terms.iter().filter(|t| t.derivative_order == 0) {
                take(format!("{}.{}", t.instance, t.variable));
            }
        }
    }
    for c in &spec.connections {
        take(c.from.clone());
    }
    let base = |c: &str| match c.rfind('[') {
        Some(i) if c.ends_with(']') => c[..i].to_string(),
        _ => c.to_string(),
    };
    for suffix in [".lambda", ".value", ".g"] {
        for c in columns {
            if base(c).ends_with(suffix) {
                take(c.clone());
            }
        }
    }
    chosen
}

/// What the system does, for the summary's first line and the plot's title:
/// the method (only when constraints, joints or coupling variables make one
/// work), the signals' scheme (when there are connections), k and H.
pub fn what_it_does(spec: &SystemSpec) -> Vec<String> {
    let mut parts = Vec::new();
    let coupled = !(spec.constraints.is_empty()
        && spec.joints.is_empty()
        && spec.coupling_variables.is_empty());
    if coupled {
        parts.push(spec.method.to_string());
    }
    if !spec.connections.is_empty() {
        let scheme = match spec.signals.scheme() {
            tether_master::SignalScheme::Jacobi => "Jacobi",
            tether_master::SignalScheme::GaussSeidel => "Gauss–Seidel",
        };
        let iterated = match (spec.signals.iterations, spec.signals.solver) {
            (Some(n), Some(tether_master::SignalSolver::Newton)) => {
                format!(" iterated by Newton (at most {n} updates)")
            }
            (Some(n), _) => format!(" iterated (at most {n} repetitions)"),
            (None, _) => String::new(),
        };
        parts.push(format!("signals: {scheme}{iterated}"));
    }
    if !coupled && spec.connections.is_empty() {
        parts.push("instances not coupled".into());
    }
    if coupled || spec.coupling.order > 0 {
        parts.push(format!("k = {}", spec.coupling.order));
    }
    parts.push(format!("H = {}", step_text(spec)));
    parts
}

/// `head` and `parts` joined by `, `, wrapped after a comma within the
/// summary's width (the continuation lines indented by two).
fn wrap_parts(head: &str, parts: &[String]) -> Vec<String> {
    let mut lines = vec![head.to_string()];
    for (i, part) in parts.iter().enumerate() {
        let last = lines.last_mut().expect("a line");
        let piece = if i + 1 < parts.len() {
            format!("{part},")
        } else {
            part.clone()
        };
        let fresh = last.trim().is_empty() || last.as_str() == head;
        if !fresh && last.chars().count() + 1 + piece.chars().count() > tether_master::SUMMARY_WIDTH
        {
            lines.push(format!("  {piece}"));
        } else {
            if !fresh {
                last.push(' ');
            }
            last.push_str(&piece);
        }
    }
    lines
}

/// The macro step for the summary: the fixed H, or the adaptive tolerances.
fn step_text(spec: &SystemSpec) -> String {
    match &spec.step_control {
        None => spec.experiment.step.to_string(),
        Some(c) => format!("adaptive (rtol = {:e}, atol = {:e})", c.rtol, c.atol),
    }
}

/// Results files estimated above this size are announced before the run.
const LARGE_CSV: f64 = 1e9;

/// Characters of a recorded value in the CSV, a comma included: a typical
/// shortest round-trip decimal (`-0.12345678901234567,`).
const BYTES_PER_VALUE: f64 = 20.0;

/// A warning when the results file would exceed [`LARGE_CSV`] bytes, with the
/// options that shrink it.
fn csv_size_warning(spec: &tether_master::SystemSpec, sim: &Simulation) -> Option<String> {
    let e = &spec.experiment;
    let interval = sim.stats().output_interval;
    let rows = if interval > 0.0 {
        ((e.stop - e.start) / interval).round() + 1.0
    } else {
        sim.total_steps() as f64 + 1.0
    };
    let columns = sim.columns().len() as f64 + 1.0;
    let bytes = rows * columns * BYTES_PER_VALUE;
    (bytes > LARGE_CSV).then(|| {
        format!(
            "the results file will be about {:.1} GB ({rows:.0} rows × {columns:.0} columns); \
             --output-interval DT records fewer rows, --output-variables PATTERN,… fewer columns",
            bytes / 1e9
        )
    })
}
