//! Inputs as Taylor polynomials of degree ≤ 2 around the current communication point
//! (`canInterpolateInputs="true"`, `fmi2SetRealInputDerivatives`).

/// An input and its first two time derivatives at the FMU's current time t_c:
/// during `fmi2DoStep` the input is u(t) = value + d1·(t−t_c) + d2·(t−t_c)²/2.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InputJet {
    pub value: f64,
    pub d1: f64,
    pub d2: f64,
}

impl InputJet {
    /// A constant input: derivatives 0.
    pub fn constant(value: f64) -> Self {
        InputJet {
            value,
            d1: 0.0,
            d2: 0.0,
        }
    }

    /// u(t_c + dt).
    pub fn eval(&self, dt: f64) -> f64 {
        self.value + dt * (self.d1 + 0.5 * dt * self.d2)
    }

    /// The same polynomial expanded around t_c + dt (value and derivatives there).
    pub fn shifted(&self, dt: f64) -> Self {
        InputJet {
            value: self.eval(dt),
            d1: self.d1 + dt * self.d2,
            d2: self.d2,
        }
    }

    /// The `order`-th derivative at t_c (order 0 is the value).
    pub fn derivative(&self, order: u32) -> f64 {
        match order {
            0 => self.value,
            1 => self.d1,
            2 => self.d2,
            _ => 0.0,
        }
    }
}

/// Evaluates every input at t_c + dt into `out`.
pub fn eval_all(jets: &[InputJet], dt: f64, out: &mut [f64]) {
    for (o, jet) in out.iter_mut().zip(jets) {
        *o = jet.eval(dt);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taylor_polynomial_matches_the_quadratic_it_was_built_from() {
        // u(t) = 1 + 2 (t - 3) - 0.5 (t - 3)^2 around t_c = 3.
        let jet = InputJet {
            value: 1.0,
            d1: 2.0,
            d2: -1.0,
        };
        for dt in [0.0, 0.1, 0.5, 2.0] {
            assert!((jet.eval(dt) - (1.0 + 2.0 * dt - 0.5 * dt * dt)).abs() < 1e-15);
        }
    }

    #[test]
    fn shifting_keeps_the_same_polynomial() {
        let jet = InputJet {
            value: -0.3,
            d1: 4.0,
            d2: 7.0,
        };
        let moved = jet.shifted(0.25);
        for s in [0.0, 0.1, 1.0] {
            assert!((moved.eval(s) - jet.eval(0.25 + s)).abs() < 1e-13);
        }
        assert_eq!(moved.derivative(2), 7.0);
        assert!((moved.derivative(1) - (4.0 + 0.25 * 7.0)).abs() < 1e-15);
    }

    #[test]
    fn constant_input_has_zero_derivatives() {
        let jet = InputJet::constant(5.0);
        assert_eq!(jet.eval(10.0), 5.0);
        assert_eq!(jet.derivative(1), 0.0);
        assert_eq!(jet.derivative(3), 0.0);
    }
}
