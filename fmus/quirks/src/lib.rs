//! A single-mass oscillator, m ẍ = F − c x − d v (like the `oscillator` FMU,
//! integrated by classical Runge–Kutta with 16 sub-steps), whose parameters
//! select a misbehaviour seen in third-party FMUs, for the conformance tests
//! of issue 33:
//!
//! - `rollback = 1`: `fmi2SetFMUstate` has no effect — the model keeps its own
//!   copy of the states, which every step advances and no restore touches;
//! - `rollback = 2`: a step repeated after a rollback does not give the same
//!   result — every step adds `1e-9 · (number of steps so far)` to the position;
//! - `rollback_after`: the rollback quirk starts with the first step from this
//!   time on (default 0: from the start);
//! - `nan_after`: from this time on the output `x` is NaN;
//! - `huge_after`: from this time on the output `x` is 1e300;
//! - `stop_after`: the first step that reaches this time asks the master to end
//!   the simulation (fmi2Discard with fmi2Terminated, as the Reference FMU
//!   `Stair` does at t = 9);
//! - `reset_parameters = 1`: `fmi2SetupExperiment` resets every parameter to
//!   its start value, as FMUs of some modelling tools do (20-sim's among them):
//!   a value set before it is lost, one set after it stays;
//!   `reset_parameters = 2`: `fmi2ExitInitializationMode` resets them, so that
//!   every value set is lost, whatever the importer's order.
//!
//! With the defaults (0 and times beyond any run) it is a well-behaved FMU.
//!
//! The equations and the declarations it shares with the oscillator come from the
//! oscillator's model (`oscillator-model`).

use std::cell::Cell;

use oscillator_model::{declare, Oscillator};
use tether_fmu_kit::{
    export_fmu, Declaration, InputJet, Integer, Model, ParameterReset, Parameters, Real,
};

/// Runge–Kutta sub-steps per communication step.
const SUBSTEPS: u32 = 16;

pub struct Quirks {
    /// m, c, d, x0 and v0 (never integrated exactly: [`Quirks::rk4`] steps).
    oscillator: Oscillator,
    rollback: i32,
    rollback_after: f64,
    nan_after: f64,
    huge_after: f64,
    stop_after: f64,
    /// `rollback = 1`: the states as the model sees them, out of the kit's
    /// reach (the model is kept across `fmi2SetFMUstate` when the parameters
    /// do not change).
    own: Cell<Option<[f64; 2]>>,
    /// `rollback = 2`: steps made so far, rollbacks notwithstanding.
    steps: Cell<u64>,
}

impl Quirks {
    fn acceleration(&self, x: f64, v: f64, f: f64) -> f64 {
        self.oscillator.acceleration(x, v, f)
    }

    fn rk4(&self, h: f64, x: &mut [f64; 2], u: InputJet) {
        let dt = h / f64::from(SUBSTEPS);
        let rhs = |tau: f64, s: [f64; 2]| [s[1], self.acceleration(s[0], s[1], u.eval(tau))];
        for i in 0..SUBSTEPS {
            let tau = f64::from(i) * dt;
            let k1 = rhs(tau, *x);
            let k2 = rhs(
                tau + dt / 2.0,
                [x[0] + dt / 2.0 * k1[0], x[1] + dt / 2.0 * k1[1]],
            );
            let k3 = rhs(
                tau + dt / 2.0,
                [x[0] + dt / 2.0 * k2[0], x[1] + dt / 2.0 * k2[1]],
            );
            let k4 = rhs(tau + dt, [x[0] + dt * k3[0], x[1] + dt * k3[1]]);
            for j in 0..2 {
                x[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
            }
        }
    }

    /// The states the outputs come from: the model's own once `rollback = 1`
    /// has started.
    fn states(&self, x: &[f64]) -> [f64; 2] {
        self.own.get().unwrap_or([x[0], x[1]])
    }
}

impl Model for Quirks {
    const DECLARATION: Declaration = Declaration {
        model_name: "quirks",
        model_identifier: "quirks",
        description: "Single mass on a spring and damper with selectable FMI misbehaviour (conformance tests)",
        real_parameters: &[
            declare::MECHANICS[0],
            declare::MECHANICS[1],
            declare::MECHANICS[2],
            declare::MECHANICS[3],
            declare::MECHANICS[4],
            Real::new("rollback_after", 0.0)
                .unit("s")
                .description("The rollback quirk starts with the first step from this time on"),
            Real::new("nan_after", 1e9)
                .unit("s")
                .description("From this time on the output x is NaN"),
            Real::new("huge_after", 1e9)
                .unit("s")
                .description("From this time on the output x is 1e300"),
            Real::new("stop_after", 1e9).unit("s").description(
                "The step reaching this time returns fmi2Discard with fmi2Terminated = true",
            ),
        ],
        integer_parameters: &[
            Integer::new("rollback", 0).min(0).max(2).description(
                "0: exact rollback; 1: fmi2SetFMUstate has no effect; 2: a repeated step differs",
            ),
            Integer::new("reset_parameters", 0).min(0).max(2).description(
                "0: parameters keep their values; 1: fmi2SetupExperiment resets them to their start values; 2: fmi2ExitInitializationMode does",
            ),
        ],
        inputs: &[declare::FORCE],
        outputs: &[
            declare::POSITION_AND_VELOCITY[0],
            declare::POSITION_AND_VELOCITY[1],
            declare::acceleration(&["pos", "vel", "F"]),
        ],
        states: &declare::STATES,
        default_experiment: declare::DEFAULT_EXPERIMENT,
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        Ok(Quirks {
            oscillator: Oscillator::with_parameters(p, false)?,
            rollback: p.integer("rollback")?,
            rollback_after: p.real("rollback_after")?,
            nan_after: p.real("nan_after")?,
            huge_after: p.real("huge_after")?,
            stop_after: p.real("stop_after")?,
            own: Cell::new(None),
            steps: Cell::new(0),
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        self.oscillator.initial_states(x);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.oscillator.derivatives_under(x, u[0], dx);
    }

    fn outputs(&self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        let [pos, vel] = self.states(x);
        let shown = if t >= self.nan_after {
            f64::NAN
        } else if t >= self.huge_after {
            1e300
        } else {
            pos
        };
        y.copy_from_slice(&[shown, vel, self.acceleration(pos, vel, u[0])]);
    }

    fn exact_step(&self, t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        let mut s = self.states(x);
        self.rk4(h, &mut s, u[0]);
        let quirky = t >= self.rollback_after;
        if self.rollback == 2 && quirky {
            let n = self.steps.get() + 1;
            self.steps.set(n);
            s[0] += 1e-9 * n as f64;
        }
        if self.rollback == 1 && quirky {
            self.own.set(Some(s));
        }
        x.copy_from_slice(&s);
        true
    }

    fn terminate(&self, t: f64, _x: &[f64]) -> bool {
        t >= self.stop_after
    }

    fn parameter_reset(p: &Parameters) -> ParameterReset {
        match p.integer("reset_parameters") {
            Ok(1) => ParameterReset::AtSetupExperiment,
            Ok(2) => ParameterReset::AtExitInitialization,
            _ => ParameterReset::Never,
        }
    }
}

export_fmu!(Quirks);
