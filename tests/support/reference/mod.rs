//! Monolithic reference solutions of the paper's mechanisms (EXAMPLES.md §2–3), written
//! from their own equations of motion: no master, no FMU code. Convergence tests
//! compare co-simulation columns with them.
//!
//! - [`double_pendulum`]: two links, the first pinned with a torsional spring-damper,
//!   in minimal coordinates (φ1, φ2).
//! - [`slider_crank`]: crank and rocker pinned to ground, the crank tip on the rocker's
//!   axis line, in the one coordinate φ1.
//!
//! Both are integrated with Dop853 (ode_solvers) at rtol = atol = [`TOLERANCE`]. Their
//! right-hand sides do not depend on time, so ode_solvers 0.6.2's wrong last-stage
//! time (see tether-fmu-kit's `integrate.rs`) does not matter here.

pub mod double_pendulum;
pub mod slider_crank;

#[cfg(test)]
mod double_pendulum_cartesian;
#[cfg(test)]
mod tests;

use ode_solvers::{Dop853, OutputType, SVector, System};

/// Relative and absolute tolerance of the reference integrations.
pub const TOLERANCE: f64 = 1e-12;

/// Gravity of both examples, acting in −y.
pub const G: f64 = 9.81;

struct Autonomous<F>(F);

impl<const N: usize, F: Fn(&[f64; N]) -> [f64; N]> System<f64, SVector<f64, N>> for Autonomous<F> {
    fn system(&self, _t: f64, y: &SVector<f64, N>, dy: &mut SVector<f64, N>) {
        let mut x = [0.0; N];
        x.copy_from_slice(y.as_slice());
        dy.as_mut_slice().copy_from_slice(&(self.0)(&x));
    }
}

/// Integrates ẏ = f(y) from y(0) = `y0` and returns y at each of `times` (sorted,
/// ≥ 0), restarting Dop853 at each requested time so every value is a step end.
///
/// # Panics
/// If `times` is not sorted and non-negative, or Dop853 fails.
pub fn integrate<const N: usize>(
    f: impl Fn(&[f64; N]) -> [f64; N] + Copy,
    y0: [f64; N],
    times: &[f64],
) -> Vec<[f64; N]> {
    let mut out = Vec::with_capacity(times.len());
    let (mut t, mut y) = (0.0, y0);
    for &t_next in times {
        assert!(
            t_next.is_finite() && t_next >= t,
            "reference times must be sorted and >= 0, got {t_next} after {t}"
        );
        if t_next > t {
            let mut solver = Dop853::new(
                Autonomous(f),
                t,
                t_next,
                t_next - t,
                SVector::<f64, N>::from(y),
                TOLERANCE,
                TOLERANCE,
            );
            solver.set_output(OutputType::Sparse);
            if let Err(e) = solver.integrate() {
                panic!("Dop853 failed between t = {t} and {t_next}: {e}");
            }
            let end = solver.y_out().last().expect("Dop853 returned no solution");
            y.copy_from_slice(end.as_slice());
            t = t_next;
        }
        out.push(y);
    }
    out
}

/// 2D cross product (z component of a × b).
pub(crate) fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Unit vector at angle φ from the x axis, and its normal (rotated by +90°).
pub(crate) fn axis_and_normal(phi: f64) -> ([f64; 2], [f64; 2]) {
    let (s, c) = phi.sin_cos();
    ([c, s], [-s, c])
}
