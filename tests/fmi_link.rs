//! The planar link FMU (fmus/link) driven through tether-fmi against closed forms:
//! free flight under gravity, the pinned link's energy and oscillation period, marker
//! kinematics (rotation, finite differences, feedthrough of port forces) and port
//! forces given as input polynomials (docs/marker-ports.md, docs/fmus.md).

use std::f64::consts::PI;

use tether_fmi::{Fmu, Instance, InstanceOptions};

/// Dop853 rtol = atol (the FMU's `tolerance`, at its default).
const TOLERANCE: f64 = 1e-10;
const G: f64 = 9.81;

struct Link {
    inst: Instance,
}

impl Link {
    /// Instantiates and initializes a link with these Real parameters.
    fn start(fmu: &Fmu, reals: &[(&str, f64)], pinned: bool) -> Link {
        let mut inst = fmu
            .instantiate("link", InstanceOptions::default())
            .expect("instantiate");
        inst.setup_experiment(Some(TOLERANCE), 0.0, None)
            .expect("setup");
        let mut link = Link { inst };
        let (names, values): (Vec<&str>, Vec<f64>) = reals.iter().copied().unzip();
        link.set(&names, &values);
        let pinned_vr = link.inst.value_reference("pinned").expect("pinned");
        link.inst
            .set_boolean(&[pinned_vr], &[pinned])
            .expect("pinned");
        link.inst.enter_initialization_mode().expect("enter init");
        link.inst.exit_initialization_mode().expect("exit init");
        link
    }

    fn vrs(&self, names: &[&str]) -> Vec<u32> {
        names
            .iter()
            .map(|n| self.inst.value_reference(n).expect("link variable"))
            .collect()
    }

    fn set(&mut self, names: &[&str], values: &[f64]) {
        let vrs = self.vrs(names);
        self.inst.set_real(&vrs, values).expect("set_real");
    }

    fn get(&mut self, names: &[&str]) -> Vec<f64> {
        let vrs = self.vrs(names);
        let mut values = vec![0.0; vrs.len()];
        self.inst.get_real(&vrs, &mut values).expect("get_real");
        values
    }

    fn get3(&mut self, marker: &str, quantity: &str) -> [f64; 3] {
        let names: Vec<String> = (1..=3)
            .map(|k| format!("{marker}.{quantity}[{k}]"))
            .collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        let v = self.get(&names);
        [v[0], v[1], v[2]]
    }

    fn rotation(&mut self, marker: &str) -> [[f64; 3]; 3] {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, value) in row.iter_mut().enumerate() {
                *value = self.get(&[&format!("{marker}.R[{},{}]", i + 1, j + 1)])[0];
            }
        }
        r
    }

    fn step(&mut self, t: f64, h: f64) {
        self.inst.do_step(t, h, true).expect("do_step");
    }
}

fn link_fmu() -> Fmu {
    let path = tether_fmu_build::workspace_fmu("link").expect("packaging the link FMU");
    Fmu::open(path).expect("open link")
}

fn rotate(phi: f64, p: [f64; 2]) -> [f64; 2] {
    let (s, c) = phi.sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1]]
}

fn assert_close(what: &str, got: &[f64], expected: &[f64], tol: f64) {
    for (g, e) in got.iter().zip(expected) {
        assert!(
            (g - e).abs() <= tol,
            "{what}: got {got:?}, expected {expected:?} (tolerance {tol:e})"
        );
    }
}

/// A free link: l = 2, m = 3, J = 0.7, its end A placed at (1, 2), moving.
const FREE: &[(&str, f64)] = &[
    ("m", 3.0),
    ("J", 0.7),
    ("l", 2.0),
    ("x0", 1.0),
    ("y0", 2.0),
    ("phi0", 0.3),
    ("omega0", 2.0),
    ("vx0", 3.0),
    ("vy0", 4.0),
];

/// Centre of mass and its velocity at t = 0 of [`FREE`] (end A at −l/2 on the axis).
fn free_initial_cm() -> ([f64; 2], [f64; 2]) {
    let arm = rotate(0.3, [1.0, 0.0]); // CoM − A = R(φ0)·(l/2, 0)
    (
        [1.0 + arm[0], 2.0 + arm[1]],
        [3.0 - 2.0 * arm[1], 4.0 + 2.0 * arm[0]],
    )
}

