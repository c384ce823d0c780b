//! FMI 3.0 co-simulation instances of the Modelica Association's Reference FMUs
//! (third-party FMUs vendored in `tests/fixtures/reference-fmus/fmi3`),
//! driven through the master's interface, `FmuInstance`.

use tether_fmi::{instantiate, Error, Fmu, FmuInstance, Placement};

/// The Reference FMU `model` and an instance of it; `None` where its binary does
/// not run (the test skips, see `tether_fmu_build::fixture_fmu`).
fn open(model: &str) -> Option<(Fmu, Box<dyn FmuInstance>)> {
    let path = tether_fmu_build::fixture_fmu(&format!("reference-fmus/fmi3/{model}.fmu"))?;
    let fmu = Fmu::open(path).unwrap();
    let instance = instantiate(&fmu, model, Default::default(), Placement::InProcess).unwrap();
    Some((fmu, instance))
}

fn vr(fmu: &Fmu, name: &str) -> u32 {
    fmu.model_description().value_reference(name).unwrap()
}

fn initialize(i: &mut dyn FmuInstance, stop: f64) {
    i.setup(None, 0.0, Some(stop)).unwrap();
    i.enter_initialization().unwrap();
    i.exit_initialization().unwrap();
}

#[test]
fn dahlquist_steps_saves_restores_and_serializes() {
    let Some((fmu, mut a)) = open("Dahlquist") else {
        return;
    };
    initialize(a.as_mut(), 10.0);
    let x = [vr(&fmu, "x")];
    let mut out = [0.0];
    a.get_reals(&x, &mut out).unwrap();
    assert_eq!(out[0], 1.0);
    a.save(0).unwrap();
    for n in 0..10 {
        a.step(n as f64 * 0.1, 0.1).unwrap();
    }
    assert!((a.time() - 1.0).abs() < 1e-12);
    let mut at_one = [0.0];
    a.get_reals(&x, &mut at_one).unwrap();
    // Forward Euler with k = 1 and h = 0.1: x = 0.9^10.
    assert!((at_one[0] - 0.9f64.powi(10)).abs() < 1e-12, "{at_one:?}");
    a.restore(0).unwrap();
    a.get_reals(&x, &mut out).unwrap();
    assert_eq!(out[0], 1.0);
    assert_eq!(a.time(), 0.0);
    let mut bytes = Vec::new();
    a.save(1).unwrap();
    a.step(0.0, 0.1).unwrap();
    a.serialize(1, &mut bytes).unwrap();
    assert!(!bytes.is_empty());
    a.deserialize(2, &bytes).unwrap();
    a.restore(2).unwrap();
    a.get_reals(&x, &mut out).unwrap();
    assert_eq!(out[0], 1.0);
    a.free(0).unwrap();
    a.terminate().unwrap();
}

#[test]
fn state_space_arrays_take_one_value_per_element() {
    let Some((fmu, mut a)) = open("StateSpace") else {
        return;
    };
    initialize(a.as_mut(), 10.0);
    let y = [vr(&fmu, "y")];
    let mut out = [0.0; 3];
    a.get_reals(&y, &mut out).unwrap();
    // x starts at zero (see the README), u at [1, 2, 3]: y = C x + D u = u.
    assert_eq!(out, [1.0, 2.0, 3.0]);
    let e = a.get_reals(&y, &mut [0.0]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::LengthMismatch {
                expected: 3,
                got: 1,
                ..
            }
        ),
        "{e}"
    );
    a.set_reals(&[vr(&fmu, "u")], &[4.0, 5.0, 6.0]).unwrap();
    a.get_reals(&y, &mut out).unwrap();
    assert_eq!(out, [4.0, 5.0, 6.0]);
    a.step(0.0, 1.0).unwrap();
}

#[test]
fn state_space_structural_parameters_are_set_in_configuration_mode() {
    let Some((fmu, mut a)) = open("StateSpace") else {
        return;
    };
    // The Reference FMUs at this commit check nValues one value too far when a
    // structural parameter is set (`ASSERT_NVALUES(1)` after the index moved on), so
    // the FMU refuses any correct call: the error is the FMU's, from the set, made in
    // configuration mode (outside it the FMU says so instead).
    let e = a.set_integers(&[vr(&fmu, "m")], &[2]).unwrap_err();
    match &e {
        Error::Failed {
            function, messages, ..
        } => {
            assert_eq!(*function, "fmi3SetUInt64");
            assert!(
                messages
                    .to_string()
                    .contains("Expected nValues >= 2 but was 1"),
                "{e}"
            );
        }
        other => panic!("{other}"),
    }
}

