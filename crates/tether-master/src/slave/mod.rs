//! One FMU instance as the coupling algorithm sees it: a thin handle on the
//! instance ([`FmuInstance`]) with what the method needs each step. Its other
//! concerns live beside it:
//!
//! - [`setup`]: instantiation, start values, the coupling's buffers, the
//!   instance's capabilities;
//! - [`coupled`]: the coupled inputs and outputs, set from the unknowns'
//!   polynomials and read after each run, with their divergence limits;
//! - [`runs`]: the runs of a macro step handed to the instance as one batch;
//! - [`recorded`]: the outputs recorded at accepted points;
//! - [`state`]: saved states (the step's, serialized copies, the system's);
//! - [`check`]: the rollback self-check.

mod check;
mod coupled;
pub(crate) mod interface;
mod recorded;
mod runs;
mod setup;
mod state;

use tether_fmi::{Fmu, FmuInstance, Slot};

pub(crate) use check::RollbackCheck;
use coupled::combine_inputs;
pub(crate) use coupled::{Coupled, CoupledOutput};
use recorded::Recorded;
pub(crate) use runs::Batch;
use runs::{recycle, Planned, Runs};

use crate::polynomial::Taylor;
use crate::stats::InstanceCounters;
use crate::MasterError;

/// The state slot of the state saved at the start of the macro step.
const SAVED: Slot = 0;
/// The state slot of the rollback self-check's own state.
const CHECK: Slot = 1;
/// The state slot of the whole system's saved state (`Simulation::save_state`).
const SNAPSHOT: Slot = 2;

/// Which call's results an instance's outputs are read after, for the message
/// naming a non-finite output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Run {
    /// Inputs set, no step: direct feedthrough (initial multipliers, the
    /// explicit method's update).
    Feedthrough,
    /// The predictor's `fmi2DoStep`.
    Predictor,
    /// A perturbed run's `fmi2DoStep`.
    Perturbed,
    /// The corrector's `fmi2DoStep` (the accepted point).
    Corrector,
    /// The explicit method's `fmi2DoStep` (the accepted point).
    Explicit,
    /// The `fmi2DoStep` after which a signal connection's sender is read.
    Signal,
    /// `fmi2GetFMUstate` / `fmi2SetFMUstate` (the rollback checks).
    Rollback,
    /// Initialization (the point T_0).
    Initial,
}

impl Run {
    /// The call, for messages: `after the predictor's fmi2DoStep`.
    pub(crate) fn describe(self) -> &'static str {
        match self {
            Run::Feedthrough => "after fmi2SetReal of the coupled inputs (direct feedthrough)",
            Run::Predictor => "after the predictor's fmi2DoStep",
            Run::Perturbed => "after a perturbed run's fmi2DoStep",
            Run::Corrector => "after the corrector's fmi2DoStep",
            Run::Explicit => "after fmi2DoStep",
            Run::Signal => "after fmi2DoStep (the sender of a signal connection)",
            Run::Rollback => "after fmi2GetFMUstate/fmi2SetFMUstate",
            Run::Initial => "after initialization",
        }
    }
}

/// An FMU instance inside a coupled system.
pub struct Slave {
    pub(crate) name: String,
    pub(crate) model_name: String,
    /// The FMU instance, in this process or in a host process: the master
    /// reaches it only through [`FmuInstance`].
    pub(crate) backend: Box<dyn FmuInstance>,
    pub(crate) fmu: Fmu,
    /// What the instance can do ([`FmuInstance::capabilities`], asked once
    /// it is instantiated).
    pub(crate) caps: tether_fmi::Capabilities,
    /// Whether the instance runs the FMU's model-exchange interface.
    pub(crate) model_exchange: bool,
    /// Why `fmi_type = "auto"` took model exchange, for the user.
    pub(crate) interface_note: Option<String>,
    /// Whether [`SAVED`] holds a state.
    saved: bool,
    /// The coupled inputs and outputs and their buffers.
    pub(crate) coupled: Coupled,
    /// A batch's buffers, kept between steps.
    runs: Runs,
    /// The outputs recorded at accepted points.
    recorded: Recorded,
    /// The rollback self-check's settings and buffers.
    pub(crate) check: RollbackCheck,
    /// The start values' effect on the FMI 3.0 arrays: sizes, values.
    pub(crate) arrays: crate::start::Arrays,
    /// Signal connections: an array output read whole (its values).
    pub(crate) signal_buf: Vec<f64>,
    pub(crate) counters: InstanceCounters,
    /// Stepped by the signal connections' Gauss–Seidel sweep before the
    /// method's step, which then only reads its outputs.
    pub(crate) stepped_ahead: bool,
    /// The start values set on parameters with `initial="exact"`, read back
    /// after initialization ([`Slave::changed_parameters`]).
    exact_parameters: Vec<crate::start::ExactParameter>,
}

