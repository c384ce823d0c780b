//! Coupling polynomials (paper Sect. 3.3, eqs. 56 and 59) on the uniform macro
//! grid, and on a variable one (adaptive macro steps: Lagrange polynomials through
//! the actual past points, [`extrapolate`] and [`interpolate`]).
//!
//! FMI 2.0 passes a polynomial input as its Taylor expansion at the start of the
//! step, `u(T_N + τ) = u₀ + u₁ τ + u₂ τ²/2`, through `fmi2SetReal` (u₀) and
//! `fmi2SetRealInputDerivatives` (u₁, u₂). A Lagrange polynomial of degree ≤ 2
//! equals its Taylor polynomial, so the mapping below is exact.

/// Taylor coefficients at the step start `T_N`: value, first and second derivative.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Taylor {
    /// u(T_N)
    pub value: f64,
    /// du/dt at T_N
    pub d1: f64,
    /// d²u/dt² at T_N
    pub d2: f64,
}

impl Taylor {
    /// The polynomial's value `τ` after the step start.
    pub fn at(&self, tau: f64) -> f64 {
        self.value + tau * (self.d1 + 0.5 * tau * self.d2)
    }
}

/// Predictor (extrapolation) polynomial of degree `degree` through
/// `(T_N, u_N), (T_{N-1}, u_{N-1}), …` — `history[0]` is u_N, `history[1]` is
/// u_{N-1}, and so on (eq. 56).
pub fn extrapolation(history: &[f64], degree: usize, h: f64) -> Taylor {
    match degree {
        0 => Taylor {
            value: history[0],
            ..Taylor::default()
        },
        1 => Taylor {
            value: history[0],
            d1: (history[0] - history[1]) / h,
            d2: 0.0,
        },
        _ => Taylor {
            value: history[0],
            d1: (3.0 * history[0] - 4.0 * history[1] + history[2]) / (2.0 * h),
            d2: (history[0] - 2.0 * history[1] + history[2]) / (h * h),
        },
    }
}

/// Perturbed-predictor and corrector (interpolation) polynomial of degree
/// `degree` through `(T_{N+1}, u_new), (T_N, u_N), (T_{N-1}, u_{N-1}), …`
/// (eq. 59 and the corrector step). Degree 0 is the constant `u_new`.
pub fn interpolation(u_new: f64, history: &[f64], degree: usize, h: f64) -> Taylor {
    match degree {
        0 => Taylor {
            value: u_new,
            ..Taylor::default()
        },
        1 => Taylor {
            value: history[0],
            d1: (u_new - history[0]) / h,
            d2: 0.0,
        },
        _ => Taylor {
            value: history[0],
            d1: (u_new - history[1]) / (2.0 * h),
            d2: (u_new - 2.0 * history[0] + history[1]) / (h * h),
        },
    }
}

/// The step sizes before the current step, `[T_N − T_{N−1}, T_{N−1} − T_{N−2}]`,
/// on a variable grid; `None` on the uniform grid, where every step is H.
pub type Past = Option<[f64; 2]>;

/// The predictor polynomial: [`extrapolation`] on the uniform grid, else the
/// Lagrange polynomial through the actual points `T_N, T_N − past[0],
/// T_N − past[0] − past[1]` (Newton's divided differences).
pub fn extrapolate(history: &[f64], degree: usize, h: f64, past: Past) -> Taylor {
    match (past, degree) {
        (Some([h1, _]), 1) => Taylor {
            value: history[0],
            d1: (history[0] - history[1]) / h1,
            d2: 0.0,
        },
        (Some([h1, h2]), 2..) => {
            // p(τ) = u_N + f[N, N−1] τ + f[N, N−1, N−2] τ (τ + h1).
            let f01 = (history[0] - history[1]) / h1;
            let f12 = (history[1] - history[2]) / h2;
            let f012 = (f01 - f12) / (h1 + h2);
            Taylor {
                value: history[0],
                d1: f01 + f012 * h1,
                d2: 2.0 * f012,
            }
        }
        _ => extrapolation(history, degree, h),
    }
}

