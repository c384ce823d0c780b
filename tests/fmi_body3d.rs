//! The 3D rigid-body FMU (fmus/body3d) driven through tether-fmi against closed forms:
//! free fall, the torque-free symmetric top, energy of the spherical and revolute
//! pendulums, orthonormal rotations, marker velocity vs. a finite difference of the
//! marker position, and the accelerations as direct feedthrough of marker forces on a
//! free and on a grounded body.

use nalgebra::{Matrix3, Rotation3, Vector3};
use tether_fmi::{Fmu, Instance, InstanceOptions};

/// Dop853's rtol = atol inside the FMU.
const TOLERANCE: f64 = 1e-12;

fn body3d() -> Fmu {
    let path = tether_fmu_build::workspace_fmu("body3d")
        .unwrap_or_else(|e| panic!("cannot build the body3d FMU: {e}"));
    Fmu::open(path).expect("open body3d")
}

/// One body3d instance, initialised with `reals` (by name) and the ground `joint`.
fn start(fmu: &Fmu, reals: &[(&str, f64)], joint: i32) -> Result<Instance, tether_fmi::Error> {
    let md = fmu.model_description();
    let mut inst = fmu.instantiate("body", InstanceOptions::default())?;
    inst.setup_experiment(None, 0.0, None)?;
    let mut names: Vec<&str> = reals.iter().map(|(n, _)| *n).collect();
    let mut values: Vec<f64> = reals.iter().map(|(_, v)| *v).collect();
    names.push("tolerance");
    values.push(TOLERANCE);
    let vrs: Vec<_> = names
        .iter()
        .map(|n| md.value_reference(n).expect("body3d variable"))
        .collect();
    inst.set_real(&vrs, &values)?;
    inst.set_integer(&[md.value_reference("joint").unwrap()], &[joint])?;
    inst.enter_initialization_mode()?;
    inst.exit_initialization_mode()?;
    Ok(inst)
}

fn vector(name: &str, v: Vector3<f64>) -> [(String, f64); 3] {
    [1, 2, 3].map(|i| (format!("{name}[{i}]"), v[i - 1]))
}

/// Parameters as owned (name, value) pairs, for [`start`].
struct Params(Vec<(String, f64)>);

impl Params {
    fn new(scalars: &[(&str, f64)]) -> Self {
        Params(scalars.iter().map(|(n, v)| (n.to_string(), *v)).collect())
    }
    fn vec(mut self, name: &str, v: Vector3<f64>) -> Self {
        self.0.extend(vector(name, v));
        self
    }
    fn start(&self, fmu: &Fmu, joint: i32) -> Instance {
        self.try_start(fmu, joint).expect("initialise body3d")
    }
    fn try_start(&self, fmu: &Fmu, joint: i32) -> Result<Instance, tether_fmi::Error> {
        let pairs: Vec<(&str, f64)> = self.0.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        start(fmu, &pairs, joint)
    }
}

/// The 24 marker outputs of `name`.
#[derive(Debug)]
struct Marker {
    r: Vector3<f64>,
    rot: Matrix3<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
    a: Vector3<f64>,
    alpha: Vector3<f64>,
}

fn marker(inst: &mut Instance, name: &str) -> Marker {
    let md = inst.model_description();
    let mut names = Vec::new();
    for q in ["r", "R", "v", "w", "a", "alpha"] {
        if q == "R" {
            for i in 1..=3 {
                for j in 1..=3 {
                    names.push(format!("{name}.R[{i},{j}]"));
                }
            }
        } else {
            names.extend((1..=3).map(|i| format!("{name}.{q}[{i}]")));
        }
    }
    let vrs: Vec<_> = names
        .iter()
        .map(|n| md.value_reference(n).expect("marker output"))
        .collect();
    let mut y = vec![0.0; vrs.len()];
    inst.get_real(&vrs, &mut y).expect("marker outputs");
    let v3 = |k: usize| Vector3::new(y[k], y[k + 1], y[k + 2]);
    Marker {
        r: v3(0),
        rot: Matrix3::from_row_slice(&y[3..12]),
        v: v3(12),
        w: v3(15),
        a: v3(18),
        alpha: v3(21),
    }
}

