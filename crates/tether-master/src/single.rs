//! One FMU on its own at a fixed communication step, every output at every
//! step: the simulation of `tether simulate` and of Python's
//! `tether.simulate` (the same job as fmpy's `simulate_fmu`).
//!
//! The FMU is driven through the master's instance interface
//! ([`tether_fmi::FmuInstance`]), so FMI 2.0 and FMI 3.0 FMUs share this loop.
//! An array output is one column per element, `y[1]`, `A[2,3]` (1-based,
//! row-major). Every Real output is checked after every call: a NaN or
//! infinite value stops the run with [`MasterError::NonFiniteOutput`] before
//! it is recorded. An FMU's request to end the simulation (FMI 2.0:
//! `fmi2Discard` with `fmi2Terminated`; FMI 3.0: `terminateSimulation`) ends
//! the run normally, the point it reached being the last row (as fmpy
//! records it).
//!
//! ```no_run
//! use tether_master::{MemoryRecorder, SingleExperiment, SingleFmu, SingleOutputs};
//! # fn main() -> Result<(), tether_master::MasterError> {
//! let fmu = tether_fmi::Fmu::open("target/fmus/oscillator.fmu")?;
//! let md = fmu.model_description();
//! let experiment = SingleExperiment::new(md, None, Some(1.0), Some(1e-3), None)?;
//! let mut single = SingleFmu::new(&fmu, &[], experiment)?;
//! let outputs = SingleOutputs::all(md, single.arrays())?;
//! let mut rows = MemoryRecorder::default();
//! let run = single.run(&outputs, &mut rows, &mut || None);
//! let end = run.end?;
//! single.terminate()?;
//! println!("{end:?} after {} steps", run.steps);
//! # Ok(()) }
//! ```

use tether_fmi::{
    BaseType, Causality, FmiStandard, Fmu, FmuInstance, Int, Integrator, MeInstance,
    ModelDescription, Placement, ScalarVariable, ValueReference, ValueType,
};

use crate::observer::integer_value;
use crate::{apply_start_values, Arrays, MasterError, Observer, Sample, StartValue};

/// The time grid of a single-FMU simulation: `start + n·step`, n = 0 … `steps`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SingleExperiment {
    /// Start time.
    pub start: f64,
    /// Stop time as asked (the grid ends at [`end`](Self::end)).
    pub stop: f64,
    /// Communication step.
    pub step: f64,
    /// Tolerance for the FMU's solver, if any.
    pub tolerance: Option<f64>,
    /// The number of steps: (stop − start)/step rounded, at least 1.
    pub steps: u64,
}

impl SingleExperiment {
    /// The given times, else the FMU's DefaultExperiment, else start 0, stop
    /// start + 1, step (stop − start)/500 (the tolerance only if given or
    /// declared). A time span that is not finite and increasing, or a step
    /// that is not finite and positive, is an error.
    pub fn new(
        md: &ModelDescription,
        start: Option<f64>,
        stop: Option<f64>,
        step: Option<f64>,
        tolerance: Option<f64>,
    ) -> Result<SingleExperiment, MasterError> {
        let de = md.default_experiment.unwrap_or_default();
        let start = start.or(de.start_time).unwrap_or(0.0);
        let stop = stop.or(de.stop_time).unwrap_or(start + 1.0);
        let step = step.or(de.step_size).unwrap_or((stop - start) / 500.0);
        let tolerance = tolerance.or(de.tolerance);
        if !(start.is_finite() && stop.is_finite() && stop > start) {
            return Err(MasterError::InvalidTimeSpan { start, stop });
        }
        if !(step.is_finite() && step > 0.0) {
            return Err(MasterError::InvalidParameter {
                name: "step".into(),
                value: step,
                expected: "a finite communication step > 0".into(),
            });
        }
        let steps = ((stop - start) / step).round().max(1.0) as u64;
        Ok(SingleExperiment {
            start,
            stop,
            step,
            tolerance,
            steps,
        })
    }

    /// The time of grid point `n`: `start + n·step`.
    pub fn time(&self, n: u64) -> f64 {
        self.start + n as f64 * self.step
    }

