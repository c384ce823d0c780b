//! Self-tests of the monolithic multibody reference (tests/support/multibody.rs):
//! constraint drift and energy on every 3D example, the velocity terms without
//! stabilisation, a revolute joint to a very heavy body against the physical-pendulum
//! equation, the grounded body3d FMU against the reference, and its parsing errors.

use std::path::PathBuf;

use nalgebra::{Matrix3, Rotation3, Vector3};
use ode_solvers::{Dop853, OutputType, System as OdeSystem, Vector2};
use tether_fmi::{Fmu, InstanceOptions};
use tether_tests::multibody::{JointKind, System};

const COMPOUND: [&str; 7] = [
    "universal",
    "revolute",
    "cylindrical",
    "translational",
    "planar",
    "inline",
    "orientation",
];

fn example(kind: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(format!("3d_{kind}.toml"))
}

fn times(stop: f64, n: usize) -> Vec<f64> {
    (0..=n).map(|k| stop * k as f64 / n as f64).collect()
}

/// Largest residual, velocity residual, relative energy drift, and how far the joint
/// moved (relative translation plus rotation between the two joint markers).
fn run(system: &System) -> (f64, f64, f64, f64) {
    let samples = system.simulate(&times(1.0, 50)).expect("reference run");
    let e0 = samples[0].energy;
    let (mut g, mut g_dot, mut de, mut moved): (f64, f64, f64, f64) = (0.0, 0.0, 0.0, 0.0);
    for s in &samples {
        g = g.max(s.residual);
        g_dot = g_dot.max(s.velocity_residual);
        de = de.max((s.energy - e0).abs() / e0.abs().max(1.0));
        let (b1, a2) = (&s.markers["body1.B"], &s.markers["body2.A"]);
        moved = moved.max((b1.r - a2.r).norm() + (b1.rot - a2.rot).abs().max());
    }
    (g, g_dot, de, moved)
}

#[test]
fn every_3d_example_keeps_its_joint_and_conserves_energy() {
    for kind in COMPOUND {
        let system = System::from_file(example(kind)).expect("example parses");
        assert_eq!(system.joints[0].kind.name(), kind);
        let (g, g_dot, de, moved) = run(&system);
        eprintln!("{kind}: |g| {g:.1e}, |g'| {g_dot:.1e}, energy drift {de:.1e}, moved {moved:.2}");
        assert!(g < 1e-10, "{kind}: constraint drift {g:e}");
        assert!(g_dot < 1e-10, "{kind}: velocity drift {g_dot:e}");
        assert!(de < 1e-10, "{kind}: relative energy drift {de:e}");
        assert!(moved > 0.1, "{kind}: the joint hardly moved ({moved})");
    }
}

#[test]
fn fundamental_joints_keep_their_condition_and_conserve_energy() {
    // The universal example's velocities also satisfy these joints (zero relative
    // velocity at the point, relative angular velocity (0, 1.5, -1) with no component
    // about x). Perpendicular needs z_i ⊥ z_j: z_i = (0, 1.5, -1) (normalised) is
    // perpendicular to z_j = x, and z_i × z_j = (0, -1, -1.5) ⊥ ω_rel, so ġ = 0 too.
    let text = std::fs::read_to_string(example("universal")).unwrap();
    for kind in ["atpoint", "inplane", "perpendicular"] {
        let mut text = text.replace("kind = \"universal\"", &format!("kind = \"{kind}\""));
        if kind == "perpendicular" {
            text = text.replacen("axis_i = [1, 0, 0]", "axis_i = [0, 1.5, -1]", 1);
            text = text.replacen("ref_i = [0, 1, 0]", "ref_i = [1, 0, 0]", 1);
        }
        let system = System::from_toml(&text).expect("parses");
        assert_eq!(system.joints[0].kind, JointKind::from_name(kind).unwrap());
        let (g, g_dot, de, moved) = run(&system);
        eprintln!("{kind}: |g| {g:.1e}, |g'| {g_dot:.1e}, energy drift {de:.1e}, moved {moved:.2}");
        assert!(g < 1e-10 && g_dot < 1e-10, "{kind}: drift {g:e}, {g_dot:e}");
        assert!(de < 1e-10, "{kind}: relative energy drift {de:e}");
    }
}

#[test]
fn without_stabilisation_the_velocity_terms_alone_keep_the_joints() {
    // Baumgarte off: a wrong γ (g̈ = G ν̇ + γ) would make g grow like t²·error.
    for kind in COMPOUND {
        let mut system = System::from_file(example(kind)).unwrap();
        system.baumgarte = (0.0, 0.0);
        let (g, g_dot, de, _) = run(&system);
        eprintln!("{kind} (no Baumgarte): |g| {g:.1e}, |g'| {g_dot:.1e}, energy drift {de:.1e}");
        assert!(g < 1e-10 && g_dot < 1e-10, "{kind}: drift {g:e}, {g_dot:e}");
    }
}

