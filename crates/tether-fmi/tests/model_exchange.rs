//! Model-exchange instances ([`MeInstance`]) of the Modelica Association's
//! Reference FMUs (third-party FMUs vendored in `tests/fixtures/reference-fmus`),
//! FMI 2.0 and FMI 3.0, against closed-form solutions: the built-in integrator,
//! time and state events, termination, and the faults that end a run.

use tether_fmi::{Error, Fmu, FmuInstance, Integrator, MeInstance, Method};

/// The Reference FMU `model` of `standard` ("fmi2", "fmi3") as a model-exchange
/// instance; `None` where its binary does not run here.
fn open(standard: &str, model: &str, integrator: Integrator) -> Option<(Fmu, MeInstance)> {
    let path = tether_fmu_build::fixture_fmu(&format!("reference-fmus/{standard}/{model}.fmu"))?;
    let fmu = Fmu::open(path).unwrap();
    let instance = MeInstance::new(&fmu, model, Default::default(), integrator).unwrap();
    Some((fmu, instance))
}

fn vr(fmu: &Fmu, name: &str) -> u32 {
    fmu.model_description().value_reference(name).unwrap()
}

fn initialize(i: &mut dyn FmuInstance, tolerance: Option<f64>, stop: f64) {
    i.setup(tolerance, 0.0, Some(stop)).unwrap();
    i.enter_initialization().unwrap();
    i.exit_initialization().unwrap();
}

fn real(i: &mut dyn FmuInstance, vr: u32) -> f64 {
    let mut out = [0.0];
    i.get_reals(&[vr], &mut out).unwrap();
    out[0]
}

/// Dahlquist, x' = −k·x, x(0) = 1: x(t) = e^(−t) within the tolerance, every
/// method, FMI 2.0 and 3.0: at rtol 1e-10 the largest error on the grid
/// (0.1 … 10) is 5.1e-11 with bdf, 1.2e-9 with esdirk (third order, its
/// local error held to the tolerance at each of the 100 restarts), 3.0e-12
/// with rk45 and 2.5e-16 with dop853, alike for both standards; asserted at
/// about three times that (1e-11 for rk45 and dop853).
#[test]
fn dahlquist_follows_the_exponential() {
    for standard in ["fmi2", "fmi3"] {
        for (method, bound) in [
            (Method::Bdf, 1.5e-10),
            (Method::Esdirk, 4e-9),
            (Method::Rk45, 1e-11),
            (Method::Dop853, 1e-11),
        ] {
            let integrator = Integrator {
                method,
                ..Integrator::default()
            };
            let Some((fmu, mut a)) = open(standard, "Dahlquist", integrator) else {
                return;
            };
            initialize(&mut a, Some(1e-10), 10.0);
            let x = vr(&fmu, "x");
            let mut worst: f64 = 0.0;
            for n in 0..100 {
                a.step(n as f64 * 0.1, 0.1).unwrap();
                let t = (n + 1) as f64 * 0.1;
                worst = worst.max((real(&mut a, x) - (-t).exp()).abs());
            }
            eprintln!("{standard} {method:?}: largest error {worst:.1e}");
            assert!(worst < bound, "{standard} {method:?}: {worst:e}");
            assert!(worst > 0.0, "an integrator is exact only by accident");
            a.terminate().unwrap();
        }
    }
}