#[test]
fn free_link_falls_on_a_parabola_and_spins_at_a_constant_rate() {
    let fmu = link_fmu();
    let mut link = Link::start(&fmu, FREE, false);
    let (c0, v0) = free_initial_cm();
    let h = 0.01;
    let e0 = link.get(&["E"])[0];
    for n in 0..=200 {
        let t = n as f64 * h;
        let phi = 0.3 + 2.0 * t;
        let c = [c0[0] + v0[0] * t, c0[1] + v0[1] * t - 0.5 * G * t * t];
        let v = [v0[0], v0[1] - G * t];
        assert_close(
            "phi, omega",
            &link.get(&["phi", "omega"]),
            &[phi, 2.0],
            1e-9,
        );
        for (marker, s) in [("A", -1.0), ("B", 1.0)] {
            let arm = rotate(phi, [s, 0.0]);
            let r = [c[0] + arm[0], c[1] + arm[1], 0.0];
            let vm = [v[0] - 2.0 * arm[1], v[1] + 2.0 * arm[0], 0.0];
            // a = g − ω² arm: no port force, no angular acceleration.
            let a = [-4.0 * arm[0], -G - 4.0 * arm[1], 0.0];
            assert_close(marker, &link.get3(marker, "r"), &r, 1e-9);
            assert_close(marker, &link.get3(marker, "v"), &vm, 1e-9);
            assert_close(marker, &link.get3(marker, "a"), &a, 1e-9);
            assert_close(marker, &link.get3(marker, "w"), &[0.0, 0.0, 2.0], 1e-9);
            assert_close(marker, &link.get3(marker, "alpha"), &[0.0; 3], 1e-12);
        }
        let e = link.get(&["E"])[0];
        assert!(
            (e - e0).abs() <= 1e-10 * e0.abs(),
            "E({t}) = {e}, E(0) = {e0}"
        );
        link.step(t, h);
    }
}

#[test]
fn pinned_link_without_damper_conserves_energy_to_1e_10() {
    let fmu = link_fmu();
    let reals = [
        ("c_phi", 50.0),
        ("phi_ref", 0.5),
        ("phi0", 1.5),
        ("omega0", 3.0),
        ("x0", 0.3),
        ("y0", -0.2),
    ];
    let mut link = Link::start(&fmu, &reals, true);
    let e0 = link.get(&["E"])[0];
    let h = 0.01;
    let mut drift = 0.0f64;
    for n in 0..500 {
        link.step(n as f64 * h, h);
        drift = drift.max((link.get(&["E"])[0] - e0).abs() / e0.abs());
        // Pinned at end A: A stays at the pivot.
        assert_close("A.r", &link.get3("A", "r"), &[0.3, -0.2, 0.0], 1e-14);
    }
    eprintln!("pinned link: relative energy drift {drift:e} over 5 s");
    assert!(drift < 1e-10, "relative energy drift {drift:e} over 5 s");
}

/// J_P φ̈ + d φ̇ + c (φ − φ_ref) = 0 (no gravity): the damped closed form.
#[test]
fn pinned_link_with_spring_and_damper_without_gravity_matches_the_closed_form() {
    let fmu = link_fmu();
    let (m, j, l, xp, c, d) = (2.0, 0.1, 1.5, 0.2, 400.0, 3.0);
    let (phi_ref, phi0, omega0) = (0.25, 0.75, -4.0);
    let reals = [
        ("m", m),
        ("J", j),
        ("l", l),
        ("g", 0.0),
        ("xP", xp),
        ("c_phi", c),
        ("d_phi", d),
        ("phi_ref", phi_ref),
        ("phi0", phi0),
        ("omega0", omega0),
    ];
    let mut link = Link::start(&fmu, &reals, true);
    let jp = j + m * (xp * l) * (xp * l); // parallel axis theorem
    let sigma = d / (2.0 * jp);
    let wd = (c / jp - sigma * sigma).sqrt();
    let (a, b) = (phi0 - phi_ref, (omega0 + sigma * (phi0 - phi_ref)) / wd);
    let h = 1e-3;
    for n in 0..=1000 {
        let t = n as f64 * h;
        let (s, co) = (wd * t).sin_cos();
        let e = (-sigma * t).exp();
        let phi = phi_ref + e * (a * co + b * s);
        let omega = e * ((b * wd - sigma * a) * co - (a * wd + sigma * b) * s);
        assert_close(
            "phi, omega",
            &link.get(&["phi", "omega"]),
            &[phi, omega],
            1e-8,
        );
        link.step(t, h);
    }
}