/// θ̈ = −(m g l / I_O) sin θ, integrated on its own.
struct Pendulum {
    k: f64,
}

impl OdeSystem<f64, Vector2<f64>> for Pendulum {
    fn system(&self, _t: f64, y: &Vector2<f64>, dy: &mut Vector2<f64>) {
        dy[0] = y[1];
        dy[1] = -self.k * y[0].sin();
    }
}

#[test]
fn revolute_joint_to_a_very_heavy_body_is_a_physical_pendulum() {
    let (m, jxx, l, g): (f64, f64, f64, f64) = (0.8, 0.02, 0.5, 9.81);
    let (theta0, omega0): (f64, f64) = (1.2, -2.0);
    let text = format!(
        r#"
[experiment]
stop = 2.0
[[instance]]
name = "ground"
fmu = "body3d.fmu"
parameters = {{ m = 1e12, Jxx = 1e12, Jyy = 1e12, Jzz = 1e12, joint = 1 }}
[[instance]]
name = "bob"
fmu = "body3d.fmu"
[instance.parameters]
m = {m}
Jxx = {jxx}
Jyy = 0.03
Jzz = 0.015
"phi0[1]" = {theta0}
"r0[2]" = {y0}
"r0[3]" = {z0}
"v0[2]" = {vy}
"v0[3]" = {vz}
"w0[1]" = {omega0}
"A.offset[3]" = {l}
[[joint]]
name = "hinge"
kind = "revolute"
i = "ground.B"
j = "bob.A"
axis_i = [1, 0, 0]
ref_i = [0, 1, 0]
axis_j = [1, 0, 0]
ref_j = [0, 1, 0]
"#,
        // CoM = −R_x(θ0)·(0, 0, l); velocity ω × CoM.
        y0 = l * theta0.sin(),
        z0 = -l * theta0.cos(),
        vy = l * omega0 * theta0.cos(),
        vz = l * omega0 * theta0.sin(),
    );
    let system = System::from_toml(&text).expect("parses");
    let t = times(2.0, 40);
    let samples = system.simulate(&t).expect("reference run");
    let k = m * g * l / (jxx + m * l * l);
    let mut worst: f64 = 0.0;
    for (s, &t) in samples.iter().zip(&t) {
        let y = if t == 0.0 {
            Vector2::new(theta0, omega0)
        } else {
            let y0 = Vector2::new(theta0, omega0);
            let mut solver = Dop853::new(Pendulum { k }, 0.0, t, t, y0, 1e-13, 1e-13);
            solver.set_output(OutputType::Sparse);
            solver.integrate().unwrap();
            *solver.y_out().last().unwrap()
        };
        let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), y[0]).into_inner();
        let bob = &s.markers["bob.A"];
        let com = -(rot * Vector3::new(0.0, 0.0, l));
        let bob_b = &s.markers["bob.B"];
        worst = worst
            .max((bob.rot - rot).abs().max())
            .max((bob.w - Vector3::x() * y[1]).norm())
            .max(bob.r.norm())
            .max((bob_b.r - com).norm());
    }
    eprintln!("physical pendulum: largest deviation {worst:.1e}");
    assert!(
        worst < 1e-8,
        "largest deviation from the pendulum {worst:e}"
    );
}