/// BouncingBall: the first bounce is a state event at √(2·h0/|g|) =
/// 0.451523641… s, located to 100·ε·max(|t|, h); after it v = −e·v⁻. The ball
/// velocity after the step over the bounce is the closed form's, at rtol
/// 1e-10, to 6.6e-14 with rk45 (exact for the ball's polynomials; asserted to
/// 1e-12), 9.1e-14 with esdirk (asserted to 3e-13) and 1.8e-9 with bdf, whose
/// first steps are of order 1 and 2 (asserted to 6e-9), FMI 2.0 and 3.0
/// alike.
#[test]
fn bouncing_ball_bounces_at_the_state_event() {
    for (standard, method, bound) in ["fmi2", "fmi3"].into_iter().flat_map(|s| {
        [
            (s, Method::Rk45, 1e-12),
            (s, Method::Bdf, 6e-9),
            (s, Method::Esdirk, 3e-13),
        ]
    }) {
        let integrator = Integrator {
            method,
            ..Integrator::default()
        };
        let Some((fmu, mut a)) = open(standard, "BouncingBall", integrator) else {
            return;
        };
        initialize(&mut a, Some(1e-10), 3.0);
        let (h, v) = (vr(&fmu, "h"), vr(&fmu, "v"));
        let t_bounce = (2.0f64 / 9.81).sqrt();
        let v_before = -9.81 * t_bounce;
        let mut crossed = None;
        let mut t = 0.0;
        for n in 0..100 {
            let before = real(&mut a, v);
            a.step(t, 0.01).unwrap();
            t = (n + 1) as f64 * 0.01;
            let after = real(&mut a, v);
            if before < 0.0 && after > 0.0 {
                crossed = Some((t, after));
                break;
            }
        }
        let (t_after, v_after) = crossed.expect("a bounce within 1 s");
        assert!(
            (t_after - 0.46).abs() < 1e-12,
            "{standard} {method:?}: {t_after}"
        );
        // v after the step = −e·v_before + g·(t_after − t_bounce).
        let expected = -0.7 * v_before - 9.81 * (t_after - t_bounce);
        let error = (v_after - expected).abs();
        eprintln!("{standard} {method:?}: v after the bounce off by {error:.1e}");
        assert!(
            error < bound,
            "{standard} {method:?}: v = {v_after}, expected {expected}"
        );
        assert!(real(&mut a, h) > 0.0);
        assert!(a.event_indicators()[0] > 0.0);
    }
}

/// Two instances of the same FMU stepped alike give the same bits, with
/// every method: every step restarts the integrator from its point with the
/// same initial step.
#[test]
fn steps_are_reproducible_bit_for_bit() {
    for (standard, (_, method)) in ["fmi2", "fmi3"]
        .into_iter()
        .flat_map(|s| Method::ALL.map(|m| (s, m)))
    {
        let mut runs = Vec::new();
        for _ in 0..2 {
            let integrator = Integrator {
                method,
                ..Integrator::default()
            };
            let Some((fmu, mut a)) = open(standard, "VanDerPol", integrator) else {
                return;
            };
            initialize(&mut a, Some(1e-6), 20.0);
            let vrs = [vr(&fmu, "x0"), vr(&fmu, "x1")];
            let mut rows = Vec::new();
            for n in 0..200 {
                a.step(n as f64 * 0.05, 0.05).unwrap();
                let mut out = [0.0; 2];
                a.get_reals(&vrs, &mut out).unwrap();
                rows.push(out.map(f64::to_bits));
            }
            runs.push(rows);
        }
        assert_eq!(runs[0], runs[1], "{standard} {method:?}");
    }
}

/// Stair has no continuous states: it is stepped without the integrator, its
/// counter counting the time events (one a second) until it asks to end the
/// simulation at the event at t = 9, which is the step's termination.
#[test]
fn stair_counts_its_time_events_without_the_integrator() {
    for standard in ["fmi2", "fmi3"] {
        let Some((fmu, mut a)) = open(standard, "Stair", Integrator::default()) else {
            return;
        };
        initialize(&mut a, None, 10.0);
        let counter = vr(&fmu, "counter");
        assert!(a.continuous_states().is_empty());
        let mut seen = Vec::new();
        let mut end = None;
        for n in 0..50 {
            if let Err(e) = a.step(n as f64 * 0.2, 0.2) {
                end = Some(e);
                break;
            }
            let mut out = [0];
            a.get_integers(&[counter], &mut out).unwrap();
            seen.push(out[0]);
        }
        // Counter 1 at the start, +1 at each whole second (events at 1, 2, …).
        assert_eq!(seen[3], 1, "{standard}: {seen:?}");
        assert_eq!(seen[4], 2, "{standard}: {seen:?}");
        assert_eq!(seen.len(), 44, "{standard}: {seen:?}");
        assert_eq!(seen[43], 9, "{standard}: {seen:?}");
        match end {
            Some(Error::TerminationRequested { time, .. }) => assert_eq!(time, 9.0),
            other => panic!("{standard}: {other:?}"),
        }
    }
}