fn real(inst: &mut Instance, name: &str) -> f64 {
    let vr = inst.value_reference(name).expect("variable");
    let mut y = [0.0];
    inst.get_real(&[vr], &mut y).expect("get_real");
    y[0]
}

fn set_vector(inst: &mut Instance, name: &str, v: Vector3<f64>) {
    let vrs: Vec<_> = (1..=3)
        .map(|i| inst.value_reference(&format!("{name}[{i}]")).unwrap())
        .collect();
    inst.set_real(&vrs, v.as_slice()).expect("set input");
}

fn rotation(phi: Vector3<f64>) -> Matrix3<f64> {
    Rotation3::from_scaled_axis(phi).into_inner()
}

fn orthonormality_error(r: &Matrix3<f64>) -> f64 {
    (r.transpose() * r - Matrix3::identity()).abs().max() + (r.determinant() - 1.0).abs()
}

#[test]
fn free_fall_is_a_parabola_and_the_attitude_is_constant() {
    let fmu = body3d();
    let (r0, v0) = (Vector3::new(0.5, -1.0, 2.0), Vector3::new(1.0, 2.0, 3.0));
    let g = Vector3::new(0.3, -0.7, -9.81);
    let phi0 = Vector3::new(0.3, -0.4, 1.2);
    let offset = Vector3::new(0.2, 0.1, -0.3);
    let mut inst = Params::new(&[("m", 2.5), ("gx", g.x), ("gy", g.y), ("gz", g.z)])
        .vec("r0", r0)
        .vec("v0", v0)
        .vec("phi0", phi0)
        .vec("A.offset", offset)
        .start(&fmu, 0);
    let rot0 = rotation(phi0);
    let h = 0.01;
    let mut worst: f64 = 0.0;
    for k in 0..=100 {
        let t = k as f64 * h;
        let m = marker(&mut inst, "A");
        let r = r0 + v0 * t + g * (0.5 * t * t) + rot0 * offset;
        worst = worst
            .max((m.r - r).norm())
            .max((m.v - (v0 + g * t)).norm())
            .max((m.a - g).norm())
            .max((m.rot - rot0).abs().max())
            .max(m.w.norm() + m.alpha.norm());
        if k < 100 {
            inst.do_step(t, h, true).expect("step");
        }
    }
    eprintln!("free fall: largest deviation {worst:.1e}");
    assert!(
        worst < 1e-10,
        "largest deviation from the parabola {worst:e}"
    );
}

/// Axisymmetric body (Jxx = Jyy = I1, Jzz = I3) without torque: with L the constant
/// angular momentum, ω = L/I1 − Ω e3 and R(t) = exp(t[L/I1]×) R0 exp(−Ω t [e_z]×),
/// Ω = (I3 − I1) ω3 / I1 (regular precession).
#[test]
fn torque_free_symmetric_top_precesses_as_the_closed_form_says() {
    let fmu = body3d();
    let (i1, i3) = (0.2, 0.5);
    let phi0 = Vector3::new(0.4, 0.2, -0.3);
    let rot0 = rotation(phi0);
    let wb0 = Vector3::new(1.5, -0.5, 6.0); // body frame
    let w0 = rot0 * wb0;
    let mut inst = Params::new(&[("Jxx", i1), ("Jyy", i1), ("Jzz", i3), ("gz", 0.0)])
        .vec("phi0", phi0)
        .vec("w0", w0)
        .start(&fmu, 0);
    let jw = rot0 * Matrix3::from_diagonal(&Vector3::new(i1, i1, i3)) * rot0.transpose();
    let l = jw * w0;
    let omega = (i3 - i1) * wb0.z / i1;
    let h = 0.01;
    let (mut worst, mut ortho): (f64, f64) = (0.0, 0.0);
    for k in 0..=300 {
        let t = k as f64 * h;
        let m = marker(&mut inst, "A");
        let rot = rotation(l / i1 * t) * rot0 * rotation(Vector3::z() * (-omega * t));
        let w = l / i1 - rot.column(2) * omega;
        worst = worst
            .max((m.rot - rot).abs().max())
            .max((m.w - w).norm() / w0.norm())
            .max((m.alpha - w.cross(&(rot.column(2) * -omega))).norm());
        ortho = ortho.max(orthonormality_error(&m.rot));
        if k < 300 {
            inst.do_step(t, h, true).expect("step");
        }
    }
    eprintln!("symmetric top: largest deviation {worst:.1e}, R orthonormal to {ortho:.1e}");
    assert!(
        worst < 1e-9,
        "largest deviation from the precession {worst:e}"
    );
    assert!(ortho < 1e-13, "R is not orthonormal: {ortho:e}");
}