/// The body3d FMU's grounded bodies (reduced equations inside the FMU) against the
/// reference (maximal coordinates, ground joints as constraint rows).
#[test]
fn grounded_body3d_fmu_matches_the_reference() {
    let fmu = Fmu::open(tether_fmu_build::workspace_fmu("body3d").expect("package body3d"))
        .expect("open body3d");
    let md = fmu.model_description();
    let phi0 = Vector3::new(0.3, -0.6, 0.2);
    let pivot = Vector3::new(0.1, -0.1, 0.4);
    let axis = Vector3::new(0.3, 1.0, 0.2);
    for joint in [1, 2] {
        let rot0 = Rotation3::from_scaled_axis(phi0).into_inner();
        let w0 = if joint == 2 {
            rot0 * axis.normalize() * 2.5
        } else {
            Vector3::new(1.0, 2.0, -0.5)
        };
        let v0 = w0.cross(&-(rot0 * pivot));
        let mut params: Vec<(String, f64)> = vec![
            ("m".into(), 1.1),
            ("Jxx".into(), 0.04),
            ("Jyy".into(), 0.06),
            ("Jzz".into(), 0.05),
        ];
        for (name, v) in [
            ("phi0", phi0),
            ("w0", w0),
            ("v0", v0),
            ("pivot", pivot),
            ("axis", axis),
            ("B.offset", Vector3::new(0.2, 0.3, -0.1)),
        ] {
            for k in 0..3 {
                params.push((format!("{name}[{}]", k + 1), v[k]));
            }
        }
        let mut text = String::from(
            "[[instance]]\nname = \"body\"\nfmu = \"body3d.fmu\"\n[instance.parameters]\n",
        );
        text += &format!("joint = {joint}\n");
        for (n, v) in &params {
            text += &format!("\"{n}\" = {v:?}\n");
        }
        let reference = System::from_toml(&text)
            .expect("parses")
            .simulate(&times(1.0, 10))
            .expect("reference run");

        let mut inst = fmu.instantiate("body", InstanceOptions::default()).unwrap();
        inst.setup_experiment(None, 0.0, None).unwrap();
        let vrs: Vec<_> = params
            .iter()
            .map(|(n, _)| md.value_reference(n).unwrap())
            .collect();
        let values: Vec<f64> = params.iter().map(|(_, v)| *v).collect();
        inst.set_real(&vrs, &values).unwrap();
        inst.set_real(&[md.value_reference("tolerance").unwrap()], &[1e-12])
            .unwrap();
        inst.set_integer(&[md.value_reference("joint").unwrap()], &[joint])
            .unwrap();
        inst.enter_initialization_mode().unwrap();
        inst.exit_initialization_mode().unwrap();
        let names: Vec<String> = (1..=3)
            .map(|i| format!("B.r[{i}]"))
            .chain((1..=3).flat_map(|i| (1..=3).map(move |j| format!("B.R[{i},{j}]"))))
            .collect();
        let out_vrs: Vec<_> = names
            .iter()
            .map(|n| md.value_reference(n).unwrap())
            .collect();
        let mut worst: f64 = 0.0;
        for (k, s) in reference.iter().enumerate() {
            if k > 0 {
                for n in 0..10 {
                    let t = (k - 1) as f64 * 0.1 + n as f64 * 0.01;
                    inst.do_step(t, 0.01, true).unwrap();
                }
            }
            let mut y = vec![0.0; 12];
            inst.get_real(&out_vrs, &mut y).unwrap();
            let b = &s.markers["body.B"];
            let r = Vector3::new(y[0], y[1], y[2]);
            let rot = Matrix3::from_row_slice(&y[3..12]);
            worst = worst.max((r - b.r).norm()).max((rot - b.rot).abs().max());
        }
        eprintln!("body3d joint = {joint} vs reference: largest deviation {worst:.1e}");
        assert!(
            worst < 1e-8,
            "joint {joint}: FMU and reference differ by {worst:e}"
        );
    }
}

#[test]
fn columns_are_read_by_their_csv_names() {
    let system = System::from_file(example("revolute")).unwrap();
    let s = &system.simulate(&[0.0]).unwrap()[0];
    let a = &s.markers["body2.A"];
    assert_eq!(s.column("body2.A.r[3]"), Some(a.r[2]));
    assert_eq!(s.column("body2.A.R[1,2]"), Some(a.rot[(0, 1)]));
    assert_eq!(s.column("body2.A.alpha[2]"), Some(a.alpha[1]));
    assert_eq!(
        s.column("revolute.lambda[5]"),
        Some(s.multipliers["revolute"][4])
    );
    assert_eq!(s.column("body2.A.r[4]"), None);
    assert_eq!(s.column("body3.A.r[1]"), None);
    assert_eq!(s.column("revolute.lambda[6]"), None);
}

#[test]
fn bad_system_files_are_refused_with_the_culprit_named() {
    let text = std::fs::read_to_string(example("revolute")).unwrap();
    let cases = [
        ("kind = \"revolute\"", "kind = \"hinge\"", "hinge"),
        ("\"pivot[3]\" = 0.5", "\"pivit[3]\" = 0.5", "pivit[3]"),
        ("j = \"body2.A\"", "j = \"body2.C\"", "\"C\""),
        ("j = \"body2.A\"", "j = \"body9.A\"", "body9"),
        ("axis_j = [1, 0, 0]", "axis_j = [0, 0, 0]", "axis"),
        ("ref_i = [0, 1, 0]", "ref_i = [1, 0, 0]", "parallel"),
        (
            "axis_i = [1, 0, 0]",
            "axis_i = [1, 0, 0]\nplane = \"xy\"",
            "plane",
        ),
    ];
    for (from, to, culprit) in cases {
        assert!(text.contains(from), "{from}");
        let err = System::from_toml(&text.replacen(from, to, 1)).unwrap_err();
        assert!(
            !err.contains('\n') && err.contains(culprit),
            "{err:?} lacks {culprit:?}"
        );
    }
    // Inconsistent initial velocities are refused before integrating.
    let err = System::from_toml(&text.replace("\"w0[1]\" = 2.8", "\"w0[1]\" = 2.9"))
        .unwrap()
        .simulate(&[1.0])
        .unwrap_err();
    assert!(err.contains("initial state violates"), "{err}");
}
