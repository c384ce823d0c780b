//! `tether simulate FILE.fmu`: one FMU at a fixed communication step, every
//! output to CSV — the same job as `fmpy simulate`, so an FMU can be checked
//! against fmpy before it is coupled.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use tether_fmi::{BaseType, Causality, Fmu};
use tether_master::{apply_start_value, CsvRecorder, MasterError, Observer, Sample, StartValue};

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
        .filter(|v| v.causality == Causality::Output && v.base_type() != BaseType::String)
        .collect();
    let columns: Vec<String> = outputs.iter().map(|v| v.name.clone()).collect();
    let real: Vec<(usize, u32)> = kind_slots(&outputs, BaseType::Real);
    let mut int: Vec<(usize, u32)> = kind_slots(&outputs, BaseType::Integer);
    int.extend(kind_slots(&outputs, BaseType::Enumeration));
    let boolean: Vec<(usize, u32)> = kind_slots(&outputs, BaseType::Boolean);

    let name = md.co_simulation.model_identifier.clone();
    let mut local = tether_fmi::LocalInstance::new(fmu.instantiate(&name, Default::default())?);
    for assignment in &args.set {
        let (var, value) = assignment
            .split_once('=')
            .with_context(|| format!("--set {assignment}: expected NAME=VALUE"))?;
        apply_start_value(
            &mut local,
            &md,
            var.trim(),
            &StartValue::parse_cli(value.trim()),
        )?;
    }
    let instance = local.instance();
    instance.setup_experiment(tolerance, start, Some(stop))?;
    instance.enter_initialization_mode()?;
    instance.exit_initialization_mode()?;

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
    let real_vrs: Vec<u32> = real.iter().map(|x| x.1).collect();
    let int_vrs: Vec<u32> = int.iter().map(|x| x.1).collect();
    let bool_vrs: Vec<u32> = boolean.iter().map(|x| x.1).collect();
    let mut real_buf = vec![0.0; real.len()];
    let mut int_buf = vec![0; int.len()];
    let mut bool_buf = vec![false; boolean.len()];
    let mut record = |instance: &mut tether_fmi::Instance, n: u64, time: f64| -> Result<()> {
        instance.get_real(&real_vrs, &mut real_buf)?;
        instance.get_integer(&int_vrs, &mut int_buf)?;
        instance.get_boolean(&bool_vrs, &mut bool_buf)?;
        // A non-finite output is the FMU's error, named before it is recorded.
        if let Some(k) = real_buf.iter().position(|v| !v.is_finite()) {
            return Err(MasterError::NonFiniteOutput {
                instance: name.clone(),
                variable: columns[real[k].0].clone(),
                value: real_buf[k],
                call: if n == 0 {
                    "after initialization"
                } else {
                    "after fmi2DoStep"
                },
                time,
            }
            .into());
        }
        for (k, &(slot, _)) in real.iter().enumerate() {
            row[slot] = real_buf[k];
        }
        for (k, &(slot, _)) in int.iter().enumerate() {
            row[slot] = f64::from(int_buf[k]);
        }
        for (k, &(slot, _)) in boolean.iter().enumerate() {
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
    let mut outcome = record(&mut *instance, 0, start);
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
        outcome = match instance.do_step(start + (n - 1) as f64 * step, step, true) {
            Ok(()) => record(&mut *instance, n, time),
            // fmi2Discard with fmi2Terminated: the FMU ends the simulation; the
            // point it reached is the last row (as fmpy records it).
            Err(e @ tether_fmi::Error::Discard { .. }) => match instance.terminated() {
                Ok(true) => {
                    let at = instance.last_successful_time().unwrap_or(time);
                    terminated_at = Some(at);
                    let recorded = record(&mut *instance, n, at);
                    if recorded.is_ok() {
                        break;
                    }
                    recorded
                }
                _ => Err(e.into()),
            },
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
             at t = {at} (fmi2Discard, fmi2Terminated), before the stop time {stop}; results: {}",
            out.display()
        ),
    }
    Ok(())
}

fn kind_slots(outputs: &[&tether_fmi::ScalarVariable], kind: BaseType) -> Vec<(usize, u32)> {
    outputs
        .iter()
        .enumerate()
        .filter(|(_, v)| v.base_type() == kind)
        .map(|(i, v)| (i, v.value_reference))
        .collect()
}