    /// The last point of the grid, `start + steps·step`.
    pub fn end(&self) -> f64 {
        self.time(self.steps)
    }

    /// Whether the stop time is on the grid (to 1e-9 of a step).
    pub fn stop_on_grid(&self) -> bool {
        (self.end() - self.stop).abs() <= 1e-9 * self.step
    }
}

/// The outputs of one kind: their value references, and the column of each
/// value (an array has one per element).
#[derive(Debug, Default)]
struct Slots {
    vrs: Vec<ValueReference>,
    columns: Vec<usize>,
}

/// The outputs a single-FMU simulation records: one column per value, an
/// array one per element.
#[derive(Debug)]
pub struct SingleOutputs {
    columns: Vec<String>,
    real: Slots,
    int: Slots,
    boolean: Slots,
}

impl SingleOutputs {
    /// Every output that is neither a String nor a Clock, in file order; the
    /// arrays' sizes follow the structural parameters set (`arrays`).
    pub fn all(md: &ModelDescription, arrays: &Arrays) -> Result<SingleOutputs, MasterError> {
        SingleOutputs::of(
            md,
            arrays,
            md.model_variables
                .iter()
                .filter(|v| v.causality == Causality::Output),
        )
    }

    /// The given variables, in the given order (String and Clock variables
    /// have no column and are left out).
    pub fn of<'a>(
        md: &ModelDescription,
        arrays: &Arrays,
        variables: impl IntoIterator<Item = &'a ScalarVariable>,
    ) -> Result<SingleOutputs, MasterError> {
        let mut outputs = SingleOutputs {
            columns: Vec::new(),
            real: Slots::default(),
            int: Slots::default(),
            boolean: Slots::default(),
        };
        for v in variables {
            if v.base_type() == BaseType::String || v.value_type == ValueType::Clock {
                continue;
            }
            let slots = match v.base_type() {
                BaseType::Real => &mut outputs.real,
                BaseType::Integer | BaseType::Enumeration => &mut outputs.int,
                _ => &mut outputs.boolean,
            };
            slots.vrs.push(v.value_reference);
            for element in arrays.element_names(md, v)? {
                slots.columns.push(outputs.columns.len());
                outputs.columns.push(element);
            }
        }
        Ok(outputs)
    }

    /// The column names (without `time`).
    pub fn columns(&self) -> &[String] {
        &self.columns
    }
}

/// How a single-FMU simulation that did not fail ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SingleEnd {
    /// At the last point of the grid.
    Completed,
    /// The FMU requested the end of the simulation at `time` (the last row).
    Terminated {
        /// The time the FMU reached.
        time: f64,
    },
}

/// What [`SingleFmu::run`] did: the steps made and recorded, and how it ended.
/// On failure the observer has the rows up to the last step made and was
/// finished with the error's message.
#[derive(Debug)]
pub struct SingleRun {
    /// The steps made and recorded (rows − 1).
    pub steps: u64,
    /// How the run ended, or why it stopped.
    pub end: Result<SingleEnd, MasterError>,
}

/// Which interface of an FMU a single-FMU simulation runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FmiType {
    /// Co-simulation: the FMU steps itself.
    CoSimulation,
    /// Model exchange, integrated by the instance's built-in integrator
    /// ([`MeInstance`]); its relative tolerance is the experiment's unless
    /// the integrator sets one.
    ModelExchange(Integrator),
}

impl FmiType {
    /// Co-simulation where the FMU has it, else model exchange (default
    /// integrator).
    pub fn default_for(md: &ModelDescription) -> FmiType {
        if md.co_simulation.is_none() && md.model_exchange.is_some() {
            FmiType::ModelExchange(Integrator::default())
        } else {
            FmiType::CoSimulation
        }
    }
}

/// An FMU instantiated in this process, its start values set and initialized:
/// ready to [`run`](Self::run).
#[derive(Debug)]
pub struct SingleFmu {
    instance: Box<dyn FmuInstance>,
    model_exchange: bool,
    experiment: SingleExperiment,
    arrays: Arrays,
    warnings: Vec<String>,
}