/// Spherical (joint = 1) and revolute (joint = 2) pendulums: the pivot stays put,
/// energy is conserved, and a revolute body keeps its axis.
fn pendulum(joint: i32) -> (f64, f64, f64, f64) {
    let fmu = body3d();
    let pivot = Vector3::new(0.1, -0.2, 0.6); // body point, from the CoM
    let phi0 = Vector3::new(0.7, -0.2, 0.4);
    let rot0 = rotation(phi0);
    let r0 = Vector3::new(0.3, 0.2, 1.0);
    let at = r0 + rot0 * pivot;
    let axis = Vector3::new(1.0, 0.5, 0.2).normalize();
    let w0 = if joint == 2 {
        rot0 * axis * 3.0
    } else {
        Vector3::new(2.0, -1.0, 4.0)
    };
    let v0 = w0.cross(&(r0 - at));
    let mut inst = Params::new(&[("m", 1.3), ("Jxx", 0.05), ("Jyy", 0.08), ("Jzz", 0.11)])
        .vec("r0", r0)
        .vec("v0", v0)
        .vec("w0", w0)
        .vec("phi0", phi0)
        .vec("pivot", pivot)
        .vec("axis", axis)
        .vec("A.offset", pivot)
        .vec("B.offset", Vector3::new(-0.3, 0.2, 0.1))
        .start(&fmu, joint);
    let e0 = real(&mut inst, "E");
    let h = 0.01;
    let (mut de, mut dp, mut ortho, mut daxis): (f64, f64, f64, f64) = (0.0, 0.0, 0.0, 0.0);
    let mut moved: f64 = 0.0;
    for k in 0..=300 {
        let t = k as f64 * h;
        let a = marker(&mut inst, "A");
        de = de.max((real(&mut inst, "E") - e0).abs() / e0.abs().max(1.0));
        dp = dp.max((a.r - at).norm() + a.v.norm() + a.a.norm());
        ortho = ortho.max(orthonormality_error(&a.rot));
        daxis = daxis.max((a.rot * axis - rot0 * axis).norm());
        moved = moved.max((a.rot - rot0).abs().max());
        if k < 300 {
            inst.do_step(t, h, true).expect("step");
        }
    }
    assert!(moved > 0.5, "the pendulum hardly moved ({moved})");
    eprintln!(
        "joint {joint}: energy drift {de:.1e}, pivot {dp:.1e}, R {ortho:.1e}, axis {daxis:.1e}"
    );
    (de, dp, ortho, daxis)
}

#[test]
fn spherical_pendulum_conserves_energy_and_keeps_its_pivot() {
    let (de, dp, ortho, _) = pendulum(1);
    assert!(de < 1e-9, "relative energy drift {de:e}");
    assert!(dp < 1e-12, "pivot motion {dp:e}");
    assert!(ortho < 1e-13, "R not orthonormal: {ortho:e}");
}

#[test]
fn revolute_pendulum_conserves_energy_and_keeps_its_axis() {
    let (de, dp, ortho, daxis) = pendulum(2);
    assert!(de < 1e-9, "relative energy drift {de:e}");
    assert!(dp < 1e-12, "pivot motion {dp:e}");
    assert!(ortho < 1e-13, "R not orthonormal: {ortho:e}");
    assert!(daxis < 1e-9, "axis moved by {daxis:e}");
}