/// NaN derivatives (Dahlquist with k = NaN) end the step with one line naming
/// the instance, the time and the cause.
#[test]
fn nan_derivatives_are_one_error_line() {
    for standard in ["fmi2", "fmi3"] {
        let Some((fmu, mut a)) = open(standard, "Dahlquist", Integrator::default()) else {
            return;
        };
        a.setup(None, 0.0, Some(1.0)).unwrap();
        a.enter_initialization().unwrap();
        a.set_reals(&[vr(&fmu, "k")], &[f64::NAN]).unwrap();
        a.exit_initialization().unwrap();
        let e = a.step(0.0, 0.1).unwrap_err();
        assert!(matches!(e, Error::ModelExchange { .. }), "{e:?}");
        let line = e.to_string();
        assert!(
            line.contains("'Dahlquist'")
                && line.contains("t = 0")
                && line.contains("NaN")
                && line.contains("Derivative")
                && !line.contains('\n'),
            "{line}"
        );
    }
}

/// A stiff model for an explicit method (Dahlquist with k = 1e9, rk45 at
/// rtol 1e-10): the integrator gives up, one line names the instance, the
/// time, the method and the tolerance.
#[test]
fn an_integrator_that_cannot_go_on_is_one_error_line() {
    let rk45 = Integrator {
        method: Method::Rk45,
        ..Integrator::default()
    };
    let Some((fmu, mut a)) = open("fmi2", "Dahlquist", rk45) else {
        return;
    };
    a.setup(Some(1e-10), 0.0, Some(1.0)).unwrap();
    a.enter_initialization().unwrap();
    a.set_reals(&[vr(&fmu, "k")], &[1e9]).unwrap();
    a.exit_initialization().unwrap();
    let e = a.step(0.0, 1.0).unwrap_err();
    let line = e.to_string();
    assert!(matches!(e, Error::ModelExchange { .. }), "{e:?}");
    assert!(
        line.contains("'Dahlquist'") && line.contains("rk45") && !line.contains('\n'),
        "{line}"
    );
}

/// An implicit method that cannot go on (bdf and esdirk held to a largest
/// step of 1e-7 s over a step of 0.1 s: more than the 100,000 steps one call
/// may take) is one line naming the instance, the time, the method and the
/// cause.
#[test]
fn an_implicit_method_that_cannot_go_on_is_one_error_line() {
    for method in [Method::Bdf, Method::Esdirk] {
        let integrator = Integrator {
            method,
            max_step: Some(1e-7),
            ..Integrator::default()
        };
        let Some((_, mut a)) = open("fmi3", "Dahlquist", integrator) else {
            return;
        };
        initialize(&mut a, Some(1e-6), 1.0);
        let e = a.step(0.0, 0.1).unwrap_err();
        let line = e.to_string();
        assert!(matches!(e, Error::ModelExchange { .. }), "{e:?}");
        assert!(
            line.contains("'Dahlquist'")
                && line.contains(&format!("({}, rtol 0.000001", method.name()))
                && line.contains("needs more than 100000 steps")
                && !line.contains('\n'),
            "{line}"
        );
        eprintln!("{line}");
        // The time of the failure: 100,000 steps of 1e-7 s.
        let Error::ModelExchange { time, .. } = e else {
            unreachable!()
        };
        assert!((time - 0.01).abs() < 1e-9, "{line}");
    }
}

