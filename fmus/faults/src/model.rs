//! The oscillator of `fmus/oscillator` (m ẍ = F − c x − d v, same variables), plus
//! the fault parameters. A copy rather than a dependency: the oscillator crate
//! exports the fmi2 symbols itself, which would clash with these.

use std::cell::Cell;

use nalgebra::Matrix5;
use tether_fmu_kit::{
    Boolean, Declaration, DefaultExperiment, InputJet, Integer, Model, Output, Parameters, Real,
    State,
};

use crate::fault::{Fault, Mode};

pub struct Faults {
    m: f64,
    c: f64,
    d: f64,
    x0: f64,
    v0: f64,
    exact: bool,
    fault: Fault,
    transition: Cell<Option<(u64, [[f64; 5]; 2])>>,
}

impl Faults {
    fn acceleration(&self, x: f64, v: f64, f: f64) -> f64 {
        (f - self.c * x - self.d * v) / self.m
    }

    fn transition(&self, h: f64) -> [[f64; 5]; 2] {
        match self.transition.get() {
            Some((bits, rows)) if bits == h.to_bits() => rows,
            _ => {
                let (m, c, d) = (self.m, self.c, self.d);
                #[rustfmt::skip]
                let a = Matrix5::new(
                    0.0,    1.0,    0.0,     0.0, 0.0,
                    -c / m, -d / m, 1.0 / m, 0.0, 0.0,
                    0.0,    0.0,    0.0,     1.0, 0.0,
                    0.0,    0.0,    0.0,     0.0, 1.0,
                    0.0,    0.0,    0.0,     0.0, 0.0,
                );
                let phi: Matrix5<f64> = (a * h).exp();
                let row = |r: usize| std::array::from_fn(|j| phi[(r, j)]);
                let rows = [row(0), row(1)];
                self.transition.set(Some((h.to_bits(), rows)));
                rows
            }
        }
    }
}

impl Model for Faults {
    const DECLARATION: Declaration = Declaration {
        model_name: "faults",
        model_identifier: "faults",
        description: "The oscillator (m x'' = F - c x - d v) that misbehaves inside fmi2DoStep on demand, for reliability tests",
        real_parameters: &[
            Real::new("m", 1.0).unit("kg").description("Mass (must be > 0)"),
            Real::new("c", 1000.0).min(0.0).unit("N/m").description("Spring stiffness"),
            Real::new("d", 10.0).min(0.0).unit("N.s/m").description("Damping coefficient"),
            Real::new("x0", 0.0).unit("m").description("Initial position"),
            Real::new("v0", 100.0).unit("m/s").description("Initial velocity"),
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
        ],
        integer_parameters: &[
            Integer::new("mode", 0).min(0).max(7).description(
                "0 none, 1 segfault, 2 abort(), 3 exit(0), 4 exit(3), 5 endless loop, 6 log flood, 7 slow calls",
            ),
            Integer::new("flood", 2000)
                .min(0)
                .description("Mode 6: warnings logged by each fmi2DoStep from `at` on"),
        ],
        boolean_parameters: &[Boolean::new("exact", false)
            .description("Integrate exactly (matrix exponential) instead of with Dop853")],
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
        max_output_derivative_order: 2,
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
        let mode = p.integer("mode")?;
        let mode = Mode::from_index(mode).ok_or_else(|| format!("unknown mode {mode}"))?;
        let flood = p.integer("flood")?;
        Ok(Faults {
            m,
            c: p.real("c")?,
            d: p.real("d")?,
            x0: p.real("x0")?,
            v0: p.real("v0")?,
            exact: p.boolean("exact")?,
            fault: Fault {
                mode,
                at: p.real("at")?,
                delay: p.real("delay")?,
                pause: p.real("pause")?,
                flood: u32::try_from(flood)
                    .map_err(|_| format!("flood must be >= 0, got {flood}"))?,
            },
            transition: Cell::new(None),
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        x.copy_from_slice(&[self.x0, self.v0]);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = self.acceleration(x[0], x[1], u[0]);
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        y.copy_from_slice(&[x[0], x[1], self.acceleration(x[0], x[1], u[0])]);
    }

    fn output_derivatives(
        &self,
        _t: f64,
        x: &[f64],
        u: &[InputJet],
        order: u32,
        dy: &mut [f64],
    ) -> bool {
        let f = u[0];
        let a = self.acceleration(x[0], x[1], f.value);
        let jerk = self.acceleration(x[1], a, f.d1);
        match order {
            1 => dy.copy_from_slice(&[x[1], a, jerk]),
            2 => dy.copy_from_slice(&[a, jerk, self.acceleration(a, jerk, f.d2)]),
            _ => return false,
        }
        true
    }

    /// Called first by every fmi2DoStep: the fault happens here, then the step
    /// itself (exact, or `false` for Dop853) as the oscillator's.
    fn exact_step(&self, t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        self.fault.strike(t, h);
        if !self.exact {
            return false;
        }
        let f = u[0];
        let z = [x[0], x[1], f.value, f.d1, f.d2];
        let rows = self.transition(h);
        let dot = |row: &[f64; 5]| (1..5).fold(row[0] * z[0], |acc, j| acc + row[j] * z[j]);
        x.copy_from_slice(&[dot(&rows[0]), dot(&rows[1])]);
        true
    }
}
