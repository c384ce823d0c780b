//! Single-mass oscillator: m ẍ = F + F_ext − c x − d v.
//!
//! Outputs position `x`, velocity `v` and acceleration `a` (direct feedthrough of the
//! forces `F` and `F_ext`), with output derivatives up to order 2. With
//! `exact = true` a step is the matrix exponential of the system augmented with the
//! input polynomial, exact for inputs of degree ≤ 2. Two force inputs let a
//! constraint drive one (`F`) while a signal connection drives the other (`F_ext`,
//! e.g. from a controller); the model only sees their sum.

use std::cell::Cell;

use nalgebra::Matrix5;
use tether_fmu_kit::{
    export_fmu, Boolean, Declaration, DefaultExperiment, InputJet, Model, Output, Parameters, Real,
    State,
};

pub struct Oscillator {
    m: f64,
    c: f64,
    d: f64,
    x0: f64,
    v0: f64,
    exact: bool,
    /// The last step size's transition matrix exp(A h), keyed by the bits of h: a
    /// co-simulation repeats one step size (the predictor, every perturbed run and the
    /// corrector), so the exponential is computed once, not on every `fmi2DoStep`. The
    /// model is rebuilt whenever a parameter changes, which drops the cache. Only the
    /// rows of x and v are kept: the input's rows are the known Taylor shift.
    transition: Cell<Option<(u64, [[f64; 5]; 2])>>,
}

impl Oscillator {
    fn acceleration(&self, x: f64, v: f64, f: f64) -> f64 {
        (f - self.c * x - self.d * v) / self.m
    }

    /// d/dt of z = [x, v, F, Ḟ, F̈] with F̈ constant: ż = A z.
    fn augmented_matrix(&self) -> Matrix5<f64> {
        let (m, c, d) = (self.m, self.c, self.d);
        #[rustfmt::skip]
        let a = Matrix5::new(
            0.0,    1.0,    0.0,     0.0, 0.0,
            -c / m, -d / m, 1.0 / m, 0.0, 0.0,
            0.0,    0.0,    0.0,     1.0, 0.0,
            0.0,    0.0,    0.0,     0.0, 1.0,
            0.0,    0.0,    0.0,     0.0, 0.0,
        );
        a
    }

    /// The rows of x and v of exp(A h), from the cache when h is the last step size.
    fn transition(&self, h: f64) -> [[f64; 5]; 2] {
        match self.transition.get() {
            Some((bits, rows)) if bits == h.to_bits() => rows,
            _ => {
                let phi: Matrix5<f64> = (self.augmented_matrix() * h).exp();
                let row = |r: usize| std::array::from_fn(|j| phi[(r, j)]);
                let rows = [row(0), row(1)];
                self.transition.set(Some((h.to_bits(), rows)));
                rows
            }
        }
    }
}

impl Model for Oscillator {
    const DECLARATION: Declaration = Declaration {
        model_name: "oscillator",
        model_identifier: "oscillator",
        description: "Single mass on a spring and damper, driven by a force: m x'' = F - c x - d v",
        real_parameters: &[
            Real::new("m", 1.0)
                .unit("kg")
                .description("Mass (must be > 0)"),
            Real::new("c", 1000.0)
                .min(0.0)
                .unit("N/m")
                .description("Spring stiffness"),
            Real::new("d", 10.0)
                .min(0.0)
                .unit("N.s/m")
                .description("Damping coefficient"),
            Real::new("x0", 0.0)
                .unit("m")
                .description("Initial position"),
            Real::new("v0", 100.0)
                .unit("m/s")
                .description("Initial velocity"),
        ],
        boolean_parameters: &[Boolean::new("exact", false)
            .description("Integrate exactly (matrix exponential) instead of with Dop853")],
        inputs: &[
            Real::new("F", 0.0)
                .unit("N")
                .description("Force on the mass"),
            Real::new("F_ext", 0.0)
                .unit("N")
                .description("Additional force on the mass (added to F)"),
        ],
        outputs: &[
            Output::new("x")
                .unit("m")
                .description("Position")
                .depends_on(&["pos"]),
            Output::new("v")
                .unit("m/s")
                .description("Velocity")
                .depends_on(&["vel"]),
            Output::new("a")
                .unit("m/s2")
                .description("Acceleration")
                .depends_on(&["pos", "vel", "F", "F_ext"]),
        ],
        states: &[
            State::new("pos")
                .unit("m", "m/s")
                .description("Position state"),
            State::new("vel")
                .unit("m/s", "m/s2")
                .description("Velocity state"),
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
        Ok(Oscillator {
            m,
            c: p.real("c")?,
            d: p.real("d")?,
            x0: p.real("x0")?,
            v0: p.real("v0")?,
            exact: p.boolean("exact")?,
            transition: Cell::new(None),
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        x.copy_from_slice(&[self.x0, self.v0]);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = self.acceleration(x[0], x[1], u[0] + u[1]);
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        y.copy_from_slice(&[x[0], x[1], self.acceleration(x[0], x[1], u[0] + u[1])]);
    }

    fn output_derivatives(
        &self,
        _t: f64,
        x: &[f64],
        u: &[InputJet],
        order: u32,
        dy: &mut [f64],
    ) -> bool {
        let f = total(u);
        let a = self.acceleration(x[0], x[1], f.value);
        let jerk = self.acceleration(x[1], a, f.d1);
        match order {
            1 => dy.copy_from_slice(&[x[1], a, jerk]),
            2 => dy.copy_from_slice(&[a, jerk, self.acceleration(a, jerk, f.d2)]),
            _ => return false,
        }
        true
    }

    fn exact_step(&self, _t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        if !self.exact {
            return false;
        }
        let f = total(u);
        let z = [x[0], x[1], f.value, f.d1, f.d2];
        let rows = self.transition(h);
        // Summed in column order, as nalgebra's matrix-vector product does.
        let dot = |row: &[f64; 5]| (1..5).fold(row[0] * z[0], |acc, j| acc + row[j] * z[j]);
        x.copy_from_slice(&[dot(&rows[0]), dot(&rows[1])]);
        true
    }
}

/// The total force F + F_ext with its derivatives.
fn total(u: &[InputJet]) -> InputJet {
    InputJet {
        value: u[0].value + u[1].value,
        d1: u[0].d1 + u[1].d1,
        d2: u[0].d2 + u[1].d2,
    }
}

export_fmu!(Oscillator);
