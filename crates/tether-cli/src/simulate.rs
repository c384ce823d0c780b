//! `tether simulate FILE.fmu`: one FMU at a fixed communication step, every
//! output to CSV — the same job as `fmpy simulate`, so an FMU can be checked
//! against fmpy before it is coupled.
//!
//! The simulation is the master's ([`tether_master::SingleFmu`], shared with
//! Python's `tether.simulate`): FMI 2.0 and FMI 3.0 FMUs, co-simulation or
//! model exchange (`--fmi-type`, the built-in integrator's settings
//! `--integrator`), an array output one
//! column per element, `y[1]`, `A[2,3]` (1-based, row-major), every output checked
//! for NaN, an FMU's request to end the simulation honoured. This file is the
//! command line around it: arguments, the CSV file, messages.

use std::path::PathBuf;

use anyhow::{Context, Result};
use tether_fmi::Fmu;
use tether_fmi::{Integrator, Method};
use tether_master::{
    CsvRecorder, FmiType, MasterError, SingleEnd, SingleExperiment, SingleFmu, SingleOutputs,
    StartValue,
};

/// The interface `--fmi-type` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Interface {
    /// The FMU steps itself.
    CoSimulation,
    /// Tether integrates the FMU's derivatives (built-in integrator).
    ModelExchange,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// The `.fmu` file or unpacked FMU directory.
    fmu: PathBuf,
    /// Start time (default: DefaultExperiment startTime, else 0).
    #[arg(long, allow_hyphen_values = true)]
    start: Option<f64>,
    /// Stop time (default: DefaultExperiment stopTime, else 1).
    #[arg(long, allow_hyphen_values = true)]
    stop: Option<f64>,
    /// Communication step (default: DefaultExperiment stepSize, else (stop − start)/500).
    #[arg(long, allow_hyphen_values = true)]
    step: Option<f64>,
    /// Tolerance for fmi2SetupExperiment (default: DefaultExperiment tolerance, if any);
    /// with model exchange also the integrator's relative tolerance (default 1e-6).
    #[arg(long, allow_hyphen_values = true)]
    tolerance: Option<f64>,
    /// The FMU's interface to run (default: co-simulation where the FMU has it,
    /// else model exchange).
    #[arg(long, value_enum, value_name = "TYPE")]
    fmi_type: Option<Interface>,
    /// Model exchange: the built-in integrator's settings, KEY=VALUE separated by
    /// commas: method (bdf, esdirk, rk45, dop853; default bdf), rtol (default:
    /// --tolerance),
    /// atol (relative to each state's nominal; default rtol), max_step (default:
    /// the communication step).
    #[arg(long, value_name = "KEY=VALUE,...")]
    integrator: Option<String>,
    /// Start value of a parameter or input, repeatable: --set m=2 --set exact=true;
    /// an array element --set 'A[2,3]=1.5', a whole array --set 'x0=[1, 0]'.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// Output CSV file (default: <modelIdentifier>.csv).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Also plot the outputs over time into this file (.svg or .png).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Outputs to plot: names separated by commas or spaces (default: all, or
    /// the first eight).
    #[arg(long, num_args = 1.., value_name = "NAME", requires = "plot")]
    columns: Vec<String>,
}

/// The plot of a simulation: the CSV as written, the units the FMU declares.
fn plot(
    args: &Args,
    md: &tether_fmi::ModelDescription,
    csv: &std::path::Path,
    title: &str,
) -> Result<()> {
    let Some(path) = &args.plot else {
        return Ok(());
    };
    let mut table = tether_study::Table::read_csv(csv)?;
    // One run: the title names it.
    table.source = String::new();
    let units: Vec<(String, String)> = table
        .columns
        .iter()
        .filter_map(|c| {
            let name = match c.rfind('[') {
                Some(i) if c.ends_with(']') => &c[..i],
                _ => c.as_str(),
            };
            let var = md.model_variables.iter().find(|v| v.name == name)?;
            let unit = var.real()?.attributes.unit.clone()?;
            Some((c.clone(), unit))
        })
        .collect();
    crate::plot::draw(
        &[table],
        &crate::columns::split(&args.columns),
        &[],
        &units,
        title,
        path,
    )?;
    crate::say!("plot: {}", path.display());
    Ok(())
}

/// The integrator settings of `--integrator method=bdf,rtol=1e-8,…`.
fn integrator(text: &str) -> Result<Integrator> {
    let mut settings = Integrator::default();
    for item in text.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let Some((key, value)) = item.split_once('=') else {
            anyhow::bail!("--integrator {text}: '{item}' is not KEY=VALUE");
        };
        let (key, value) = (key.trim(), value.trim());
        if key == "method" {
            settings.method = Method::parse(value).with_context(|| {
                let known: Vec<&str> = Method::ALL.iter().map(|(n, _)| *n).collect();
                format!(
                    "--integrator {text}: unknown method '{value}' (known: {})",
                    known.join(", ")
                )
            })?;
            continue;
        }
        let number: f64 = value
            .parse()
            .ok()
            .with_context(|| format!("--integrator {text}: {key} = '{value}' is not a number"))?;
        match key {
            "rtol" => settings.rtol = Some(number),
            "atol" => settings.atol = Some(number),
            "max_step" => settings.max_step = Some(number),
            _ => anyhow::bail!(
                "--integrator {text}: unknown key '{key}' (known: method, rtol, atol, max_step)"
            ),
        }
    }
    if let Err(why) = settings.check() {
        anyhow::bail!("--integrator {text}: {why}");
    }
    Ok(settings)
}

