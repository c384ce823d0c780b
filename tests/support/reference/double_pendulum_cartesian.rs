//! A second, independent formulation of the double pendulum for the self-tests of
//! [`super::double_pendulum`]: both links as free bodies in Cartesian coordinates
//! q = (x1, y1, φ1, x2, y2, φ2) (centres of mass), held by four constraints
//! (link 1's end A at the origin, link 1's end B on link 2's end A) with Lagrange
//! multipliers and Baumgarte stabilization, M q̈ = f − Gᵀμ, G q̈ = γ − 2ξ ċ − ξ² c.

use nalgebra::{SMatrix, SVector};

use super::double_pendulum::{DoublePendulum, DoublePendulumState};
use super::{axis_and_normal, integrate};

/// Baumgarte rate ξ (1/s); the constraints start satisfied, so this only damps drift.
const XI: f64 = 20.0;

/// Accelerations q̈ (6) and multipliers μ (4: pivot x, y; joint x, y).
fn solve(p: &DoublePendulum, y: &[f64; 12]) -> ([f64; 6], [f64; 4]) {
    let (q, v) = (&y[..6], &y[6..]);
    let (e1, _) = axis_and_normal(q[2]);
    let (e2, _) = axis_and_normal(q[5]);
    let [l1, l2] = p.l;
    // Body points relative to the centres of mass, and their ∂/∂φ = k × ρ.
    let rho_1a = [-0.5 * l1 * e1[0], -0.5 * l1 * e1[1]];
    let rho_1b = [0.5 * l1 * e1[0], 0.5 * l1 * e1[1]];
    let rho_2a = [-0.5 * l2 * e2[0], -0.5 * l2 * e2[1]];
    let perp = |r: [f64; 2]| [-r[1], r[0]];
    let mut g = SMatrix::<f64, 4, 6>::zeros();
    let mut c = [0.0; 4];
    let mut c_dot = [0.0; 4];
    let mut gamma = [0.0; 4];
    for i in 0..2 {
        // Pivot: r1 + ρ1A = 0.
        g[(i, i)] = 1.0;
        g[(i, 2)] = perp(rho_1a)[i];
        c[i] = q[i] + rho_1a[i];
        c_dot[i] = v[i] + perp(rho_1a)[i] * v[2];
        gamma[i] = v[2] * v[2] * rho_1a[i];
        // Joint: (r1 + ρ1B) − (r2 + ρ2A) = 0.
        g[(2 + i, i)] = 1.0;
        g[(2 + i, 2)] = perp(rho_1b)[i];
        g[(2 + i, 3 + i)] = -1.0;
        g[(2 + i, 5)] = -perp(rho_2a)[i];
        c[2 + i] = q[i] + rho_1b[i] - q[3 + i] - rho_2a[i];
        c_dot[2 + i] = v[i] + perp(rho_1b)[i] * v[2] - v[3 + i] - perp(rho_2a)[i] * v[5];
        gamma[2 + i] = v[2] * v[2] * rho_1b[i] - v[5] * v[5] * rho_2a[i];
    }
    let mut kkt = SMatrix::<f64, 10, 10>::zeros();
    let mut rhs = SVector::<f64, 10>::zeros();
    let mass = [p.m[0], p.m[0], p.j[0], p.m[1], p.m[1], p.j[1]];
    for i in 0..6 {
        kkt[(i, i)] = mass[i];
    }
    kkt.view_mut((0, 6), (6, 4)).copy_from(&g.transpose());
    kkt.view_mut((6, 0), (4, 6)).copy_from(&g);
    rhs[1] = -p.m[0] * p.g;
    rhs[2] = -p.c_phi * (q[2] - p.phi_ref) - p.d_phi * v[2];
    rhs[4] = -p.m[1] * p.g;
    for i in 0..4 {
        rhs[6 + i] = gamma[i] - 2.0 * XI * c_dot[i] - XI * XI * c[i];
    }
    let x = kkt.lu().solve(&rhs).expect("regular KKT matrix");
    let mut acc = [0.0; 6];
    acc.copy_from_slice(&x.as_slice()[..6]);
    let mut mu = [0.0; 4];
    mu.copy_from_slice(&x.as_slice()[6..]);
    (acc, mu)
}

/// φ1, φ2, ω1, ω2 and the force on link 1 at B (−μ_joint) at `times`.
pub fn solve_cartesian(p: &DoublePendulum, times: &[f64]) -> Vec<DoublePendulumState> {
    let [l1, l2] = p.l;
    let (e1, n1) = axis_and_normal(p.phi0[0]);
    let (e2, n2) = axis_and_normal(p.phi0[1]);
    let [w1, w2] = p.omega0;
    let mut y0 = [0.0; 12];
    for i in 0..2 {
        y0[i] = 0.5 * l1 * e1[i];
        y0[3 + i] = l1 * e1[i] + 0.5 * l2 * e2[i];
        y0[6 + i] = 0.5 * l1 * w1 * n1[i];
        y0[9 + i] = l1 * w1 * n1[i] + 0.5 * l2 * w2 * n2[i];
    }
    y0[2] = p.phi0[0];
    y0[5] = p.phi0[1];
    y0[8] = w1;
    y0[11] = w2;
    let params = *p;
    let rhs = move |y: &[f64; 12]| {
        let (acc, _) = solve(&params, y);
        let mut dy = [0.0; 12];
        dy[..6].copy_from_slice(&y[6..]);
        dy[6..].copy_from_slice(&acc);
        dy
    };
    integrate(rhs, y0, times)
        .iter()
        .zip(times)
        .map(|(y, &t)| {
            let (acc, mu) = solve(p, y);
            let b1 = [y[0] + 0.5 * l1 * y[2].cos(), y[1] + 0.5 * l1 * y[2].sin()];
            DoublePendulumState {
                t,
                phi: [y[2], y[5]],
                omega: [y[8], y[11]],
                alpha: [acc[2], acc[5]],
                lambda: [-mu[2], -mu[3]],
                link1_a: [y[0] - 0.5 * l1 * y[2].cos(), y[1] - 0.5 * l1 * y[2].sin()],
                link1_b: b1,
                link2_b: [y[3] + 0.5 * l2 * y[5].cos(), y[4] + 0.5 * l2 * y[5].sin()],
                // Not needed by the comparison.
                link1_b_velocity: [f64::NAN; 2],
                link2_b_velocity: [f64::NAN; 2],
                link_energy: [f64::NAN; 2],
            }
        })
        .collect()
}