/// The experiment an instance is set up for: start, stop and tolerance.
pub(crate) type Experiment = (f64, f64, Option<f64>);

impl Slave {
    /// Number of coupled outputs (the length [`read_coupled`](Self::read_coupled) fills).
    pub(crate) fn coupled_len(&self) -> usize {
        self.coupled.outputs.len()
    }

    pub(crate) fn is_coupled(&self) -> bool {
        !self.coupled.inputs.is_empty()
    }

    /// Set the coupled inputs from the unknowns' polynomials, and their
    /// derivatives through `fmi2SetRealInputDerivatives` when k > 0 (`finalize`).
    pub(crate) fn apply_inputs(&mut self, polys: &[Taylor]) -> Result<(), MasterError> {
        if self.coupled.inputs.is_empty() {
            return Ok(());
        }
        combine_inputs(
            &self.coupled.inputs,
            &self.coupled.input_positions,
            polys,
            &mut self.coupled.input.values,
            &mut self.coupled.input.derivatives,
        );
        self.backend.set_inputs(&self.coupled.input.as_inputs())?;
        self.count_inputs();
        Ok(())
    }

    /// Counts the calls that set the coupled inputs.
    pub(super) fn count_inputs(&mut self) {
        self.counters.set_reals += 1;
        if !self.coupled.input.derivative_vrs.is_empty() {
            self.counters.set_input_derivatives += 1;
        }
    }

    /// One `fmi2DoStep` from `t` over `h`.
    /// fmi2Discard with `fmi2Terminated` true is
    /// [`MasterError::TerminationRequested`].
    pub(crate) fn do_step(&mut self, t: f64, h: f64) -> Result<(), MasterError> {
        self.counters.do_steps += 1;
        self.backend.step(t, h)?;
        Ok(())
    }

    /// `fmi2Terminate`, at a normal end of the run (not after a fatal error:
    /// tether-fmi then calls nothing).
    pub(crate) fn terminate(&mut self) -> Result<(), MasterError> {
        if !self.backend.is_fatal() {
            self.backend.terminate()?;
        }
        Ok(())
    }

    /// Read the coupled outputs into `out` (as long as [`coupled_len`](Self::coupled_len)).
    /// Every value must be finite: otherwise the error names this instance,
    /// the output, the call `run` and the time.
    pub(crate) fn read_coupled(&mut self, out: &mut [f64], run: Run) -> Result<(), MasterError> {
        let nv = self.values_len();
        if nv > 0 {
            self.backend
                .get_reals(&self.coupled.value_vrs, &mut self.coupled.value_buf[..nv])?;
            self.counters.get_reals += 1;
        }
        for (&(vr, order), value) in self
            .coupled
            .derivative_reads
            .iter()
            .zip(&mut self.coupled.value_buf[nv..])
        {
            self.backend
                .get_output_derivatives(&[vr], &[order], std::slice::from_mut(value))?;
        }
        let values = std::mem::take(&mut self.coupled.value_buf);
        let taken = self.take_coupled(&values, out, run);
        self.coupled.value_buf = values;
        taken
    }