#[test]
fn marker_velocity_is_the_derivative_of_the_marker_position() {
    let fmu = body3d();
    for joint in [0, 1] {
        let pivot = Vector3::new(0.0, 0.0, 0.5);
        let w0 = Vector3::new(1.0, -2.0, 3.0);
        let v0 = if joint == 0 {
            Vector3::new(0.3, 0.1, 2.0)
        } else {
            w0.cross(&-pivot)
        };
        let mut inst = Params::new(&[("Jxx", 0.1), ("Jyy", 0.2), ("Jzz", 0.25)])
            .vec("w0", w0)
            .vec("v0", v0)
            .vec("pivot", pivot)
            .vec("B.offset", Vector3::new(0.4, -0.3, 0.2))
            .start(&fmu, joint);
        let h = 1e-4;
        let mut samples = Vec::new();
        for k in 0..=2000 {
            samples.push(marker(&mut inst, "B"));
            if k < 2000 {
                inst.do_step(k as f64 * h, h, true).expect("step");
            }
        }
        let mut worst: f64 = 0.0;
        for k in (1..2000).step_by(97) {
            let dr = (samples[k + 1].r - samples[k - 1].r) / (2.0 * h);
            let dv = (samples[k + 1].v - samples[k - 1].v) / (2.0 * h);
            let dw = (samples[k + 1].w - samples[k - 1].w) / (2.0 * h);
            let drot = (samples[k + 1].rot - samples[k - 1].rot) / (2.0 * h);
            let s = &samples[k];
            let w_cross = Matrix3::new(0.0, -s.w.z, s.w.y, s.w.z, 0.0, -s.w.x, -s.w.y, s.w.x, 0.0);
            worst = worst
                .max((dr - s.v).norm())
                .max((dv - s.a).norm())
                .max((dw - s.alpha).norm())
                .max((drot - w_cross * s.rot).abs().max());
        }
        // Central differences: error ~ h²/6 · third derivative ≈ 1e-8 · O(100).
        eprintln!("joint {joint}: finite differences differ by {worst:.1e}");
        assert!(worst < 1e-6, "joint {joint}: derivative mismatch {worst:e}");
    }
}

/// World inertia of principal moments `j` at orientation `rot`.
fn world_inertia(rot: &Matrix3<f64>, j: Vector3<f64>) -> Matrix3<f64> {
    rot * Matrix3::from_diagonal(&j) * rot.transpose()
}

#[test]
fn marker_forces_act_at_once_on_a_free_body() {
    let fmu = body3d();
    let (m, j) = (2.0, Vector3::new(0.1, 0.3, 0.4));
    let phi0 = Vector3::new(-0.5, 0.3, 0.8);
    let rot = rotation(phi0);
    let w = Vector3::new(0.7, -1.1, 0.4);
    let g = Vector3::new(0.0, 0.0, -9.81);
    let (rho_a, rho_b) = (Vector3::new(0.3, 0.1, -0.2), Vector3::new(-0.2, 0.4, 0.1));
    let mut inst = Params::new(&[("m", m), ("Jxx", j.x), ("Jyy", j.y), ("Jzz", j.z)])
        .vec("phi0", phi0)
        .vec("w0", w)
        .vec("A.offset", rho_a)
        .vec("B.offset", rho_b)
        .start(&fmu, 0);
    let (fa, ta) = (Vector3::new(3.0, -2.0, 5.0), Vector3::new(0.5, 0.2, -0.3));
    let fb = Vector3::new(-1.0, 4.0, 0.5);
    set_vector(&mut inst, "A.F", fa);
    set_vector(&mut inst, "A.T", ta);
    set_vector(&mut inst, "B.F", fb);
    let (sa, sb) = (rot * rho_a, rot * rho_b);
    let jw = world_inertia(&rot, j);
    let tau = sa.cross(&fa) + ta + sb.cross(&fb);
    let alpha = jw.try_inverse().unwrap() * (tau - w.cross(&(jw * w)));
    let a_com = (fa + fb) / m + g;
    let at = |s: Vector3<f64>| a_com + alpha.cross(&s) + w.cross(&w.cross(&s));
    let (ma, mb) = (marker(&mut inst, "A"), marker(&mut inst, "B"));
    let err = (ma.a - at(sa))
        .norm()
        .max((mb.a - at(sb)).norm())
        .max((ma.alpha - alpha).norm())
        .max((mb.alpha - alpha).norm());
    assert!(err < 1e-12, "feedthrough mismatch {err:e}");
}

