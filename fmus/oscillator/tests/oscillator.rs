//! The oscillator against closed forms, in both integration modes, through the kit's
//! instance (the same code path as the C functions).

use oscillator::Oscillator;
use tether_fmu_kit::instance::{Instance, Status};
use tether_fmu_kit::machine::Call;

// Value references: m 0, c 1, d 2, x0 3, v0 4, tolerance 5, exact 6, F 7, F_ext 8,
// x 9, v 10, a 11.
const C: u32 = 1;
const X0: u32 = 3;
const V0: u32 = 4;
const EXACT: u32 = 6;
const F: u32 = 7;
const X: u32 = 9;
const V: u32 = 10;
const A: u32 = 11;

fn oscillator(exact: bool, reals: &[(u32, f64)]) -> Instance<Oscillator> {
    let mut inst = Instance::new("test", None, false);
    let (vrs, values): (Vec<u32>, Vec<f64>) = reals.iter().copied().unzip();
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&vrs, &values)),
        Status::Ok
    );
    assert_eq!(
        inst.call(Call::SetBoolean, |i| i.set_boolean(&[EXACT], &[exact])),
        Status::Ok
    );
    assert_eq!(
        inst.call(
            Call::EnterInitializationMode,
            Instance::enter_initialization_mode
        ),
        Status::Ok
    );
    assert_eq!(
        inst.call(
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode
        ),
        Status::Ok
    );
    inst
}

fn get(inst: &mut Instance<Oscillator>, vrs: &[u32]) -> Vec<f64> {
    let mut values = vec![0.0; vrs.len()];
    assert_eq!(
        inst.call(Call::GetReal, |i| i.get_real(vrs, &mut values)),
        Status::Ok
    );
    values
}

/// m ẍ + d ẋ + c x = F (constant), x(0) = x0, v(0) = v0, with m = 1, d = 10.
fn closed_form(c: f64, force: f64, x0: f64, v0: f64, t: f64) -> (f64, f64) {
    let (sigma, xp) = (5.0, force / c);
    let omega = (c - sigma * sigma).sqrt();
    let (a, b) = (x0 - xp, (v0 + sigma * (x0 - xp)) / omega);
    let e = (-sigma * t).exp();
    let (s, co) = (omega * t).sin_cos();
    let x = xp + e * (a * co + b * s);
    let v = e * ((b * omega - sigma * a) * co - (a * omega + sigma * b) * s);
    (x, v)
}

#[test]
fn both_modes_follow_the_closed_form_with_a_constant_force() {
    for exact in [false, true] {
        let mut inst = oscillator(exact, &[(C, 400.0), (X0, 0.01), (V0, -2.0)]);
        assert_eq!(
            inst.call(Call::SetReal, |i| i.set_real(&[F], &[7.0])),
            Status::Ok
        );
        for n in 0..50 {
            assert_eq!(
                inst.call(Call::DoStep, |i| i.do_step(n as f64 * 0.02, 0.02)),
                Status::Ok
            );
            let t = (n + 1) as f64 * 0.02;
            let (x, v) = closed_form(400.0, 7.0, 0.01, -2.0, t);
            let got = get(&mut inst, &[X, V, A]);
            assert!(
                (got[0] - x).abs() < 1e-11,
                "exact={exact} t={t}: x {} vs {x}",
                got[0]
            );
            assert!(
                (got[1] - v).abs() < 1e-9,
                "exact={exact} t={t}: v {} vs {v}",
                got[1]
            );
            assert!(
                (got[2] - (7.0 - 400.0 * got[0] - 10.0 * got[1])).abs() < 1e-9,
                "a is direct feedthrough"
            );
        }
    }
}

#[test]
fn exact_step_matches_dop853_with_a_quadratic_force() {
    let mut runs = [false, true].map(|exact| {
        let mut inst = oscillator(exact, &[]);
        assert_eq!(
            inst.call(Call::SetReal, |i| i.set_real(&[F], &[3.0])),
            Status::Ok
        );
        let set = |i: &mut Instance<Oscillator>| {
            i.set_real_input_derivatives(&[F, F], &[1, 2], &[-40.0, 900.0])
        };
        assert_eq!(inst.call(Call::SetRealInputDerivatives, set), Status::Ok);
        assert_eq!(
            inst.call(Call::DoStep, |i| i.do_step(0.0, 0.05)),
            Status::Ok
        );
        inst
    });
    let [numeric, exact] = &mut runs;
    let (xn, xe) = (get(numeric, &[X, V, A, F]), get(exact, &[X, V, A, F]));
    for (n, e) in xn.iter().zip(&xe) {
        assert!((n - e).abs() < 1e-8 * e.abs().max(1.0), "{xn:?} vs {xe:?}");
    }
    assert!(
        (xe[3] - (3.0 - 40.0 * 0.05 + 450.0 * 0.05 * 0.05)).abs() < 1e-12,
        "F at the end of the step"
    );
}

#[test]
fn output_derivatives_are_the_chain_of_v_and_a() {
    let mut inst = oscillator(true, &[]);
    let set =
        |i: &mut Instance<Oscillator>| i.set_real_input_derivatives(&[F, F], &[1, 2], &[5.0, 7.0]);
    assert_eq!(inst.call(Call::SetRealInputDerivatives, set), Status::Ok);
    assert_eq!(
        inst.call(Call::DoStep, |i| i.do_step(0.0, 0.01)),
        Status::Ok
    );
    let y = get(&mut inst, &[X, V, A, F]);
    let mut d = vec![0.0; 6];
    let vrs = [X, V, A, X, V, A];
    let get_d = |i: &mut Instance<Oscillator>| {
        i.get_real_output_derivatives(&vrs, &[1, 1, 1, 2, 2, 2], &mut d)
    };
    assert_eq!(inst.call(Call::GetRealOutputDerivatives, get_d), Status::Ok);
    let f1 = 5.0 + 7.0 * 0.01;
    let jerk = f1 - 1000.0 * y[1] - 10.0 * y[2];
    assert_eq!(d[0], y[1]);
    assert_eq!(d[1], y[2]);
    assert!((d[2] - jerk).abs() < 1e-9 * jerk.abs());
    assert_eq!(d[3], y[2]);
    assert!((d[5] - (7.0 - 1000.0 * y[2] - 10.0 * jerk)).abs() < 1e-9 * d[5].abs());
    let too_high =
        |i: &mut Instance<Oscillator>| i.get_real_output_derivatives(&[X], &[3], &mut [0.0]);
    assert_eq!(
        inst.call(Call::GetRealOutputDerivatives, too_high),
        Status::Error
    );
}

#[test]
fn a_non_positive_mass_is_refused_at_initialization() {
    let mut inst: Instance<Oscillator> = Instance::new("test", None, false);
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[C], &[-1.0])),
        Status::Error,
        "c >= 0"
    );
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[0], &[0.0])),
        Status::Ok
    );
    assert_eq!(
        inst.call(
            Call::EnterInitializationMode,
            Instance::enter_initialization_mode
        ),
        Status::Ok
    );
    assert_eq!(
        inst.call(
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode
        ),
        Status::Error
    );
}