#[test]
fn feedthrough_passes_every_type() {
    let Some((fmu, mut a)) = open("Feedthrough") else {
        return;
    };
    initialize(a.as_mut(), 2.0);
    let v = |n: &str| vr(&fmu, n);
    a.set_reals(
        &[v("Float32_continuous_input"), v("Float64_continuous_input")],
        &[0.1, 0.2],
    )
    .unwrap();
    let mut reals = [0.0; 2];
    a.get_reals(
        &[
            v("Float32_continuous_output"),
            v("Float64_continuous_output"),
        ],
        &mut reals,
    )
    .unwrap();
    assert_eq!(reals, [f64::from(0.1f32), 0.2]);
    let ints = [
        "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
    ];
    let inputs: Vec<u32> = ints.iter().map(|t| v(&format!("{t}_input"))).collect();
    let outputs: Vec<u32> = ints.iter().map(|t| v(&format!("{t}_output"))).collect();
    a.set_integers(&inputs, &[-8, 8, -16, 16, -32, 32, -64, 64])
        .unwrap();
    let mut got = [0; 8];
    a.get_integers(&outputs, &mut got).unwrap();
    assert_eq!(got, [-8, 8, -16, 16, -32, 32, -64, 64]);
    let e = a.set_integers(&inputs[1..2], &[-1]).unwrap_err();
    assert!(
        e.to_string()
            .contains("outside the range of UInt8 'UInt8_input'"),
        "{e}"
    );
    a.set_integers(&[v("Enumeration_input")], &[2]).unwrap();
    a.get_integers(&[v("Enumeration_output")], &mut got[..1])
        .unwrap();
    assert_eq!(got[0], 2);
    a.set_booleans(&[v("Boolean_input")], &[true]).unwrap();
    let mut b = [false];
    a.get_booleans(&[v("Boolean_output")], &mut b).unwrap();
    assert!(b[0]);
    a.set_strings(
        &[v("String_input"), v("Binary_input")],
        &["hello", "00ff10"],
    )
    .unwrap();
    let mut s = [String::new(), String::new()];
    a.get_strings(&[v("String_output"), v("Binary_output")], &mut s)
        .unwrap();
    assert_eq!(s, ["hello", "00ff10"]);
    let e = a.get_reals(&[v("Int8_output")], &mut [0.0]).unwrap_err();
    assert!(e.to_string().contains("'Int8_output' is Int8"), "{e}");
    a.step(0.0, 0.1).unwrap();
}

#[test]
fn stair_requests_the_end_of_the_simulation() {
    let Some((_fmu, mut a)) = open("Stair") else {
        return;
    };
    initialize(a.as_mut(), 20.0);
    let mut t = 0.0;
    let end = loop {
        match a.step(t, 1.0) {
            Ok(()) => t += 1.0,
            Err(Error::TerminationRequested { time, .. }) => break time,
            Err(e) => panic!("{e}"),
        }
        assert!(t < 20.0, "no termination request");
    };
    assert!((9.0..=11.0).contains(&end), "{end}");
}

#[test]
fn input_derivatives_and_the_fmi2_instantiate_are_refused_with_a_reason() {
    let Some((fmu, mut a)) = open("Dahlquist") else {
        return;
    };
    initialize(a.as_mut(), 1.0);
    let k = [vr(&fmu, "k")];
    let inputs = tether_fmi::Inputs {
        vrs: &[],
        values: &[],
        derivative_vrs: &k,
        orders: &[1],
        derivatives: &[0.0],
    };
    let e = a.set_inputs(&inputs).unwrap_err().to_string();
    assert!(e.contains("FMI 3.0 has no input derivatives"), "{e}");
    let e = fmu
        .instantiate("c", Default::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("tether_fmi::instantiate"), "{e}");
}