/// Small oscillation about the equilibrium of spring and gravity: the period is
/// 2π·√(J_P / k) with k = c_φ − m g (l/2) sin φ_eq (pinned at end A).
#[test]
fn small_oscillation_period_with_spring_and_gravity_matches_the_linearization() {
    let (m, l, c, phi_ref) = (1.0, 1.0, 500.0, PI / 4.0);
    let jp = 1.0 / 12.0 + m * 0.25 * l * l;
    // Equilibrium: −c (φ − φ_ref) − m g (l/2) cos φ = 0, by Newton.
    let mut phi_eq = phi_ref;
    for _ in 0..50 {
        let f = -c * (phi_eq - phi_ref) - m * G * 0.5 * l * phi_eq.cos();
        let df = -c + m * G * 0.5 * l * phi_eq.sin();
        phi_eq -= f / df;
    }
    let k = c - m * G * 0.5 * l * phi_eq.sin();
    let period = 2.0 * PI * (jp / k).sqrt();

    let fmu = link_fmu();
    let reals = [("c_phi", c), ("phi_ref", phi_ref), ("phi0", phi_eq + 1e-3)];
    let mut link = Link::start(&fmu, &reals, true);
    let h = 1e-3;
    let mut previous = (0.0, link.get(&["phi", "omega"]));
    let mut upward_crossings = Vec::new();
    for n in 0..1000 {
        let t = n as f64 * h;
        link.step(t, h);
        let now = (t + h, link.get(&["phi", "omega"]));
        let (y0, y1) = (previous.1[0] - phi_eq, now.1[0] - phi_eq);
        if y0 < 0.0 && y1 >= 0.0 {
            // Root of the cubic Hermite interpolant through (φ, ω) at both ends.
            let (d0, d1) = (previous.1[1] * h, now.1[1] * h);
            let hermite = |s: f64| {
                let s2 = s * s;
                let s3 = s2 * s;
                (2.0 * s3 - 3.0 * s2 + 1.0) * y0
                    + (s3 - 2.0 * s2 + s) * d0
                    + (-2.0 * s3 + 3.0 * s2) * y1
                    + (s3 - s2) * d1
            };
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if hermite(mid) < 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            upward_crossings.push(previous.0 + lo * h);
        }
        previous = now;
    }
    assert!(upward_crossings.len() >= 5, "{upward_crossings:?}");
    let n = upward_crossings.len() - 1;
    let measured = (upward_crossings[n] - upward_crossings[0]) / n as f64;
    let error = (measured - period).abs() / period;
    eprintln!("small-oscillation period: relative error {error:e}");
    assert!(
        error < 1e-7,
        "period {measured} vs linearization {period}: relative error {error:e}"
    );
}