/// The interpolation polynomial: [`interpolation`] on the uniform grid, else
/// the Lagrange polynomial through `(T_N + h, u_new), (T_N, u_N), (T_N −
/// past[0], u_{N−1})` (degrees 0 and 1 do not depend on the past steps).
pub fn interpolate(u_new: f64, history: &[f64], degree: usize, h: f64, past: Past) -> Taylor {
    match (past, degree) {
        (Some([h1, _]), 2..) => {
            // p(τ) = u_N + f[N, N−1] τ + f[N+1, N, N−1] τ (τ + h1).
            let f01 = (history[0] - history[1]) / h1;
            let fn0 = (u_new - history[0]) / h;
            let f012 = (fn0 - f01) / (h + h1);
            Taylor {
                value: history[0],
                d1: f01 + f012 * h1,
                d2: 2.0 * f012,
            }
        }
        _ => interpolation(u_new, history, degree, h),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quadratic sampled on the grid is reproduced exactly by both forms.
    #[test]
    fn quadratics_are_reproduced_exactly() {
        let h = 0.1;
        let p = |t: f64| 3.0 - 2.0 * t + 5.0 * t * t;
        let tn = 1.0;
        let hist = [p(tn), p(tn - h), p(tn - 2.0 * h)];
        let e = extrapolation(&hist, 2, h);
        let i = interpolation(p(tn + h), &hist, 2, h);
        for tau in [0.0, 0.05, 0.1] {
            assert!((e.at(tau) - p(tn + tau)).abs() < 1e-12);
            assert!((i.at(tau) - p(tn + tau)).abs() < 1e-12);
        }
    }

    #[test]
    fn interpolation_passes_through_the_new_point() {
        let hist = [1.0, 0.5, 0.0];
        for degree in 0..=2 {
            let i = interpolation(7.0, &hist, degree, 0.2);
            assert!((i.at(0.2) - 7.0).abs() < 1e-12, "degree {degree}");
        }
    }

    /// With the predicted value as the new point, the interpolation polynomial
    /// is the predictor polynomial: an unperturbed re-run reproduces the predictor.
    #[test]
    fn interpolation_through_the_prediction_is_the_predictor() {
        let h = 0.01;
        let hist = [2.0, 1.7, 1.1];
        for degree in 0..=2 {
            let e = extrapolation(&hist, degree, h);
            let i = interpolation(e.at(h), &hist, degree.clamp(1, 2), h);
            if degree > 0 {
                assert!((e.d1 - i.d1).abs() < 1e-9 && (e.d2 - i.d2).abs() < 1e-6);
            }
            assert!((e.at(0.5 * h) - i.at(0.5 * h)).abs() < 1e-12);
        }
    }

    /// The general formulas on a uniform grid equal the uniform tables (to
    /// rounding: they are other expressions of the same polynomial).
    #[test]
    fn variable_grid_formulas_on_a_uniform_grid_equal_the_tables() {
        let h = 0.01;
        let hist = [2.0, 1.7, 1.1];
        for degree in 0..=2 {
            let (a, b) = (
                extrapolation(&hist, degree, h),
                extrapolate(&hist, degree, h, Some([h, h])),
            );
            let (c, d) = (
                interpolation(2.4, &hist, degree, h),
                interpolate(2.4, &hist, degree, h, Some([h, h])),
            );
            for (x, y) in [(a, b), (c, d)] {
                assert!((x.value - y.value).abs() <= 1e-15 * x.value.abs());
                assert!(
                    (x.d1 - y.d1).abs() <= 1e-12 * x.d1.abs().max(1.0),
                    "{x:?} {y:?}"
                );
                assert!(
                    (x.d2 - y.d2).abs() <= 1e-12 * x.d2.abs().max(1.0),
                    "{x:?} {y:?}"
                );
            }
            // Without a past the tables themselves are used, bit for bit.
            assert_eq!(extrapolate(&hist, degree, h, None), a);
            assert_eq!(interpolate(2.4, &hist, degree, h, None), c);
        }
    }

    /// On a non-uniform grid a quadratic is reproduced exactly.
    #[test]
    fn quadratics_are_reproduced_on_a_variable_grid() {
        let p = |t: f64| 3.0 - 2.0 * t + 5.0 * t * t;
        let (tn, h1, h2, h) = (1.0, 0.03, 0.07, 0.02);
        let hist = [p(tn), p(tn - h1), p(tn - h1 - h2)];
        let e = extrapolate(&hist, 2, h, Some([h1, h2]));
        let i = interpolate(p(tn + h), &hist, 2, h, Some([h1, h2]));
        for tau in [0.0, 0.01, 0.02] {
            assert!((e.at(tau) - p(tn + tau)).abs() < 1e-12);
            assert!((i.at(tau) - p(tn + tau)).abs() < 1e-12);
        }
        // A line through unequal points, degree 1.
        let l = |t: f64| 1.0 + 4.0 * t;
        let hist = [l(tn), l(tn - h1), 0.0];
        let e = extrapolate(&hist, 1, h, Some([h1, h2]));
        assert!((e.at(h) - l(tn + h)).abs() < 1e-12);
    }
}
