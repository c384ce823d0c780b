//! `tether simulate FILE.fmu`: one FMU at a fixed communication step, every
//! output to CSV — the same job as `fmpy simulate`, so an FMU can be checked
//! against fmpy before it is coupled.
//!
//! The FMU is driven through the master's instance interface
//! ([`tether_fmi::FmuInstance`]), so FMI 2.0 and FMI 3.0 FMUs share this loop. An
//! array output is one column per element, `y[1]`, `A[2,3]` (1-based, row-major).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use tether_fmi::{
    BaseType, Causality, FmiStandard, Fmu, FmuInstance, Placement, ValueReference, ValueType,
};
use tether_master::{apply_start_value, CsvRecorder, MasterError, Observer, Sample, StartValue};

/// The outputs of one kind: their value references, and the column of each value
/// (an array has one per element).
#[derive(Default)]
struct Slots {
    vrs: Vec<ValueReference>,
    columns: Vec<usize>,
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
    /// Tolerance for fmi2SetupExperiment (default: DefaultExperiment tolerance, if any).
    #[arg(long, allow_hyphen_values = true)]
    tolerance: Option<f64>,
    /// Start value of a parameter or input, repeatable: --set m=2 --set exact=true.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// Output CSV file (default: <modelIdentifier>.csv).
    #[arg(long, short)]
    out: Option<PathBuf>,
}

