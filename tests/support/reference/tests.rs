//! Self-tests of the references: two formulations of the double pendulum agree, its
//! energy balance closes, and the slider-crank keeps its energy and its joint.

use super::double_pendulum::{self, DoublePendulumState};
use super::double_pendulum_cartesian::solve_cartesian;
use super::slider_crank::{self, SliderCrankState};
use super::{axis_and_normal, cross, integrate};

fn grid(stop: f64, step: f64) -> Vec<f64> {
    let n = (stop / step).round() as usize;
    (0..=n).map(|k| k as f64 * step).collect()
}

#[test]
fn double_pendulum_minimal_and_cartesian_coordinates_agree_to_1e_8() {
    let times = grid(2.0, 0.05);
    let minimal = double_pendulum::reference(&times);
    let cartesian = solve_cartesian(&double_pendulum::PAPER, &times);
    let mut worst = [0.0f64; 4];
    for (a, b) in minimal.iter().zip(&cartesian) {
        let diff = |x: [f64; 2], y: [f64; 2]| (x[0] - y[0]).abs().max((x[1] - y[1]).abs());
        worst[0] = worst[0].max(diff(a.phi, b.phi));
        worst[1] = worst[1].max(diff(a.omega, b.omega));
        worst[2] = worst[2].max(diff(a.lambda, b.lambda));
        worst[3] = worst[3].max(diff(a.link2_b, b.link2_b).max(diff(a.link1_b, b.link1_b)));
    }
    eprintln!(
        "double pendulum, minimal vs Cartesian: |Δφ| {:e}, |Δω| {:e}, |Δλ| {:e}, |Δr| {:e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(
        worst[0] < 1e-8 && worst[1] < 1e-8 && worst[3] < 1e-8,
        "{worst:?}"
    );
    // λ is O(10 N).
    assert!(worst[2] < 1e-7, "{worst:?}");
    // Something happens: the pendulum swings and the joint carries load.
    let last = minimal.last().unwrap();
    assert!((last.phi[1] - minimal[0].phi[1]).abs() > 0.1, "{last:?}");
    assert!(minimal.iter().any(|s| s.lambda[1].abs() > 5.0));
}

#[test]
fn double_pendulum_energy_plus_damper_dissipation_is_constant() {
    // Integrate D = ∫ d_φ φ̇1² dt along: E(t) + D(t) = E(0).
    let p = double_pendulum::PAPER;
    let rhs = move |y: &[f64; 5]| {
        let alpha = p.accelerations(&[y[0], y[1], y[2], y[3]]);
        [y[2], y[3], alpha[0], alpha[1], p.d_phi * y[2] * y[2]]
    };
    let times = grid(2.0, 0.1);
    let y0 = [p.phi0[0], p.phi0[1], p.omega0[0], p.omega0[1], 0.0];
    let e0 = p.state_at(0.0, &[y0[0], y0[1], y0[2], y0[3]]).energy();
    let mut worst = 0.0f64;
    for (y, &t) in integrate(rhs, y0, &times).iter().zip(&times) {
        let e = p.state_at(t, &[y[0], y[1], y[2], y[3]]).energy();
        worst = worst.max((e + y[4] - e0).abs() / e0.abs());
    }
    eprintln!("double pendulum: relative energy-balance error {worst:e}");
    assert!(worst < 1e-9, "{worst:e}");
}

#[test]
fn double_pendulum_columns_name_the_markers_of_the_example() {
    let s: DoublePendulumState = double_pendulum::reference(&[0.3])[0];
    assert_eq!(s.column("link2.A.r[1]"), s.column("link1.B.r[1]"));
    assert_eq!(s.column("link1.B.r[2]"), Some(s.link1_b[1]));
    assert_eq!(s.column("link2.B.v[1]"), Some(s.link2_b_velocity[0]));
    assert_eq!(s.column("link1.A.r[1]"), Some(0.0));
    assert_eq!(s.column("link2.phi"), Some(s.phi[1]));
    assert_eq!(s.column("link1.E"), Some(s.link_energy[0]));
    assert_eq!(s.column("link2.B.r[3]"), Some(0.0));
    assert_eq!(s.column("link3.phi"), None);
    assert_eq!(s.column("link1.C.r[1]"), None);
    // Link 2's end B is l2 from link 1's end B along φ2.
    let (e2, _) = axis_and_normal(s.phi[1]);
    assert!((s.link2_b[0] - s.link1_b[0] - e2[0]).abs() < 1e-15);
    // At t = 0 the links are where EXAMPLES.md §2 puts them, at rest.
    let s0 = double_pendulum::reference(&[0.0])[0];
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!((s0.link1_b[0] - h).abs() < 1e-15 && (s0.link2_b[0] - 2.0 * h).abs() < 1e-15);
    assert!(s0.link2_b[1].abs() < 1e-15 && s0.omega == [0.0, 0.0]);
}

