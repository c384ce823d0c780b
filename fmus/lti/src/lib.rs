//! First-order linear block with two inputs and direct feedthrough:
//! ẋ = a x + b1 u1 + b2 u2, y = c x + d1 u1 + d2 u2.
//!
//! One FMU for the three parts of a control loop: a source (no inputs
//! connected: y = c x0 e^{a t}), a PI controller (u1 the set point, u2 the
//! measurement: b1 = 1, b2 = −1, c = ki, d1 = kp, d2 = −kp) and a plant whose
//! output passes part of its input straight through (d1 ≠ 0). It declares
//! `canGetAndSetFMUstate` and `canInterpolateInputs`, and a step is exact
//! for inputs of degree ≤ 2 (the φ-functions of a h), so the FMU adds no
//! integration error of its own.

use tether_fmu_kit::{
    export_fmu, Capabilities, Declaration, DefaultExperiment, InputJet, Model, Output, Parameters,
    Real, State,
};

pub struct Lti {
    a: f64,
    b: [f64; 2],
    c: f64,
    d: [f64; 2],
    x0: f64,
}

/// φ_k(z) = Σ_{j≥0} z^j / (j + k)!, for k = 0 … 3: ∫_0^h e^{a(h−s)} s^{k−1}/(k−1)! ds
/// = h^k φ_k(a h).
fn phi(z: f64) -> [f64; 4] {
    let e = z.exp();
    if z.abs() > 0.5 {
        let p1 = (e - 1.0) / z;
        let p2 = (p1 - 1.0) / z;
        let p3 = (p2 - 0.5) / z;
        return [e, p1, p2, p3];
    }
    // Series: accurate where the differences above cancel.
    let mut out = [e, 0.0, 0.0, 0.0];
    for (k, p) in out.iter_mut().enumerate().skip(1) {
        let mut term = 1.0;
        for i in 1..=k {
            term /= i as f64;
        }
        let mut sum = 0.0;
        for j in 0..30 {
            sum += term;
            term *= z / (j + k + 1) as f64;
        }
        *p = sum;
    }
    out
}

impl Model for Lti {
    const DECLARATION: Declaration = Declaration {
        model_name: "lti",
        model_identifier: "lti",
        description: "First-order linear block x' = a x + b1 u1 + b2 u2, y = c x + d1 u1 + d2 u2",
        real_parameters: &[
            Real::new("a", -1.0).description("State coefficient"),
            Real::new("b1", 1.0).description("Input coefficient of u1 in x'"),
            Real::new("b2", 0.0).description("Input coefficient of u2 in x'"),
            Real::new("c", 1.0).description("Output coefficient of x"),
            Real::new("d1", 0.0).description("Direct feedthrough of u1"),
            Real::new("d2", 0.0).description("Direct feedthrough of u2"),
            Real::new("x0", 0.0).description("Initial state"),
        ],
        inputs: &[
            Real::new("u1", 0.0).description("First input"),
            Real::new("u2", 0.0).description("Second input"),
        ],
        outputs: &[Output::new("y")
            .description("c x + d1 u1 + d2 u2")
            .depends_on(&["x", "u1", "u2"])],
        states: &[State::new("x").description("The state")],
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-3,
        },
        capabilities: Capabilities::ALL,
        model_exchange: true,
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        Ok(Lti {
            a: p.real("a")?,
            b: [p.real("b1")?, p.real("b2")?],
            c: p.real("c")?,
            d: [p.real("d1")?, p.real("d2")?],
            x0: p.real("x0")?,
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        x[0] = self.x0;
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = self.a * x[0] + self.b[0] * u[0] + self.b[1] * u[1];
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        y[0] = self.c * x[0] + self.d[0] * u[0] + self.d[1] * u[1];
    }

    /// x(t + h) = e^{ah} x + Σ_k h^{k+1} φ_{k+1}(ah) f^{(k)}, f = b·u a
    /// polynomial of degree ≤ 2.
    fn exact_step(&self, _t: f64, h: f64, x: &mut [f64], u: &[InputJet]) -> bool {
        let f = |g: fn(&InputJet) -> f64| self.b[0] * g(&u[0]) + self.b[1] * g(&u[1]);
        let p = phi(self.a * h);
        x[0] = p[0] * x[0]
            + h * p[1] * f(|j| j.value)
            + h * h * p[2] * f(|j| j.d1)
            + h * h * h * p[3] * f(|j| j.d2);
        true
    }
}

export_fmu!(Lti);

#[cfg(test)]
mod tests {
    use super::phi;

    /// The series and the closed forms agree where both are accurate.
    #[test]
    fn phi_series_meets_the_closed_form() {
        for z in [-0.49, 0.3, 0.5] {
            let e = f64::exp(z);
            let closed = [
                e,
                (e - 1.0) / z,
                (e - 1.0 - z) / (z * z),
                (e - 1.0 - z - z * z / 2.0) / (z * z * z),
            ];
            let series = phi(z);
            for k in 0..4 {
                assert!(
                    (series[k] - closed[k]).abs() < 1e-13,
                    "z {z} k {k}: {series:?} {closed:?}"
                );
            }
        }
    }
}