/// Rotation, positions, velocities and accelerations of both markers agree with each
/// other: R orthonormal with its first column along A→B, and v, a, w, alpha equal to
/// central differences of r, v, φ, w.
#[test]
fn marker_kinematics_are_consistent_with_finite_differences() {
    let fmu = link_fmu();
    let pinned = [
        ("c_phi", 20.0),
        ("d_phi", 0.3),
        ("phi0", 2.0),
        ("omega0", 1.0),
        ("xP", 0.1),
        ("yP", 0.05),
        ("xA", -0.4),
        ("yA", 0.1),
    ];
    for (reals, is_pinned) in [(FREE, false), (&pinned[..], true)] {
        let mut link = Link::start(&fmu, reals, is_pinned);
        // A steady push at A and a torque at B, so that alpha ≠ 0.
        link.set(&["A.F[1]", "A.F[2]", "B.T[3]"], &[1.5, -2.0, 0.7]);
        let dt = 1e-4;
        let mut samples = Vec::new();
        for n in 0..=3000 {
            let mut row = Vec::new();
            for marker in ["A", "B"] {
                for q in ["r", "v", "a", "w", "alpha"] {
                    row.push(link.get3(marker, q));
                }
            }
            if n % 1000 == 500 {
                for marker in ["A", "B"] {
                    let r = link.rotation(marker);
                    for i in 0..3 {
                        for j in 0..3 {
                            let dot: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
                            let id = if i == j { 1.0 } else { 0.0 };
                            assert!((dot - id).abs() < 1e-14, "RᵀR of {marker}: {r:?}");
                        }
                    }
                    let det = r[0][0] * r[1][1] - r[0][1] * r[1][0];
                    assert!((det - 1.0).abs() < 1e-14 && r[2][2] == 1.0, "{r:?}");
                }
                // The link axis is R's first column (pinned case: A sits off the axis).
                let (ra, rb) = (link.get3("A", "r"), link.get3("B", "r"));
                let r = link.rotation("A");
                let phi = link.get(&["phi"])[0];
                assert_close(
                    "R column 1",
                    &[r[0][0], r[1][0]],
                    &[phi.cos(), phi.sin()],
                    1e-14,
                );
                if !is_pinned {
                    let len = ((rb[0] - ra[0]).powi(2) + (rb[1] - ra[1]).powi(2)).sqrt();
                    let axis = [(rb[0] - ra[0]) / len, (rb[1] - ra[1]) / len];
                    assert_close("axis A→B", &axis, &[r[0][0], r[1][0]], 1e-12);
                }
            }
            samples.push(row);
            link.step(n as f64 * dt, dt);
        }
        // Fourth-order central differences, error O(dt⁴·fifth derivative).
        for n in (2..2999).step_by(97) {
            for m in 0..2 {
                let at = |k: usize, q: usize| samples[k][5 * m + q];
                let diff = |q: usize| -> Vec<f64> {
                    (0..3)
                        .map(|c| {
                            (8.0 * (at(n + 1, q)[c] - at(n - 1, q)[c]) - at(n + 2, q)[c]
                                + at(n - 2, q)[c])
                                / (12.0 * dt)
                        })
                        .collect()
                };
                assert_close("v = dr/dt", &at(n, 1), &diff(0), 1e-6);
                assert_close("a = dv/dt", &at(n, 2), &diff(1), 1e-5);
                assert_close("alpha = dw/dt", &at(n, 4), &diff(3), 1e-5);
            }
        }
    }
}

/// Forces and torques at the ports act at once: the accelerations read right after
/// fmi2SetReal are the closed-form rigid-body accelerations (direct feedthrough).
#[test]
fn port_forces_give_the_closed_form_accelerations_at_once() {
    let fmu = link_fmu();
    let mut link = Link::start(&fmu, FREE, false);
    let (m, j, omega) = (3.0, 0.7, 2.0);
    for (t, loads) in [
        (0.0, [2.0, -3.0, 0.0, 1.0, 1.0, 0.5]),
        (0.5, [-1.0, 4.0, 2.0, 0.0, -2.5, -1.0]),
    ] {
        if t > 0.0 {
            link.set(
                &["A.F[1]", "A.F[2]", "A.T[3]", "B.F[1]", "B.F[2]", "B.T[3]"],
                &[0.0; 6],
            );
            link.step(0.0, t);
        }
        let phi = link.get(&["phi"])[0];
        let w = link.get(&["omega"])[0];
        if t == 0.0 {
            assert_eq!(w, omega);
        }
        link.set(
            &["A.F[1]", "A.F[2]", "A.T[3]", "B.F[1]", "B.F[2]", "B.T[3]"],
            &loads,
        );
        let arms = [rotate(phi, [-1.0, 0.0]), rotate(phi, [1.0, 0.0])];
        let forces = [[loads[0], loads[1]], [loads[3], loads[4]]];
        let cross = |a: [f64; 2], b: [f64; 2]| a[0] * b[1] - a[1] * b[0];
        let alpha =
            (loads[2] + loads[5] + cross(arms[0], forces[0]) + cross(arms[1], forces[1])) / j;
        let a_cm = [(loads[0] + loads[3]) / m, (loads[1] + loads[4]) / m - G];
        for (k, marker) in ["A", "B"].iter().enumerate() {
            let p = arms[k];
            let a = [
                a_cm[0] - alpha * p[1] - w * w * p[0],
                a_cm[1] + alpha * p[0] - w * w * p[1],
                0.0,
            ];
            assert_close(marker, &link.get3(marker, "a"), &a, 1e-12);
            assert_close(
                marker,
                &link.get3(marker, "alpha"),
                &[0.0, 0.0, alpha],
                1e-12,
            );
        }
    }
}