/// FMI 3.0 clocks are refused for model exchange in one line, before the FMU
/// is instantiated: the Reference BouncingBall with a clock added to its
/// model description (unpacked into a temporary folder, its binary as
/// shipped).
#[test]
fn fmi3_clocks_are_refused_in_one_line() {
    let Some(path) = tether_fmu_build::fixture_fmu("reference-fmus/fmi3/BouncingBall.fmu") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut archive = zip::ZipArchive::new(std::fs::File::open(path).unwrap()).unwrap();
    archive.extract(dir.path()).unwrap();
    let xml_path = dir.path().join("modelDescription.xml");
    let xml = std::fs::read_to_string(&xml_path).unwrap().replacen(
        "<ModelVariables>",
        r#"<ModelVariables>
    <Clock name="tick" valueReference="100" causality="input" intervalVariability="triggered"/>"#,
        1,
    );
    std::fs::write(&xml_path, xml).unwrap();
    let fmu = Fmu::open(dir.path()).unwrap();
    let e = MeInstance::new(&fmu, "bb", Default::default(), Integrator::default()).unwrap_err();
    let line = e.to_string();
    assert!(matches!(e, Error::Unsupported { .. }), "{e:?}");
    assert!(
        line.contains("clocks (tick)") && line.contains("model exchange") && !line.contains('\n'),
        "{line}"
    );
}

/// A saved state holds the FMU's state and the instance's (states,
/// indicators, next time event): after a restore the same steps give the
/// same bits, across BouncingBall's first bounce, FMI 2.0 and 3.0.
#[test]
fn a_restored_state_repeats_the_steps_bit_for_bit() {
    for standard in ["fmi2", "fmi3"] {
        let Some((fmu, mut a)) = open(standard, "BouncingBall", Integrator::default()) else {
            return;
        };
        initialize(&mut a, Some(1e-8), 3.0);
        let vrs = [vr(&fmu, "h"), vr(&fmu, "v")];
        for n in 0..40 {
            a.step(n as f64 * 0.01, 0.01).unwrap();
        }
        a.save(0).unwrap();
        let mut runs = Vec::new();
        for _ in 0..2 {
            a.restore(0).unwrap();
            assert_eq!(a.time(), 0.4);
            let mut rows = Vec::new();
            for n in 40..60 {
                a.step(n as f64 * 0.01, 0.01).unwrap();
                let mut out = [0.0; 2];
                a.get_reals(&vrs, &mut out).unwrap();
                rows.push(out.map(f64::to_bits));
            }
            assert_eq!(a.events().0, 1, "{standard}: the bounce");
            runs.push(rows);
        }
        assert_eq!(runs[0], runs[1], "{standard}");
        a.free(0).unwrap();
        let e = a.restore(0).unwrap_err().to_string();
        assert!(e.contains("no FMU state saved in slot 0"), "{e}");
    }
}

/// A serialized state (the instance's part and the FMU's) taken into a second
/// instance makes it step as the first, bit for bit, across the bounce;
/// bytes of another shape are refused in one line.
#[test]
fn a_serialized_state_moves_to_another_instance() {
    for standard in ["fmi2", "fmi3"] {
        let Some((fmu, mut a)) = open(standard, "BouncingBall", Integrator::default()) else {
            return;
        };
        let Some((_, mut b)) = open(standard, "BouncingBall", Integrator::default()) else {
            return;
        };
        initialize(&mut a, Some(1e-8), 3.0);
        initialize(&mut b, Some(1e-8), 3.0);
        for n in 0..40 {
            a.step(n as f64 * 0.01, 0.01).unwrap();
        }
        a.save(0).unwrap();
        let mut bytes = Vec::new();
        a.serialize(0, &mut bytes).unwrap();
        b.deserialize(1, &bytes).unwrap();
        b.restore(1).unwrap();
        assert_eq!(b.time(), 0.4, "{standard}");
        let vrs = [vr(&fmu, "h"), vr(&fmu, "v")];
        for n in 40..60 {
            let mut rows = [[0.0; 2]; 2];
            for (i, x) in [&mut a, &mut b].into_iter().enumerate() {
                x.step(n as f64 * 0.01, 0.01).unwrap();
                x.get_reals(&vrs, &mut rows[i]).unwrap();
            }
            assert_eq!(
                rows[0].map(f64::to_bits),
                rows[1].map(f64::to_bits),
                "{standard}, step {n}"
            );
        }
        assert_eq!(b.events().0, 1, "{standard}: the bounce");
        let e = b
            .deserialize(1, &bytes[..bytes.len() - 1])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no saved state of a model-exchange instance") && !e.contains('\n'),
            "{e}"
        );
    }
}