pub fn main(args: Args) -> Result<()> {
    crate::interrupt::install()?;
    let fmu = Fmu::open(&args.fmu)?;
    let md = fmu.model_description().clone();
    let de = md.default_experiment.unwrap_or_default();
    let start = args.start.or(de.start_time).unwrap_or(0.0);
    let stop = args.stop.or(de.stop_time).unwrap_or(start + 1.0);
    let step = args.step.or(de.step_size).unwrap_or((stop - start) / 500.0);
    let tolerance = args.tolerance.or(de.tolerance);
    if !(start.is_finite() && stop.is_finite() && stop > start) {
        bail!("invalid time span: start {start}, stop {stop} (stop must be after start)");
    }
    if !(step.is_finite() && step > 0.0) {
        bail!("invalid --step {step}: expected a finite step > 0");
    }
    let steps = ((stop - start) / step).round().max(1.0) as u64;
    let end = start + steps as f64 * step;
    if (end - stop).abs() > 1e-9 * step {
        crate::say!(
            "warning: stop = {stop} is not on the communication grid start + n·step (start = {start}, \
             step = {step}): the simulation ends at t = {end}"
        );
    }

    let outputs: Vec<_> = md
        .model_variables
        .iter()
        .filter(|v| {
            v.causality == Causality::Output
                && v.base_type() != BaseType::String
                && v.value_type != ValueType::Clock
        })
        .collect();
    let mut columns: Vec<String> = Vec::new();
    let (mut real, mut int, mut boolean) = (Slots::default(), Slots::default(), Slots::default());
    for v in &outputs {
        let slots = match v.base_type() {
            BaseType::Real => &mut real,
            BaseType::Integer | BaseType::Enumeration => &mut int,
            _ => &mut boolean,
        };
        slots.vrs.push(v.value_reference);
        for element in md.element_names(v)? {
            slots.columns.push(columns.len());
            columns.push(element);
        }
    }
    let fmi3 = md.standard == FmiStandard::Fmi3;

    let name = md.co_simulation.model_identifier.clone();
    let mut instance =
        tether_fmi::instantiate(&fmu, &name, Default::default(), Placement::InProcess)?;
    for assignment in &args.set {
        let (var, value) = assignment
            .split_once('=')
            .with_context(|| format!("--set {assignment}: expected NAME=VALUE"))?;
        apply_start_value(
            instance.as_mut(),
            &md,
            var.trim(),
            &StartValue::parse_cli(value.trim()),
        )?;
    }
    instance.setup(tolerance, start, Some(stop))?;
    instance.enter_initialization()?;
    instance.exit_initialization()?;

    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.csv")));
    crate::output::not_an_input(&out, [args.fmu.as_path()])?;
    let file = crate::output::create(&out)?;
    let mut recorder = CsvRecorder::file_at(file, &out);
    let guard = crate::exit_guard::arm(recorder.emergency(), &out);
    let cannot_write = || format!("cannot write {}", out.display());
    recorder.start(&columns).with_context(cannot_write)?;
    let mut row = vec![0.0; columns.len()];
    let mut real_buf = vec![0.0; real.columns.len()];
    let mut int_buf = vec![0; int.columns.len()];
    let mut bool_buf = vec![false; boolean.columns.len()];
    let after_step = if fmi3 {
        "after fmi3DoStep"
    } else {
        "after fmi2DoStep"
    };
    let mut record = |instance: &mut dyn FmuInstance, n: u64, time: f64| -> Result<()> {
        if !real.vrs.is_empty() || !fmi3 {
            instance.get_reals(&real.vrs, &mut real_buf)?;
        }
        if !int.vrs.is_empty() || !fmi3 {
            instance.get_integers(&int.vrs, &mut int_buf)?;
        }
        if !boolean.vrs.is_empty() || !fmi3 {
            instance.get_booleans(&boolean.vrs, &mut bool_buf)?;
        }
        // A non-finite output is the FMU's error, named before it is recorded.
        if let Some(k) = real_buf.iter().position(|v| !v.is_finite()) {
            return Err(MasterError::NonFiniteOutput {
                instance: name.clone(),
                variable: columns[real.columns[k]].clone(),
                value: real_buf[k],
                call: if n == 0 {
                    "after initialization"
                } else {
                    after_step
                },
                time,
            }
            .into());
        }
        for (k, &slot) in real.columns.iter().enumerate() {
            row[slot] = real_buf[k];
        }
        for (k, &slot) in int.columns.iter().enumerate() {
            row[slot] = f64::from(int_buf[k]);
        }
        for (k, &slot) in boolean.columns.iter().enumerate() {
            row[slot] = if bool_buf[k] { 1.0 } else { 0.0 };
        }
        recorder
            .sample(Sample {
                step: n,
                time,
                values: &row,
            })
            .with_context(cannot_write)?;
        Ok(())
    };
    // Every failure after the header, the FMU's or ours, ends the CSV with its trailer.
    let mut outcome = record(instance.as_mut(), 0, start);
    // Set when the FMU asks to end the simulation: the time it reached.
    let mut terminated_at = None;
    for n in 1..=steps {
        if outcome.is_err() {
            break;
        }
        if crate::interrupt::pending() {
            outcome = Err(MasterError::Interrupted {
                time: start + (n - 1) as f64 * step,
                reason: crate::interrupt::REASON.into(),
            }
            .into());
            break;
        }
        let time = start + n as f64 * step;
        outcome = match instance.step(start + (n - 1) as f64 * step, step) {
            Ok(()) => record(instance.as_mut(), n, time),
            // The FMU ends the simulation (FMI 2.0: fmi2Discard with fmi2Terminated;
            // FMI 3.0: terminateSimulation): the point it reached is the last row (as
            // fmpy records it).
            Err(tether_fmi::Error::TerminationRequested { time: at, .. }) => {
                terminated_at = Some(at);
                let recorded = record(instance.as_mut(), n, at);
                if recorded.is_ok() {
                    break;
                }
                recorded
            }
            Err(e) => Err(e.into()),
        };
    }
    let failure = outcome.as_ref().err().map(|e| format!("{e:#}"));
    let finished = recorder.finish(failure.as_deref());
    drop(guard);
    finished.with_context(cannot_write)?;
    outcome.with_context(|| {
        format!(
            "simulation stopped; results so far kept in {}",
            out.display()
        )
    })?;
    instance.terminate()?;
    match terminated_at {
        None => crate::say!(
            "{name}: {steps} steps of {step} from {start} to {stop}; results: {}",
            out.display()
        ),
        Some(at) => crate::say!(
            "{name}: steps of {step} from {start}; the FMU requested the end of the simulation \
             at t = {at} ({}), before the stop time {stop}; results: {}",
            if fmi3 {
                "fmi3DoStep, terminateSimulation"
            } else {
                "fmi2Discard, fmi2Terminated"
            },
            out.display()
        ),
    }
    Ok(())
}
