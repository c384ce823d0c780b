//! The oscillator of `fmus/oscillator` (its model, `oscillator-model`) with the
//! force input F alone, plus the fault parameters.

use oscillator_model::{declare, Oscillator};
use tether_fmu_kit::model::Restore;
use tether_fmu_kit::{Declaration, InputJet, Integer, Model, Parameters, Real};

use crate::fault::{Fault, Mode};

pub struct Faults {
    oscillator: Oscillator,
    fault: Fault,
}

impl Model for Faults {
    const DECLARATION: Declaration = Declaration {
        model_name: "faults",
        model_identifier: "faults",
        description: "The oscillator (m x'' = F - c x - d v) that misbehaves inside fmi2DoStep on demand, for reliability tests",
        real_parameters: &[
            declare::MECHANICS[0],
            declare::MECHANICS[1],
            declare::MECHANICS[2],
            declare::MECHANICS[3],
            declare::MECHANICS[4],
            Real::new("at", 0.5)
                .unit("s")
                .description("The fault happens in the first fmi2DoStep from this communication point on"),
            Real::new("delay", 0.0)
                .min(0.0)
                .unit("s")
                .description("Wall time every fmi2DoStep sleeps, in every mode (to slow a run down)"),
            Real::new("pause", 1.0)
                .min(0.0)
                .unit("s")
                .description("Mode 7: wall time each fmi2DoStep from `at` on sleeps"),
            Real::new("noise", 0.01)
                .min(0.0)
                .unit("m")
                .description("Mode 13: the largest offset the fmi2DoStep after each fmi2SetFMUstate from `at` on adds to the states; mode 14: the drift of the position output per read"),
        ],
        integer_parameters: &[
            Integer::new("mode", 0).min(0).max(16).description(
                "0 none, 1 segfault, 2 abort(), 3 exit(0), 4 exit(3), 5 endless loop, 6 log flood, 7 slow calls, 8 a helper process then segfault, 9 fork and the child calls exit(0), 10 fork with a lingering child then segfault, 11 a helper process, 12 fmi2SetFMUstate keeps the states, 13 the step after fmi2SetFMUstate adds noise, 14 every read of the outputs adds noise (they change without a step), 15 the library stays loaded and aborts at process exit, 16 the step from `at` waits for `peers` instances to reach it",
            ),
            Integer::new("flood", 2000)
                .min(0)
                .description("Mode 6: warnings logged by each fmi2DoStep from `at` on"),
            Integer::new("peers", 2)
                .min(1)
                .description("Mode 16: the instances that must reach the step from `at` before it goes on"),
        ],
        boolean_parameters: &[declare::EXACT],
        inputs: &[declare::FORCE],
        outputs: &[
            declare::POSITION_AND_VELOCITY[0],
            declare::POSITION_AND_VELOCITY[1],
            declare::acceleration(&["pos", "vel", "F"]),
        ],
        states: &declare::STATES,
        max_output_derivative_order: 2,
        default_experiment: declare::DEFAULT_EXPERIMENT,
        ..Declaration::EMPTY
    };
    // The log flood (mode 6) goes through the environment's logger.
    const LOGS: bool = true;

    fn new(p: &Parameters) -> Result<Self, String> {
        let oscillator = Oscillator::with_parameters(p, p.boolean("exact")?)?;
        let mode = p.integer("mode")?;
        let mode = Mode::from_index(mode).ok_or_else(|| format!("unknown mode {mode}"))?;
        let flood = p.integer("flood")?;
        let peers = p.integer("peers")?;
        Ok(Faults {
            oscillator,
            fault: Fault {
                mode,
                at: p.real("at")?,
                delay: p.real("delay")?,
                pause: p.real("pause")?,
                flood: u32::try_from(flood)
                    .map_err(|_| format!("flood must be >= 0, got {flood}"))?,
                peers: u32::try_from(peers)
                    .map_err(|_| format!("peers must be >= 1, got {peers}"))?,
                noise: p.real("noise")?,
                seed: std::cell::Cell::new(0x9E37_79B9_7F4A_7C15),
                pending: std::cell::Cell::new(0.0),
                reads: std::cell::Cell::new(0),
            },
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        self.oscillator.initial_states(x);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.oscillator.derivatives_under(x, u[0], dx);
    }

    fn outputs(&self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        self.oscillator.outputs_under(x, u[0], y);
        self.fault.drift(t, y);
    }

    fn output_derivatives(
        &self,
        _t: f64,
        x: &[f64],
        u: &[InputJet],
        order: u32,
        dy: &mut [f64],
    ) -> bool {
        self.oscillator.output_derivatives_under(x, u[0], order, dy)
    }

    /// Called first by every fmi2DoStep: the fault happens here (and mode 13's
    /// offset after a restore), then the step itself (exact, or `false` for Dop853) as the oscillator's.
    fn exact_step(&self, t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        self.fault.strike(t, h);
        self.fault.disturb(x);
        self.oscillator.exact_step_under(h, x, u[0])
    }

    fn restore(&self, t: f64) -> Restore {
        self.fault.restore(t)
    }
}
