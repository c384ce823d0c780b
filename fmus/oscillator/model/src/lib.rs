//! The single-mass oscillator m ẍ = F − c x − d v: the model of the `oscillator`
//! FMU (where F is the sum of its two force inputs), kept apart from that FMU's
//! exports so that other FMUs (`faults`, `quirks`) build on the same equations
//! and declarations: a crate that exports an FMU cannot be linked into another.
//!
//! [`Oscillator`] is the oscillator FMU's [`Model`]; its methods taking the total
//! force (`*_under`) are what a model with other inputs calls.

use std::cell::Cell;

use nalgebra::Matrix5;
use tether_fmu_kit::{
    Boolean, Declaration, DefaultExperiment, InputJet, Model, Output, Parameters, Real, State,
};

/// The declarations the oscillator's variants share.
pub mod declare {
    use super::*;

    /// The parameters m, c, d, x0 and v0, in this order.
    pub const MECHANICS: [Real; 5] = [
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
    ];

    /// The parameter `exact`.
    pub const EXACT: Boolean = Boolean::new("exact", false)
        .description("Integrate exactly (matrix exponential) instead of with Dop853");

    /// The input F.
    pub const FORCE: Real = Real::new("F", 0.0)
        .unit("N")
        .description("Force on the mass");

    /// The outputs x and v.
    pub const POSITION_AND_VELOCITY: [Output; 2] = [
        Output::new("x")
            .unit("m")
            .description("Position")
            .depends_on(&["pos"]),
        Output::new("v")
            .unit("m/s")
            .description("Velocity")
            .depends_on(&["vel"]),
    ];

    /// The output a, which depends on the states and on the force `inputs`.
    pub const fn acceleration(inputs: &'static [&'static str]) -> Output {
        Output::new("a")
            .unit("m/s2")
            .description("Acceleration")
            .depends_on(inputs)
    }

    /// The states pos and vel.
    pub const STATES: [State; 2] = [
        State::new("pos")
            .unit("m", "m/s")
            .description("Position state"),
        State::new("vel")
            .unit("m/s", "m/s2")
            .description("Velocity state"),
    ];

    /// One second in steps of 1 ms.
    pub const DEFAULT_EXPERIMENT: DefaultExperiment = DefaultExperiment {
        start_time: 0.0,
        stop_time: 1.0,
        step_size: 1e-3,
    };
}

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
    /// The oscillator with the parameters of [`declare::MECHANICS`] from `p`,
    /// integrated exactly when `exact`; m must be > 0.
    pub fn with_parameters(p: &Parameters, exact: bool) -> Result<Self, String> {
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
            exact,
            transition: Cell::new(None),
        })
    }

    /// ẍ at position `x` and velocity `v` under the total force `f`.
    pub fn acceleration(&self, x: f64, v: f64, f: f64) -> f64 {
        (f - self.c * x - self.d * v) / self.m
    }

    /// [`Model::derivatives`] under the total force `f`.
    pub fn derivatives_under(&self, x: &[f64], f: f64, dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = self.acceleration(x[0], x[1], f);
    }

    /// [`Model::outputs`] (x, v, a) under the total force `f`.
    pub fn outputs_under(&self, x: &[f64], f: f64, y: &mut [f64]) {
        y.copy_from_slice(&[x[0], x[1], self.acceleration(x[0], x[1], f)]);
    }

    /// [`Model::output_derivatives`] (orders 1 and 2) under the total force `f`
    /// with its derivatives.
    pub fn output_derivatives_under(
        &self,
        x: &[f64],
        f: InputJet,
        order: u32,
        dy: &mut [f64],
    ) -> bool {
        let a = self.acceleration(x[0], x[1], f.value);
        let jerk = self.acceleration(x[1], a, f.d1);
        match order {
            1 => dy.copy_from_slice(&[x[1], a, jerk]),
            2 => dy.copy_from_slice(&[a, jerk, self.acceleration(a, jerk, f.d2)]),
            _ => return false,
        }
        true
    }

    /// [`Model::exact_step`] under the total force `f`: `false` (Dop853) unless
    /// `exact`.
    pub fn exact_step_under(&self, h: f64, x: &mut [f64], f: InputJet) -> bool {
        if !self.exact {
            return false;
        }
        let z = [x[0], x[1], f.value, f.d1, f.d2];
        let rows = self.transition(h);
        // Summed in column order, as nalgebra's matrix-vector product does.
        let dot = |row: &[f64; 5]| (1..5).fold(row[0] * z[0], |acc, j| acc + row[j] * z[j]);
        x.copy_from_slice(&[dot(&rows[0]), dot(&rows[1])]);
        true
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

/// The oscillator FMU: inputs F and F_ext, of which the model sees the sum.
impl Model for Oscillator {
    const DECLARATION: Declaration = Declaration {
        model_name: "oscillator",
        model_identifier: "oscillator",
        description: "Single mass on a spring and damper, driven by a force: m x'' = F - c x - d v",
        real_parameters: &declare::MECHANICS,
        boolean_parameters: &[declare::EXACT],
        inputs: &[
            declare::FORCE,
            Real::new("F_ext", 0.0)
                .unit("N")
                .description("Additional force on the mass (added to F)"),
        ],
        outputs: &[
            declare::POSITION_AND_VELOCITY[0],
            declare::POSITION_AND_VELOCITY[1],
            declare::acceleration(&["pos", "vel", "F", "F_ext"]),
        ],
        states: &declare::STATES,
        max_output_derivative_order: 2,
        default_experiment: declare::DEFAULT_EXPERIMENT,
        model_exchange: true,
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        Oscillator::with_parameters(p, p.boolean("exact")?)
    }

    fn initial_states(&self, x: &mut [f64]) {
        x.copy_from_slice(&[self.x0, self.v0]);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.derivatives_under(x, u[0] + u[1], dx);
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        self.outputs_under(x, u[0] + u[1], y);
    }

    fn output_derivatives(
        &self,
        _t: f64,
        x: &[f64],
        u: &[InputJet],
        order: u32,
        dy: &mut [f64],
    ) -> bool {
        self.output_derivatives_under(x, total(u), order, dy)
    }

    fn exact_step(&self, _t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        self.exact_step_under(h, x, total(u))
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