/// A model-exchange instance answers what it can do from its `ModelExchange`
/// element and its integrator, not from `CoSimulation`: rollback (it owns the
/// continuous states), serialized states as `ModelExchange` declares them,
/// steps of any size, polynomials on every input, no output derivatives.
#[test]
fn a_model_exchange_instance_says_what_it_can_do() {
    for standard in ["fmi2", "fmi3"] {
        let Some((fmu, a)) = open(standard, "BouncingBall", Integrator::default()) else {
            return;
        };
        let me = fmu.model_description().model_exchange.as_ref().unwrap();
        let caps = a.capabilities();
        assert!(
            caps.rollback && caps.variable_steps && caps.polynomial_inputs,
            "{standard}"
        );
        assert_eq!(
            caps.serialization,
            me.can_get_and_set_fmu_state && me.can_serialize_fmu_state,
            "{standard}"
        );
        assert_eq!(caps.output_derivative_order, 0, "{standard}");
        assert_eq!(
            caps,
            tether_fmi::Capabilities::model_exchange(fmu.model_description())
        );
    }
}

/// Integer, Boolean, String and discrete Real inputs are set in event mode
/// after the initialization, as the standard requires (the Reference FMUs
/// refuse `SetInteger` in continuous-time mode): a changed value is one event
/// and reaches the discrete outputs; an unchanged one, or a continuous input,
/// is no event.
#[test]
fn discrete_inputs_are_set_in_event_mode() {
    for standard in ["fmi2", "fmi3"] {
        let Some((fmu, mut a)) = open(standard, "Feedthrough", Integrator::default()) else {
            return;
        };
        initialize(&mut a, None, 1.0);
        a.step(0.0, 0.1).unwrap();
        let events = |a: &MeInstance| a.events().0;
        let n = events(&a);
        let (int_in, int_out) = (vr(&fmu, "Int32_input"), vr(&fmu, "Int32_output"));
        a.set_integers(&[int_in], &[5]).unwrap();
        assert_eq!(
            events(&a),
            n + 1,
            "{standard}: a changed Integer is an event"
        );
        a.set_integers(&[int_in], &[5]).unwrap();
        assert_eq!(events(&a), n + 1, "{standard}: the same Integer is none");
        let (cont_in, disc_in, disc_out) = (
            vr(&fmu, "Float64_continuous_input"),
            vr(&fmu, "Float64_discrete_input"),
            vr(&fmu, "Float64_discrete_output"),
        );
        a.set_reals(&[cont_in], &[2.0]).unwrap();
        assert_eq!(events(&a), n + 1, "{standard}: a continuous input is none");
        a.set_reals(&[cont_in, disc_in], &[2.5, 3.0]).unwrap();
        assert_eq!(events(&a), n + 2, "{standard}: a discrete Real is an event");
        let (bool_in, bool_out) = (vr(&fmu, "Boolean_input"), vr(&fmu, "Boolean_output"));
        a.set_booleans(&[bool_in], &[true]).unwrap();
        let (str_in, str_out) = (vr(&fmu, "String_input"), vr(&fmu, "String_output"));
        a.set_strings(&[str_in], &["tethered"]).unwrap();
        assert_eq!(events(&a), n + 4, "{standard}");
        a.step(0.1, 0.1).unwrap();
        let mut i = [0];
        a.get_integers(&[int_out], &mut i).unwrap();
        let mut b = [false];
        a.get_booleans(&[bool_out], &mut b).unwrap();
        let mut s = [String::new()];
        a.get_strings(&[str_out], &mut s).unwrap();
        assert_eq!(
            (i[0], real(&mut a, disc_out), b[0], s[0].as_str()),
            (5, 3.0, true, "tethered"),
            "{standard}"
        );
        a.terminate().unwrap();
    }
}
