//! Dormand–Prince 5(4) (`rk45`) with Hairer's error control (DOPRI5: the
//! initial step guess, the PI step-size controller with β = 0.04, safety 0.9,
//! step ratios within [0.2, 10], stiffness detection every 1000 accepted
//! steps), in buffers kept between calls, so that an integration allocates
//! nothing once the buffers have the states' length.
//!
//! The `ode_solvers` crate implements the same method, but every call builds
//! its solver and stage vectors anew and every stage allocates nalgebra
//! temporaries: over a communication step of a small model that costs more
//! than the model's right-hand side (see docs/fmi-import.md, "Cost").

/// The right-hand side and what is checked after every accepted step.
pub(crate) trait Problem {
    /// dy = f(tau, y); false when it failed (the problem keeps the error).
    fn rhs(&mut self, tau: f64, y: &[f64], dy: &mut [f64]) -> bool;
    /// Called after every accepted step; true stops the integration there.
    fn accepted(&mut self, tau: f64, y: &[f64]) -> bool;
}

/// Why an integration stopped short of its end without the problem asking.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Failure {
    /// The right-hand side failed at `tau` (the problem has the error).
    Rhs { tau: f64 },
    /// More than `n_step` steps.
    MaxSteps { tau: f64, n_step: u32 },
    /// The step size fell below the resolution of time.
    Underflow { tau: f64 },
    /// The stiffness test failed 15 times in a row.
    Stiff { tau: f64 },
}

/// The settings of one integration.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Options {
    pub rtol: f64,
    pub atol: f64,
    pub h_max: f64,
    pub n_max: u32,
}