impl SingleFmu {
    /// Instantiate `fmu` (named by its model identifier) for co-simulation, set
    /// the start values by variable name, in the given order, and initialize it
    /// for `experiment`.
    pub fn new(
        fmu: &Fmu,
        start_values: &[(String, StartValue)],
        experiment: SingleExperiment,
    ) -> Result<SingleFmu, MasterError> {
        SingleFmu::new_as(fmu, start_values, experiment, FmiType::CoSimulation)
    }

    /// As [`new`](Self::new), for the interface `fmi_type`.
    pub fn new_as(
        fmu: &Fmu,
        start_values: &[(String, StartValue)],
        experiment: SingleExperiment,
        fmi_type: FmiType,
    ) -> Result<SingleFmu, MasterError> {
        let md = fmu.model_description();
        let (mut instance, model_exchange): (Box<dyn FmuInstance>, bool) = match fmi_type {
            FmiType::CoSimulation => {
                let name = &md.cs().model_identifier;
                let instance =
                    tether_fmi::instantiate(fmu, name, Default::default(), Placement::InProcess)?;
                (instance, false)
            }
            FmiType::ModelExchange(integrator) => {
                let name = md
                    .model_exchange
                    .as_ref()
                    .map_or(md.model_identifier(), |me| me.model_identifier.as_str());
                let instance = MeInstance::new(fmu, name, Default::default(), integrator)?;
                (Box::new(instance), true)
            }
        };
        // FMI 2.0: the experiment right after instantiation, then the start
        // values, as FMPy and libcosim set them (docs/fmi-import.md).
        instance.setup(
            experiment.tolerance,
            experiment.start,
            Some(experiment.stop),
        )?;
        let values = || start_values.iter().map(|(n, v)| (n.as_str(), v));
        let arrays = apply_start_values(instance.as_mut(), md, values())?;
        instance.enter_initialization()?;
        instance.exit_initialization()?;
        let exact = crate::start::exact_parameters(md, values());
        let warnings = crate::start::changed_parameters(instance.as_mut(), &exact, &[])?;
        Ok(SingleFmu {
            instance,
            model_exchange,
            experiment,
            arrays,
            warnings,
        })
    }

    /// Warnings for the user before the run, each one line: every parameter
    /// set with `initial="exact"` that the FMU changed in its initialization.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The arrays' sizes and values as the start values set them.
    pub fn arrays(&self) -> &Arrays {
        &self.arrays
    }

    /// The instance name (the FMU's model identifier).
    pub fn name(&self) -> &str {
        self.instance.name()
    }

    /// Whether the simulation runs the FMU's model-exchange interface.
    pub fn is_model_exchange(&self) -> bool {
        self.model_exchange
    }

    /// Whether the FMU is an FMI 3.0 one.
    pub fn is_fmi3(&self) -> bool {
        self.instance.model_description().standard == FmiStandard::Fmi3
    }

    /// Record `outputs` at every grid point into `observer` (started with
    /// their columns, finished with the failure's message, if any), stepping
    /// to the end of the grid or to the FMU's request to end. `interrupt` is
    /// asked before every step: `Some(reason)` stops the run there with
    /// [`MasterError::Interrupted`].
    pub fn run(
        &mut self,
        outputs: &SingleOutputs,
        observer: &mut dyn Observer,
        interrupt: &mut dyn FnMut() -> Option<String>,
    ) -> SingleRun {
        if let Err(e) = observer.start(&outputs.columns) {
            return SingleRun {
                steps: 0,
                end: Err(e.into()),
            };
        }
        let mut recorder = Recorder::new(outputs, self.is_fmi3(), self.model_exchange);
        let instance = self.instance.as_mut();
        let x = self.experiment;
        // Every failure after the start, the FMU's or the observer's, finishes
        // the observer with its message.
        let mut made = 0;
        let mut outcome = recorder.record(instance, observer, 0, x.start);
        let mut end = SingleEnd::Completed;
        for n in 1..=x.steps {
            if outcome.is_err() {
                break;
            }
            if let Some(reason) = interrupt() {
                outcome = Err(MasterError::Interrupted {
                    time: x.time(n - 1),
                    reason,
                });
                break;
            }
            outcome = match instance.step(x.time(n - 1), x.step) {
                Ok(()) => recorder.record(instance, observer, n, x.time(n)),
                Err(tether_fmi::Error::TerminationRequested { time, .. }) => {
                    let recorded = recorder.record(instance, observer, n, time);
                    if recorded.is_ok() {
                        made = n;
                        end = SingleEnd::Terminated { time };
                        break;
                    }
                    recorded
                }
                Err(e) => Err(MasterError::Fmi(e)),
            };
            if outcome.is_ok() {
                made = n;
            }
        }
        let failure = outcome.as_ref().err().map(|e| crate::error_line(e));
        let finished = observer.finish(failure.as_deref());
        SingleRun {
            steps: made,
            end: outcome.and(finished.map_err(MasterError::from).map(|()| end)),
        }
    }

