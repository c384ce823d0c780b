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
//!   `Stair` does at t = 9).
//!
//! With the defaults (0 and times beyond any run) it is a well-behaved FMU.

use std::cell::Cell;

use tether_fmu_kit::{
    export_fmu, Declaration, DefaultExperiment, InputJet, Integer, Model, Output, Parameters, Real,
    State,
};

/// Runge–Kutta sub-steps per communication step.
const SUBSTEPS: u32 = 16;

pub struct Quirks {
    m: f64,
    c: f64,
    d: f64,
    x0: f64,
    v0: f64,
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
        (f - self.c * x - self.d * v) / self.m
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
            Real::new("m", 1.0).unit("kg").description("Mass (must be > 0)"),
            Real::new("c", 1000.0).min(0.0).unit("N/m").description("Spring stiffness"),
            Real::new("d", 10.0).min(0.0).unit("N.s/m").description("Damping coefficient"),
            Real::new("x0", 0.0).unit("m").description("Initial position"),
            Real::new("v0", 100.0).unit("m/s").description("Initial velocity"),
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
        integer_parameters: &[Integer::new("rollback", 0).min(0).max(2).description(
            "0: exact rollback; 1: fmi2SetFMUstate has no effect; 2: a repeated step differs",
        )],
        inputs: &[Real::new("F", 0.0).unit("N").description("Force on the mass")],
        outputs: &[
            Output::new("x").unit("m").description("Position").depends_on(&["pos"]),
            Output::new("v").unit("m/s").description("Velocity").depends_on(&["vel"]),
            Output::new("a")
                .unit("m/s2")
                .description("Acceleration")
                .depends_on(&["pos", "vel", "F"]),
        ],
        states: &[
            State::new("pos").unit("m", "m/s").description("Position state"),
            State::new("vel").unit("m/s", "m/s2").description("Velocity state"),
        ],
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-3,
        },
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        let m = p.real("m")?;
        if m.is_nan() || m <= 0.0 {
            return Err(format!("m must be > 0, got {m}"));
        }
        Ok(Quirks {
            m,
            c: p.real("c")?,
            d: p.real("d")?,
            x0: p.real("x0")?,
            v0: p.real("v0")?,
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
        x.copy_from_slice(&[self.x0, self.v0]);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = self.acceleration(x[0], x[1], u[0]);
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
}

export_fmu!(Quirks);