/// F(t) = f0 + f1 t + f2 t²/2 split equally on A and B (no net torque about the
/// centre of mass) and T(t) likewise at A, set once at t = 0 with their derivatives
/// and never again: the kit follows the polynomials, and the motion is the closed
/// form c(t) = c0 + v0 t + g t²/2 + (f0 t²/2 + f1 t³/6 + f2 t⁴/24)/m.
#[test]
fn polynomial_port_inputs_give_the_closed_form_motion() {
    let fmu = link_fmu();
    let mut link = Link::start(&fmu, FREE, false);
    let (m, j) = (3.0, 0.7);
    let fx = [4.0, -6.0, 12.0];
    let fy = [-2.0, 8.0, -9.0];
    let tq = [1.0, -3.0, 5.0];
    let names = ["A.F[1]", "A.F[2]", "B.F[1]", "B.F[2]", "A.T[3]"];
    let vrs = link.vrs(&names);
    let per_order = |o: usize| [fx[o] / 2.0, fy[o] / 2.0, fx[o] / 2.0, fy[o] / 2.0, tq[o]];
    link.set(&names, &per_order(0));
    for order in [1, 2] {
        link.inst
            .set_real_input_derivatives(&vrs, &[order; 5], &per_order(order as usize))
            .expect("input derivatives");
    }
    let poly =
        |c: [f64; 3], t: f64| c[0] * t * t / 2.0 + c[1] * t.powi(3) / 6.0 + c[2] * t.powi(4) / 24.0;
    let (c0, v0) = free_initial_cm();
    let h = 0.01;
    for n in 0..=100 {
        let t = n as f64 * h;
        let c = [
            c0[0] + v0[0] * t + poly(fx, t) / m,
            c0[1] + v0[1] * t - 0.5 * G * t * t + poly(fy, t) / m,
        ];
        let phi = 0.3 + 2.0 * t + poly(tq, t) / j;
        let (ra, rb) = (link.get3("A", "r"), link.get3("B", "r"));
        let mid = [(ra[0] + rb[0]) / 2.0, (ra[1] + rb[1]) / 2.0];
        assert_close("centre of mass", &mid, &c, 1e-9);
        assert_close("phi", &link.get(&["phi"]), &[phi], 1e-9);
        let torque = tq[0] + tq[1] * t + tq[2] * t * t / 2.0;
        assert_close("A.T[3](t)", &link.get(&["A.T[3]"]), &[torque], 1e-9);
        link.step(t, h);
    }
}

#[test]
fn a_restored_fmu_state_repeats_the_step_bit_for_bit() {
    let fmu = link_fmu();
    let reals = [
        ("c_phi", 500.0),
        ("d_phi", 50.0),
        ("phi_ref", PI / 4.0),
        ("phi0", 0.3),
    ];
    let mut link = Link::start(&fmu, &reals, true);
    link.set(&["B.F[1]", "B.F[2]"], &[3.0, -1.0]);
    link.step(0.0, 0.01);
    let state = link.inst.get_fmu_state().expect("get state");
    link.step(0.01, 0.01);
    let first = link.get(&["B.r[1]", "B.r[2]", "B.v[1]", "B.a[2]", "E"]);
    link.inst.set_fmu_state(&state).expect("set state");
    link.step(0.01, 0.01);
    let again = link.get(&["B.r[1]", "B.r[2]", "B.v[1]", "B.a[2]", "E"]);
    assert_eq!(first, again);
}