    /// End the simulation (`fmi2Terminate`, `fmi3Terminate`); the instance is
    /// freed when dropped.
    pub fn terminate(&mut self) -> Result<(), MasterError> {
        Ok(self.instance.terminate()?)
    }
}

/// Reads the outputs into a row and hands it to the observer.
struct Recorder<'a> {
    outputs: &'a SingleOutputs,
    fmi3: bool,
    model_exchange: bool,
    row: Vec<f64>,
    reals: Vec<f64>,
    ints: Vec<Int>,
    /// The integers of the row that a float rounds, exactly (by column).
    exact: Vec<(usize, Int)>,
    bools: Vec<bool>,
}

impl<'a> Recorder<'a> {
    fn new(outputs: &'a SingleOutputs, fmi3: bool, model_exchange: bool) -> Recorder<'a> {
        Recorder {
            outputs,
            fmi3,
            model_exchange,
            row: vec![0.0; outputs.columns.len()],
            reals: vec![0.0; outputs.real.columns.len()],
            ints: vec![0; outputs.int.columns.len()],
            exact: Vec::new(),
            bools: vec![false; outputs.boolean.columns.len()],
        }
    }

    /// Grid point `n` at `time`: read, check, record.
    fn record(
        &mut self,
        instance: &mut dyn FmuInstance,
        observer: &mut dyn Observer,
        n: u64,
        time: f64,
    ) -> Result<(), MasterError> {
        let o = self.outputs;
        // An FMI 2.0 FMU is asked even for no values (as fmpy does).
        if !o.real.vrs.is_empty() || !self.fmi3 {
            instance.get_reals(&o.real.vrs, &mut self.reals)?;
        }
        if !o.int.vrs.is_empty() || !self.fmi3 {
            instance.get_integers(&o.int.vrs, &mut self.ints)?;
        }
        if !o.boolean.vrs.is_empty() || !self.fmi3 {
            instance.get_booleans(&o.boolean.vrs, &mut self.bools)?;
        }
        // A non-finite output is the FMU's error, named before it is recorded.
        if let Some(k) = self.reals.iter().position(|v| !v.is_finite()) {
            return Err(MasterError::NonFiniteOutput {
                instance: instance.name().to_string(),
                variable: o.columns[o.real.columns[k]].clone(),
                value: self.reals[k],
                call: match (n, self.fmi3, self.model_exchange) {
                    (0, _, _) => "after initialization",
                    (_, _, true) => "after an integrator step",
                    (_, true, _) => "after fmi3DoStep",
                    (_, false, _) => "after fmi2DoStep",
                },
                time,
            });
        }
        for (k, &slot) in o.real.columns.iter().enumerate() {
            self.row[slot] = self.reals[k];
        }
        self.exact.clear();
        for (k, &slot) in o.int.columns.iter().enumerate() {
            let (v, exact) = integer_value(self.ints[k]);
            self.row[slot] = v;
            if !exact {
                self.exact.push((slot, self.ints[k]));
            }
        }
        self.exact.sort_unstable_by_key(|&(slot, _)| slot);
        for (k, &slot) in o.boolean.columns.iter().enumerate() {
            self.row[slot] = if self.bools[k] { 1.0 } else { 0.0 };
        }
        observer.sample(Sample {
            step: n,
            time,
            values: &self.row,
            exact: &self.exact,
            strings: &[],
        })?;
        Ok(())
    }
}