    /// A perturbed or corrector run: roll back to the saved state, set the
    /// inputs from `polys`, step from `t` over `h`; with `out`, read the
    /// coupled outputs into it.
    pub(crate) fn rerun(
        &mut self,
        polys: &[Taylor],
        t: f64,
        h: f64,
        out: Option<&mut [f64]>,
    ) -> Result<(), MasterError> {
        if self.check.verify_restore {
            self.restore_state()?;
            self.apply_inputs(polys)?;
            self.do_step(t, h)?;
            return match out {
                Some(out) => self.read_coupled(out, Run::Perturbed),
                None => Ok(()),
            };
        }
        assert!(self.saved, "rerun is only called after save_state");
        let run = Planned {
            step: Some((polys, t, h)),
            restore: true,
            out,
            record: false,
            run: Run::Perturbed,
        };
        self.runs(&mut [run], Batch::Whole).map(drop)
    }

    /// The predictor's run (only the read of the coupled outputs for an
    /// instance the signals' sweep has stepped) and, with the same step, the
    /// perturbed runs from the saved state, one per `(polys, out)` of
    /// `perturbed`: handed to the instance together, since none depends on
    /// another's outputs (docs/algorithm.md, Steps 2 and 3). `how` as
    /// [`Slave::runs`] takes it (returns whether a reply is awaited).
    pub(crate) fn predict_and_perturb<'p>(
        &mut self,
        polys: &[Taylor],
        (t, h): (f64, f64),
        out: &mut [f64],
        perturbed: impl Iterator<Item = (&'p [Taylor], &'p mut [f64])>,
        how: Batch,
    ) -> Result<bool, MasterError> {
        let predictor = Planned {
            step: (!self.stepped_ahead).then_some((polys, t, h)),
            restore: false,
            out: Some(out),
            record: false,
            run: Run::Predictor,
        };
        if self.check.verify_restore {
            // Each restore is checked on its own (its outputs read back).
            self.runs(&mut [predictor], Batch::Whole)?;
            for (polys, out) in perturbed {
                self.rerun(polys, t, h, Some(out))?;
            }
            return Ok(false);
        }
        let mut planned = recycle(std::mem::take(&mut self.runs.planned_buf));
        planned.push(predictor);
        planned.extend(perturbed.map(|(polys, out)| Planned {
            step: Some((polys, t, h)),
            restore: true,
            out: Some(out),
            record: false,
            run: Run::Perturbed,
        }));
        let ran = self.runs(&mut planned, how);
        self.runs.planned_buf = recycle(planned);
        ran
    }

    /// The corrector's run: from the saved state with the inputs from
    /// `polys` over the step, the coupled outputs into `out` and the recorded
    /// outputs read at T_{N+1}, the accepted point. `how` as [`Slave::runs`]
    /// takes it (returns whether a reply is awaited).
    pub(crate) fn correct(
        &mut self,
        polys: &[Taylor],
        (t, h): (f64, f64),
        out: &mut [f64],
        how: Batch,
    ) -> Result<bool, MasterError> {
        if self.check.verify_restore {
            self.rerun(polys, t, h, None)?;
            return self.read_accepted(out, Run::Corrector).map(|()| false);
        }
        assert!(self.saved, "correct is only called after save_state");
        let run = Planned {
            step: Some((polys, t, h)),
            restore: true,
            out: Some(out),
            record: true,
            run: Run::Corrector,
        };
        self.runs(&mut [run], how)
    }

    /// The coupled outputs into `out` and the recorded outputs, at an
    /// accepted point reached after `run`.
    pub(crate) fn read_accepted(&mut self, out: &mut [f64], run: Run) -> Result<(), MasterError> {
        self.read_accepted_as(out, run, Batch::Whole).map(drop)
    }

    /// [`read_accepted`](Self::read_accepted) with `how` as [`Slave::runs`]
    /// takes it (returns whether a reply is awaited).
    pub(crate) fn read_accepted_as(
        &mut self,
        out: &mut [f64],
        run: Run,
        how: Batch,
    ) -> Result<bool, MasterError> {
        let read = Planned {
            step: None,
            restore: false,
            out: Some(out),
            record: true,
            run,
        };
        self.runs(&mut [read], how)
    }

    /// Call counters, with the round trips to the instance's host process.
    pub fn counters(&self) -> InstanceCounters {
        InstanceCounters {
            round_trips: self.backend.round_trips() - self.check.trips,
            ..self.counters.clone()
        }
    }
}
