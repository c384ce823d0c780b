//! The oscillator FMU (fmus/oscillator) driven through tether-fmi reproduces the closed-form
//! solutions of m ẍ + d ẋ + c x = F(t): free damped oscillation, and a quadratic force
//! F(t) = f0 + f1 t + f2 t²/2 passed as input derivatives (orders 1 and 2) at every
//! communication point (ALGORITHM.md §3).

use tether_fmi::{Fmu, Instance, InstanceOptions, ValueReference};
use tether_tests::fmi::oscillator_fmu;

/// Parameters of m ẍ + d ẋ + c x = F with x(0) = x0, ẋ(0) = v0 (underdamped).
#[derive(Clone, Copy)]
struct Oscillator {
    m: f64,
    c: f64,
    d: f64,
    x0: f64,
    v0: f64,
}

const PLANT: Oscillator = Oscillator {
    m: 1.0,
    c: 1000.0,
    d: 10.0,
    x0: 0.5,
    v0: 10.0,
};

/// Force polynomial F(t) = f0 + f1 t + f2 t²/2.
#[derive(Clone, Copy)]
struct Force {
    f0: f64,
    f1: f64,
    f2: f64,
}

impl Force {
    const ZERO: Force = Force {
        f0: 0.0,
        f1: 0.0,
        f2: 0.0,
    };

    fn at(self, t: f64) -> [f64; 3] {
        [
            self.f0 + self.f1 * t + 0.5 * self.f2 * t * t,
            self.f1 + self.f2 * t,
            self.f2,
        ]
    }
}

/// Closed-form (x, ẋ, ẍ) at t: particular solution x_p = p0 + p1 t + p2 t² of the
/// polynomial forcing plus the damped homogeneous solution matching x0, v0.
fn closed_form(o: Oscillator, f: Force, t: f64) -> [f64; 3] {
    // Coefficients of t², t¹, t⁰ in m x_p'' + d x_p' + c x_p = f0 + f1 t + (f2/2) t².
    let p2 = f.f2 / (2.0 * o.c);
    let p1 = (f.f1 - 2.0 * o.d * p2) / o.c;
    let p0 = (f.f0 - 2.0 * o.m * p2 - o.d * p1) / o.c;
    let alpha = o.d / (2.0 * o.m);
    let wd = (o.c / o.m - alpha * alpha).sqrt();
    let a = o.x0 - p0;
    let b = (o.v0 - p1 + alpha * a) / wd;
    // x_h = e^{-αt}(a cos + b sin); v_h = e^{-αt}(c1 cos + d1 sin); a_h likewise.
    let c1 = b * wd - alpha * a;
    let d1 = -(a * wd + alpha * b);
    let c2 = d1 * wd - alpha * c1;
    let d2 = -(c1 * wd + alpha * d1);
    let (s, c) = (wd * t).sin_cos();
    let e = (-alpha * t).exp();
    [
        e * (a * c + b * s) + p0 + p1 * t + p2 * t * t,
        e * (c1 * c + d1 * s) + p1 + 2.0 * p2 * t,
        e * (c2 * c + d2 * s) + 2.0 * p2,
    ]
}

struct Vrs {
    f: ValueReference,
    outputs: [ValueReference; 3],
}

fn start(fmu: &Fmu, exact: bool, o: Oscillator, stop: f64) -> (Instance, Vrs) {
    let md = fmu.model_description();
    let vr = |name: &str| md.value_reference(name).expect("oscillator variable");
    let mut inst = fmu
        .instantiate(
            if exact { "exact" } else { "dop853" },
            InstanceOptions::default(),
        )
        .expect("instantiate");
    inst.setup_experiment(None, 0.0, Some(stop)).expect("setup");
    let names = ["m", "c", "d", "x0", "v0", "tolerance"];
    let values = [o.m, o.c, o.d, o.x0, o.v0, TOLERANCE];
    let vrs: Vec<_> = names.iter().map(|n| vr(n)).collect();
    inst.set_real(&vrs, &values).expect("parameters");
    inst.set_boolean(&[vr("exact")], &[exact])
        .expect("exact flag");
    inst.enter_initialization_mode().expect("enter init");
    inst.exit_initialization_mode().expect("exit init");
    let vrs = Vrs {
        f: vr("F"),
        outputs: [vr("x"), vr("v"), vr("a")],
    };
    (inst, vrs)
}