/// The interface to run: as asked, else co-simulation where the FMU has it.
fn fmi_type(args: &Args, fmu: &Fmu) -> Result<FmiType> {
    let md = fmu.model_description();
    let settings = args.integrator.as_deref().map(integrator).transpose()?;
    let asked = match args.fmi_type {
        Some(asked) => asked,
        None if md.co_simulation.is_none() => Interface::ModelExchange,
        None => Interface::CoSimulation,
    };
    match asked {
        Interface::CoSimulation => {
            if settings.is_some() {
                anyhow::bail!(
                    "--integrator applies to model exchange: add --fmi-type model-exchange"
                );
            }
            fmu.require_co_simulation()?;
            Ok(FmiType::CoSimulation)
        }
        Interface::ModelExchange => {
            if md.model_exchange.is_none() {
                anyhow::bail!(
                    "--fmi-type model-exchange: '{}' (model '{}') has no model-exchange interface",
                    args.fmu.display(),
                    md.model_name
                );
            }
            Ok(FmiType::ModelExchange(settings.unwrap_or_default()))
        }
    }
}

pub fn main(args: Args) -> Result<()> {
    crate::interrupt::install()?;
    let fmu = Fmu::open(&args.fmu)?;
    let md = fmu.model_description();
    let fmi_type = fmi_type(&args, &fmu)?;
    let x = SingleExperiment::new(md, args.start, args.stop, args.step, args.tolerance)?;
    let (start, stop, step, steps) = (x.start, x.stop, x.step, x.steps);
    let x_end = x.end();
    if !x.stop_on_grid() {
        crate::say!(
            "warning: stop = {stop} is not on the communication grid start + n·step (start = {start}, \
             step = {step}): the simulation ends at t = {}",
            x.end()
        );
    }
    let mut start_values = Vec::with_capacity(args.set.len());
    for assignment in &args.set {
        let (var, value) = assignment
            .split_once('=')
            .with_context(|| format!("--set {assignment}: expected NAME=VALUE"))?;
        start_values.push((var.trim().to_string(), StartValue::parse_cli(value.trim())));
    }
    // Start values come from --set: a name that does not fit says so.
    let mut single = SingleFmu::new_as(&fmu, &start_values, x, fmi_type).map_err(|e| match e {
        MasterError::UnknownVariable(mut u) if u.place == "parameters" => {
            u.place = format!("--set {}", u.name);
            MasterError::UnknownVariable(u)
        }
        MasterError::ArrayElement {
            place,
            instance,
            name,
            reason,
        } if place == "parameters" => MasterError::ArrayElement {
            place: format!("--set {name}"),
            instance,
            name,
            reason,
        },
        e => e,
    })?;
    for warning in single.warnings() {
        crate::say!("warning: {warning}");
    }
    let outputs = SingleOutputs::all(md, single.arrays())?;
    let name = single.name().to_string();

    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.csv")));
    crate::output::not_an_input(&out, [args.fmu.as_path()])?;
    if let Some(path) = &args.plot {
        crate::output::not_an_input(path, [args.fmu.as_path(), out.as_path()])?;
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        if !matches!(ext.as_deref(), Some("svg" | "png")) {
            anyhow::bail!(
                "--plot {}: the file name must end in .svg or .png",
                path.display()
            );
        }
    }
    let file = crate::output::create(&out)?;
    let mut recorder = CsvRecorder::file_at(file, &out);
    let guard = crate::exit_guard::arm(recorder.emergency(), &out);
    let cannot_write = || format!("cannot write {}", out.display());
    // Every failure after the header, the FMU's or ours, ends the CSV with its trailer.
    let run = single.run(&outputs, &mut recorder, &mut || {
        crate::interrupt::pending().then(|| crate::interrupt::REASON.to_string())
    });
    drop(guard);
    let end = match run.end {
        Ok(end) => end,
        Err(MasterError::Recording(e)) => return Err(anyhow::Error::new(e).context(cannot_write())),
        Err(e) => {
            return Err(anyhow::Error::new(e).context(format!(
                "simulation stopped; results so far kept in {}",
                out.display()
            )))
        }
    };
    single.terminate()?;
    let last = match end {
        SingleEnd::Completed => x_end,
        SingleEnd::Terminated { time } => time,
    };
    let title = format!("{name}: H = {step}, t = {start} … {last}");
    plot(&args, md, &out, &title)?;
    match end {
        SingleEnd::Completed => crate::say!(
            "{name}: {steps} steps of {step} from {start} to {stop}; results: {}",
            out.display()
        ),
        SingleEnd::Terminated { time: at } => crate::say!(
            "{name}: steps of {step} from {start}; the FMU requested the end of the simulation \
             at t = {at} ({}), before the stop time {stop}; results: {}",
            match (single.is_model_exchange(), single.is_fmi3()) {
                (true, _) => "model exchange, terminateSimulation",
                (false, true) => "fmi3DoStep, terminateSimulation",
                (false, false) => "fmi2Discard, fmi2Terminated",
            },
            out.display()
        ),
    }
    Ok(())
}