#[test]
#[should_panic(expected = "sorted")]
fn reference_times_must_be_sorted() {
    double_pendulum::reference(&[0.2, 0.1]);
}

fn slider_crank_run() -> Vec<SliderCrankState> {
    slider_crank::reference(&grid(2.0, 0.01))
}

#[test]
fn slider_crank_energy_is_constant_to_1e_10() {
    let states = slider_crank_run();
    let e0 = states[0].energy();
    let worst = states
        .iter()
        .map(|s| (s.energy() - e0).abs() / e0.abs())
        .fold(0.0, f64::max);
    eprintln!("slider-crank: relative energy drift {worst:e} over 2 s");
    assert!(worst < 1e-10, "{worst:e}");
    // It moves: the crank falls through a good part of a turn.
    let swing = states
        .iter()
        .map(|s| (s.phi[0] - states[0].phi[0]).abs())
        .fold(0.0, f64::max);
    assert!(swing > 1.0, "{swing}");
}

#[test]
fn slider_crank_keeps_the_crank_tip_on_the_rocker_axis() {
    for s in slider_crank_run() {
        let (e2, n2) = axis_and_normal(s.phi[1]);
        let u = [
            s.crank_tip[0] - s.rocker_pivot[0],
            s.crank_tip[1] - s.rocker_pivot[1],
        ];
        // Position, velocity (tip velocity ⊥ n2 after removing the rocker's rotation).
        assert!((u[0] * n2[0] + u[1] * n2[1]).abs() < 1e-14, "{s:?}");
        assert!(
            (u[0] * e2[0] + u[1] * e2[1] - s.slide).abs() < 1e-14,
            "{s:?}"
        );
        let w_u = [-s.omega[1] * u[1], s.omega[1] * u[0]];
        let rel = [
            s.crank_tip_velocity[0] - w_u[0],
            s.crank_tip_velocity[1] - w_u[1],
        ];
        assert!((rel[0] * n2[0] + rel[1] * n2[1]).abs() < 1e-12, "{s:?}");
    }
    let s0 = slider_crank::reference(&[0.0])[0];
    assert!((s0.crank_tip[0] - 1.0).abs() < 1e-15 && (s0.crank_tip[1] - 1.0).abs() < 1e-15);
    assert!((s0.phi[1] - 3.0 * std::f64::consts::FRAC_PI_4).abs() < 1e-15);
}

#[test]
fn slider_crank_multiplier_balances_the_crank_too() {
    // λ comes from the rocker's moment balance; the crank's must hold with it:
    // J1 φ̈1 = −m1 g (l1/2) cos φ1 + (P × λ n2), J1 about the pivot.
    let p = slider_crank::PAPER;
    let j1 = p.j[0] + p.m[0] * p.l[0] * p.l[0] / 4.0;
    let mut worst = 0.0f64;
    for s in slider_crank_run() {
        let (_, n2) = axis_and_normal(s.phi[1]);
        let moment = -p.m[0] * p.g * 0.5 * p.l[0] * s.phi[0].cos()
            + cross(s.crank_tip, [s.lambda * n2[0], s.lambda * n2[1]]);
        worst = worst.max((j1 * s.alpha[0] - moment).abs());
    }
    assert!(worst < 1e-10, "{worst:e}");
}

#[test]
fn slider_crank_columns_name_the_markers_of_the_example() {
    let s = slider_crank::reference(&[0.4])[0];
    assert_eq!(s.column("crank.B.r[1]"), Some(s.crank_tip[0]));
    assert_eq!(s.column("rocker.A.r[1]"), Some(2.0));
    assert_eq!(s.column("rocker.B.v[2]"), Some(s.rocker_b_velocity[1]));
    assert_eq!(s.column("rocker.phi"), Some(s.phi[1]));
    assert_eq!(s.column("crank.omega"), Some(s.omega[0]));
    assert_eq!(s.column("crank.X"), None);
}