#[test]
fn marker_forces_act_at_once_on_grounded_bodies() {
    let fmu = body3d();
    let (m, j) = (1.5, Vector3::new(0.1, 0.2, 0.15));
    let phi0 = Vector3::new(0.2, 0.6, -0.4);
    let rot = rotation(phi0);
    let pivot = Vector3::new(0.1, 0.0, 0.5);
    let axis = Vector3::new(0.0, 0.6, 0.8);
    let rho_a = Vector3::new(0.3, -0.2, 0.1);
    let g = Vector3::new(0.0, -9.81, 0.0);
    let (fa, ta) = (Vector3::new(2.0, 1.0, -3.0), Vector3::new(-0.2, 0.4, 0.1));
    // At rest (ω = 0): J_O α = τ_O about the fixed point O, τ_O from the marker force,
    // the marker torque and gravity at the CoM.
    let r0 = Vector3::zeros();
    let o = r0 + rot * pivot;
    let tau = (rot * rho_a + r0 - o).cross(&fa) + ta + (r0 - o).cross(&(g * m));
    let d = r0 - o;
    let jo =
        world_inertia(&rot, j) + m * (Matrix3::identity() * d.norm_squared() - d * d.transpose());
    for joint in [1, 2] {
        let mut inst = Params::new(&[
            ("m", m),
            ("Jxx", j.x),
            ("Jyy", j.y),
            ("Jzz", j.z),
            ("gy", g.y),
            ("gz", 0.0),
        ])
        .vec("phi0", phi0)
        .vec("pivot", pivot)
        .vec("axis", axis)
        .vec("A.offset", rho_a)
        .start(&fmu, joint);
        set_vector(&mut inst, "A.F", fa);
        set_vector(&mut inst, "A.T", ta);
        let alpha = if joint == 1 {
            jo.try_inverse().unwrap() * tau
        } else {
            let n = rot * axis.normalize();
            n * (n.dot(&tau) / n.dot(&(jo * n)))
        };
        let ma = marker(&mut inst, "A");
        let a = alpha.cross(&(ma.r - o));
        let err = (ma.alpha - alpha).norm().max((ma.a - a).norm());
        assert!(err < 1e-12, "joint {joint}: feedthrough mismatch {err:e}");
    }
}

#[test]
fn invalid_parameters_are_refused_at_initialisation() {
    let fmu = body3d();
    assert!(Params::new(&[("m", 0.0)]).try_start(&fmu, 0).is_err());
    assert!(Params::new(&[("Jyy", -1.0)]).try_start(&fmu, 0).is_err());
    // A grounded body whose CoM velocity does not follow from w0.
    let inconsistent = Params::new(&[])
        .vec("pivot", Vector3::new(0.0, 0.0, 1.0))
        .vec("v0", Vector3::new(1.0, 0.0, 0.0));
    assert!(inconsistent.try_start(&fmu, 1).is_err());
    // A revolute body spinning off its axis.
    let off_axis = Params::new(&[]).vec("w0", Vector3::new(1.0, 0.0, 0.0));
    assert!(off_axis.try_start(&fmu, 2).is_err());
    assert!(Params::new(&[])
        .vec("axis", Vector3::zeros())
        .try_start(&fmu, 2)
        .is_err());
    // Both are fine when free.
    assert!(inconsistent.try_start(&fmu, 0).is_ok());
    assert!(off_axis.try_start(&fmu, 0).is_ok());
}