// The Dormand–Prince 5(4) tableau (Hairer, Nørsett, Wanner, I, table 5.2).
const C: [f64; 7] = [0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0];
const A: [[f64; 6]; 7] = [
    [0.0; 6],
    [0.2, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];
/// The fifth-order solution minus the fourth-order one.
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

const SAFETY: f64 = 0.9;
const BETA: f64 = 0.04;
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 10.0;
const STIFF_EVERY: u32 = 1000;

/// The buffers of the method: the seven stages, the state, the next state.
#[derive(Debug, Default)]
pub(crate) struct Dopri5 {
    k: [Vec<f64>; 7],
    y: Vec<f64>,
    y_next: Vec<f64>,
    y_stiff: Vec<f64>,
}

impl Dopri5 {
    pub(crate) fn resize(&mut self, n: usize) {
        for v in self
            .k
            .iter_mut()
            .chain([&mut self.y, &mut self.y_next, &mut self.y_stiff])
        {
            v.resize(n, 0.0);
        }
    }

    /// Integrates from (tau0, y0) towards tau1 until the end or until
    /// `accepted` stops it: the time reached, the state there in `y_out`.
    pub(crate) fn integrate(
        &mut self,
        p: &mut dyn Problem,
        o: &Options,
        tau0: f64,
        tau1: f64,
        y0: &[f64],
        y_out: &mut Vec<f64>,
    ) -> Result<f64, Failure> {
        let n = y0.len();
        self.resize(n);
        self.y.copy_from_slice(y0);
        let mut tau = tau0;
        if !p.rhs(tau, &self.y, &mut self.k[0]) {
            return Err(Failure::Rhs { tau });
        }
        let mut h = self.initial_step(p, o, tau, tau1)?;
        let mut fac_old = 1e-4_f64;
        let mut reject = false;
        let mut accepted = 0u32;
        let (mut stiff, mut non_stiff) = (0u32, 0u32);
        let mut n_step = 0u32;
        let mut last = false;
        let done = loop {
            if n_step > o.n_max {
                return Err(Failure::MaxSteps { tau, n_step });
            }
            if 0.1 * h.abs() <= f64::EPSILON * tau.abs() {
                return Err(Failure::Underflow { tau });
            }
            if tau + 1.01 * h - tau1 > 0.0 {
                h = tau1 - tau;
                last = true;
            }
            n_step += 1;
            // The stages 2…7 (the seventh is f at the new point).
            for s in 1..7 {
                let (done, rest) = self.k.split_at_mut(s);
                for i in 0..n {
                    let mut sum = 0.0;
                    for (j, kj) in done.iter().enumerate() {
                        sum += A[s][j] * kj[i];
                    }
                    self.y_next[i] = self.y[i] + h * sum;
                }
                if s == 5 {
                    self.y_stiff.copy_from_slice(&self.y_next);
                }
                if !p.rhs(tau + C[s] * h, &self.y_next, &mut rest[0]) {
                    return Err(Failure::Rhs {
                        tau: tau + C[s] * h,
                    });
                }
            }
            // The error of the step, scaled per state.
            let mut err = 0.0;
            for i in 0..n {
                let mut e = 0.0;
                for (j, kj) in self.k.iter().enumerate() {
                    e += E[j] * kj[i];
                }
                let sc = o.atol + self.y[i].abs().max(self.y_next[i].abs()) * o.rtol;
                err += (h * e / sc).powi(2);
            }
            let err = if n == 0 { 0.0 } else { (err / n as f64).sqrt() };
            // The PI controller.
            let fac11 = err.powf(0.2 - BETA * 0.75);
            let fac =
                (1.0 / FAC_MAX).max((1.0 / FAC_MIN).min(fac11 * fac_old.powf(-BETA) / SAFETY));
            let mut h_new = h / fac;
            if err <= 1.0 {
                fac_old = err.max(1e-4);
                h_new = h_new.min(o.h_max);
                if reject {
                    h_new = h_new.min(h);
                }
                reject = false;
                accepted += 1;
                if accepted.is_multiple_of(STIFF_EVERY) || stiff > 0 {
                    let (mut num, mut den) = (0.0, 0.0);
                    for i in 0..n {
                        num += (self.k[6][i] - self.k[5][i]).powi(2);
                        den += (self.y_next[i] - self.y_stiff[i]).powi(2);
                    }
                    let h_lamb = if den > 0.0 {
                        h * (num / den).sqrt()
                    } else {
                        0.0
                    };
                    if h_lamb > 3.25 {
                        non_stiff = 0;
                        stiff += 1;
                        if stiff == 15 {
                            return Err(Failure::Stiff { tau });
                        }
                    } else {
                        non_stiff += 1;
                        if non_stiff == 6 {
                            stiff = 0;
                        }
                    }
                }
                // First same as last: the seventh stage is the next first.
                self.k.swap(0, 6);
                std::mem::swap(&mut self.y, &mut self.y_next);
                tau += h;
                if p.accepted(tau, &self.y) || last {
                    break tau;
                }
            } else {
                h_new = h / (1.0 / FAC_MIN).min(fac11 / SAFETY);
                reject = true;
                last = false;
            }
            h = h_new;
        };
        y_out.clear();
        y_out.extend_from_slice(&self.y);
        Ok(done)
    }

    /// Hairer's initial step from f0 = `k[0]` and one explicit Euler probe
    /// (in `y_next`, `k[1]`).
    fn initial_step(
        &mut self,
        p: &mut dyn Problem,
        o: &Options,
        tau: f64,
        tau1: f64,
    ) -> Result<f64, Failure> {
        let n = self.y.len();
        let (mut d0, mut d1) = (0.0, 0.0);
        for i in 0..n {
            let sc = o.atol + self.y[i].abs() * o.rtol;
            d0 += (self.y[i] / sc).powi(2);
            d1 += (self.k[0][i] / sc).powi(2);
        }
        let h_max = o.h_max.min(tau1 - tau);
        let h0 = if d0 < 1e-10 || d1 < 1e-10 {
            1e-6
        } else {
            0.01 * (d0 / d1).sqrt()
        }
        .min(h_max);
        for i in 0..n {
            self.y_next[i] = self.y[i] + h0 * self.k[0][i];
        }
        let (head, tail) = self.k.split_at_mut(1);
        if !p.rhs(tau + h0, &self.y_next, &mut tail[0]) {
            return Err(Failure::Rhs { tau: tau + h0 });
        }
        let mut d2 = 0.0;
        for i in 0..n {
            let sc = o.atol + self.y[i].abs() * o.rtol;
            d2 += ((tail[0][i] - head[0][i]) / sc).powi(2);
        }
        let d2 = d2.sqrt() / h0;
        let d1 = d1.sqrt();
        let h1 = if d1.max(d2) <= 1e-15 {
            1e-6_f64.max(h0 * 1e-3)
        } else {
            (0.01 / d1.max(d2)).powf(0.2)
        };
        Ok((100.0 * h0).min(h1).min(h_max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y' = −y and the harmonic oscillator, against their closed forms.
    struct Linear {
        evals: u32,
        oscillator: bool,
    }

    impl Problem for Linear {
        fn rhs(&mut self, _tau: f64, y: &[f64], dy: &mut [f64]) -> bool {
            self.evals += 1;
            if self.oscillator {
                dy[0] = y[1];
                dy[1] = -y[0];
            } else {
                dy[0] = -y[0];
            }
            true
        }
        fn accepted(&mut self, _tau: f64, _y: &[f64]) -> bool {
            false
        }
    }

    fn options(tol: f64) -> Options {
        Options {
            rtol: tol,
            atol: tol,
            h_max: f64::INFINITY,
            n_max: 100_000,
        }
    }

    #[test]
    fn follows_the_closed_forms_within_the_tolerance() {
        let mut m = Dopri5::default();
        let mut y = Vec::new();
        for tol in [1e-6, 1e-10] {
            let mut p = Linear {
                evals: 0,
                oscillator: false,
            };
            let t = m.integrate(&mut p, &options(tol), 0.0, 2.0, &[1.0], &mut y);
            assert_eq!(t, Ok(2.0));
            assert!((y[0] - (-2.0f64).exp()).abs() < 10.0 * tol, "{tol}: {y:?}");
            let mut p = Linear {
                evals: 0,
                oscillator: true,
            };
            m.integrate(&mut p, &options(tol), 0.0, 10.0, &[1.0, 0.0], &mut y)
                .unwrap();
            assert!((y[0] - 10.0f64.cos()).abs() < 100.0 * tol, "{tol}: {y:?}");
            assert!((y[1] + 10.0f64.sin()).abs() < 100.0 * tol, "{tol}: {y:?}");
        }
    }

    #[test]
    fn the_error_falls_with_the_fifth_power_of_the_step() {
        // Fixed steps (h_max, a loose tolerance): halving h divides the
        // error of the oscillator by about 2^5.
        let mut m = Dopri5::default();
        let mut y = Vec::new();
        let mut errors = Vec::new();
        for h in [0.1, 0.05] {
            let o = Options {
                rtol: 1.0,
                atol: 1.0,
                h_max: h,
                n_max: 100_000,
            };
            let mut p = Linear {
                evals: 0,
                oscillator: true,
            };
            m.integrate(&mut p, &o, 0.0, 1.0, &[1.0, 0.0], &mut y)
                .unwrap();
            errors.push((y[0] - 1.0f64.cos()).abs());
        }
        let order = (errors[0] / errors[1]).log2();
        assert!((4.7..5.5).contains(&order), "{errors:?}: order {order}");
    }

    #[test]
    fn a_repeated_integration_gives_the_same_bits() {
        let mut m = Dopri5::default();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let mut p = Linear {
            evals: 0,
            oscillator: true,
        };
        m.integrate(&mut p, &options(1e-8), 0.5, 1.7, &[0.3, 0.2], &mut a)
            .unwrap();
        m.integrate(&mut p, &options(1e-8), 0.0, 3.0, &[1.0, 0.0], &mut b)
            .unwrap();
        m.integrate(&mut p, &options(1e-8), 0.5, 1.7, &[0.3, 0.2], &mut b)
            .unwrap();
        assert_eq!(a, b);
    }
}
