//! PI position controller: u = kp·(r − y) + ki·z with ż = r − y.
//!
//! It declares `canGetAndSetFMUstate="false"` and `canInterpolateInputs="false"`,
//! as many tool-exported controllers do: a master cannot roll it back and holds
//! its input constant over a step. The integral state is advanced exactly for
//! such a held input (and for an input polynomial of degree ≤ 2), so the FMU
//! adds no integration error of its own.

use tether_fmu_kit::{
    export_fmu, Capabilities, Declaration, DefaultExperiment, InputJet, Model, Output, Parameters,
    Real, State,
};

pub struct Controller {
    kp: f64,
    ki: f64,
    r: f64,
}

impl Controller {
    fn command(&self, z: f64, y: f64) -> f64 {
        self.kp * (self.r - y) + self.ki * z
    }
}

impl Model for Controller {
    const DECLARATION: Declaration = Declaration {
        model_name: "controller",
        model_identifier: "controller",
        description: "PI controller u = kp (r - y) + ki z, z' = r - y, without FMU states",
        real_parameters: &[
            Real::new("kp", 1000.0)
                .unit("N/m")
                .description("Proportional gain"),
            Real::new("ki", 10000.0)
                .unit("N/(m.s)")
                .description("Integral gain"),
            Real::new("r", 0.1)
                .unit("m")
                .description("Set point of the measured position"),
        ],
        inputs: &[Real::new("y", 0.0)
            .unit("m")
            .description("Measured position")],
        outputs: &[Output::new("u")
            .unit("N")
            .description("Commanded force")
            .depends_on(&["z", "y"])],
        states: &[State::new("z")
            .unit("m.s", "m")
            .description("Integral of the control error r - y")],
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-3,
        },
        capabilities: Capabilities {
            can_get_and_set_fmu_state: false,
            can_interpolate_inputs: false,
        },
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        Ok(Controller {
            kp: p.real("kp")?,
            ki: p.real("ki")?,
            r: p.real("r")?,
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        x[0] = 0.0;
    }

    fn derivatives(&self, _t: f64, _x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = self.r - u[0];
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        y[0] = self.command(x[0], u[0]);
    }

    /// z(t + h) = z + ∫ (r − y) over the step, y a polynomial of degree ≤ 2.
    fn exact_step(&self, _t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        let y = u[0];
        x[0] += h * (self.r - y.value) - h * h / 2.0 * y.d1 - h * h * h / 6.0 * y.d2;
        true
    }
}

export_fmu!(Controller);