/// Largest |FMU − closed form| of x, ẋ and ẍ over n steps of h, each scaled by the
/// signal's largest magnitude (so "1e-9" means nine correct digits of the swing).
fn max_relative_error(exact: bool, f: Force, h: f64, n: usize) -> [f64; 3] {
    let fmu = Fmu::open(oscillator_fmu()).expect("open oscillator");
    let (mut inst, vrs) = start(&fmu, exact, PLANT, n as f64 * h);
    let mut worst = [0.0f64; 3];
    let mut scale = [0.0f64; 3];
    let mut y = [0.0; 3];
    for k in 0..n {
        let t = k as f64 * h;
        let [value, d1, d2] = f.at(t);
        inst.set_real(&[vrs.f], &[value]).expect("F");
        inst.set_real_input_derivatives(&[vrs.f, vrs.f], &[1, 2], &[d1, d2])
            .expect("input derivatives");
        // Outputs at the communication point, with the input just set (direct feedthrough).
        inst.get_real(&vrs.outputs, &mut y).expect("outputs at t");
        let expected = closed_form(PLANT, f, t);
        for i in 0..3 {
            worst[i] = worst[i].max((y[i] - expected[i]).abs());
            scale[i] = scale[i].max(expected[i].abs());
        }
        inst.do_step(t, h, true).expect("do_step");
    }
    [
        worst[0] / scale[0],
        worst[1] / scale[1],
        worst[2] / scale[2],
    ]
}

/// Dop853's rtol = atol (the FMU's `tolerance` parameter, at its default).
const TOLERANCE: f64 = 1e-10;

const FORCE: Force = Force {
    f0: 500.0,
    f1: -2000.0,
    f2: 6000.0,
};

#[test]
fn closed_form_reference_satisfies_the_ode() {
    // Guard the reference itself: m ẍ + d ẋ + c x = F and the initial conditions.
    for f in [Force::ZERO, FORCE] {
        let [x, v, _] = closed_form(PLANT, f, 0.0);
        assert!((x - PLANT.x0).abs() < 1e-12 && (v - PLANT.v0).abs() < 1e-12);
        for t in [0.0, 0.3, 0.77] {
            let [x, v, a] = closed_form(PLANT, f, t);
            let residual = PLANT.m * a + PLANT.d * v + PLANT.c * x - f.at(t)[0];
            assert!(residual.abs() < 1e-9, "residual {residual} at t={t}");
        }
    }
}

#[test]
fn free_oscillation_with_dop853_matches_the_closed_form_to_1e_9() {
    let err = max_relative_error(false, Force::ZERO, 1e-3, 1000);
    assert!(
        err.iter().all(|&e| e < 1e-9),
        "relative errors x, v, a: {err:?}"
    );
}

#[test]
fn free_oscillation_with_the_exact_integrator_matches_the_closed_form_to_1e_12() {
    let err = max_relative_error(true, Force::ZERO, 1e-3, 1000);
    assert!(
        err.iter().all(|&e| e < 1e-12),
        "relative errors x, v, a: {err:?}"
    );
}

#[test]
fn quadratic_force_as_input_derivatives_matches_the_forced_solution_with_dop853() {
    let err = max_relative_error(false, FORCE, 1e-3, 1000);
    assert!(
        err.iter().all(|&e| e < 1e-9),
        "relative errors x, v, a: {err:?}"
    );
}

#[test]
fn quadratic_force_as_input_derivatives_matches_the_forced_solution_exactly() {
    let err = max_relative_error(true, FORCE, 1e-3, 1000);
    assert!(
        err.iter().all(|&e| e < 1e-12),
        "relative errors x, v, a: {err:?}"
    );
}

#[test]
fn output_derivatives_are_consistent_with_the_outputs() {
    // ẋ and ẍ reported as output derivatives of x equal the v and a outputs.
    let fmu = Fmu::open(oscillator_fmu()).expect("open oscillator");
    let (mut inst, vrs) = start(&fmu, true, PLANT, 1.0);
    inst.do_step(0.0, 0.01, true).expect("step");
    let mut y = [0.0; 3];
    inst.get_real(&vrs.outputs, &mut y).expect("outputs");
    let mut d = [0.0; 2];
    let x = vrs.outputs[0];
    inst.get_real_output_derivatives(&[x, x], &[1, 2], &mut d)
        .expect("output derivatives");
    assert!(
        (d[0] - y[1]).abs() <= 1e-12 * y[1].abs().max(1.0),
        "{d:?} vs {y:?}"
    );
    assert!(
        (d[1] - y[2]).abs() <= 1e-12 * y[2].abs().max(1.0),
        "{d:?} vs {y:?}"
    );
}
