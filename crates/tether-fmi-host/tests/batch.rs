//! A batch of runs crosses to the host as one message and computes what the
//! same runs in process do, bit for bit; the calls that answer nothing wait
//! for the next that does; an error inside a batch names the call that
//! failed, as in process.

use tether_fmi::{instantiate, Fmu, FmuInstance, Inputs, Placement, RunRequest};

fn started(fmu: &Fmu, placement: Placement) -> Box<dyn FmuInstance> {
    let mut instance = instantiate(fmu, "m", Default::default(), placement).unwrap();
    instance.setup(None, 0.0, Some(1.0)).unwrap();
    instance.enter_initialization().unwrap();
    instance.exit_initialization().unwrap();
    instance
}

#[test]
fn a_batch_is_one_round_trip_and_names_the_call_that_failed() {
    let fmu = Fmu::open(tether_fmu_build::workspace_fmu("oscillator").unwrap()).unwrap();
    let md = fmu.model_description();
    let vr = |name: &str| md.value_reference(name).unwrap();
    let (x, v, force) = (vr("x"), vr("v"), vr("F"));
    let mut local = started(&fmu, Placement::InProcess);
    let mut remote = started(&fmu, Placement::Process { timeout: None });
    let force = [force];
    let inputs = |f: &'static [f64]| Inputs {
        vrs: &force,
        values: f,
        derivative_vrs: &[],
        orders: &[],
        derivatives: &[],
    };
    let outputs = [x, v];
    // A predictor run and two perturbed runs from the state saved before.
    let runs = [
        RunRequest {
            inputs: Some(inputs(&[1.0])),
            step: Some((0.0, 0.01)),
            outputs: &outputs,
            ..Default::default()
        },
        RunRequest {
            restore: Some(0),
            inputs: Some(inputs(&[1.5])),
            step: Some((0.0, 0.01)),
            outputs: &outputs,
            ..Default::default()
        },
        RunRequest {
            restore: Some(0),
            inputs: Some(inputs(&[2.0])),
            step: Some((0.0, 0.01)),
            outputs: &outputs,
            recorded: &[v],
            ..Default::default()
        },
    ];
    let (mut a, mut b) = ([0.0; 7], [0.0; 7]);
    let before = remote.round_trips();
    for (instance, out) in [(&mut local, &mut a), (&mut remote, &mut b)] {
        instance.save(0).unwrap();
        instance.run_batch(&runs, out).unwrap();
    }
    assert_eq!(remote.round_trips() - before, 1, "the save and the batch");
    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    assert_ne!(a[0], a[2], "the perturbed runs differ from the predictor");
    assert_eq!(a[5..], [a[5], a[6]], "x, v, then v recorded");
    assert_eq!(a[6].to_bits(), a[5].to_bits());

    // A run that reads nothing waits for the next call that answers.
    let corrector = RunRequest {
        restore: Some(0),
        inputs: Some(inputs(&[1.25])),
        step: Some((0.0, 0.01)),
        ..Default::default()
    };
    let before = remote.round_trips();
    for instance in [&mut local, &mut remote] {
        instance.run(&corrector, &mut []).unwrap();
    }
    assert_eq!(remote.round_trips(), before, "deferred");
    let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
    local.get_reals(&outputs, &mut a).unwrap();
    remote.get_reals(&outputs, &mut b).unwrap();
    assert_eq!(remote.round_trips() - before, 1);
    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));

    // The second run of a batch reads a variable the FMU does not have: the
    // error names fmi2GetReal and the time of that run, as in process.
    let failing = [
        RunRequest {
            restore: Some(0),
            ..runs[0]
        },
        RunRequest {
            restore: Some(0),
            step: Some((0.0, 0.01)),
            outputs: &[9999],
            ..Default::default()
        },
    ];
    let mut out = [0.0; 3];
    let in_process = local.run_batch(&failing, &mut out).unwrap_err();
    let isolated = remote.run_batch(&failing, &mut out).unwrap_err();
    assert_eq!(isolated.function(), Some("fmi2GetReal"), "{isolated}");
    assert_eq!(isolated.to_string(), in_process.to_string());
    // The host goes on after an FMI error.
    remote.get_reals(&outputs, &mut b).unwrap();
}

/// An FMI 3.0 Reference FMU (Modelica Association, vendored in
/// `tests/fixtures/reference-fmus/fmi3`); `None` where its binary does not run.
fn reference3(model: &str) -> Option<Fmu> {
    let path = tether_fmu_build::fixture_fmu(&format!("reference-fmus/fmi3/{model}.fmu"))?;
    Some(Fmu::open(path).unwrap())
}

/// FMI 3.0 instances go through the same batches: a batch of runs is one
/// round trip and equal to the runs in process bit for bit, a failing call
/// is named by its FMI 3.0 function, and a request to end the simulation
/// (the Reference `Stair`) crosses as `Error::TerminationRequested`, word for
/// word as in process, with the next call that answers.
#[test]
fn fmi3_instances_are_batched_and_their_errors_cross_as_in_process() {
    let Some(fmu) = reference3("Dahlquist") else {
        return;
    };
    let x = [fmu.model_description().value_reference("x").unwrap()];
    let mut local = started(&fmu, Placement::InProcess);
    let mut remote = started(&fmu, Placement::Process { timeout: None });
    // One step of 0.1, then from the saved state one of 0.2.
    let runs = [
        RunRequest {
            step: Some((0.0, 0.1)),
            outputs: &x,
            ..Default::default()
        },
        RunRequest {
            restore: Some(0),
            step: Some((0.0, 0.2)),
            outputs: &x,
            recorded: &x,
            ..Default::default()
        },
    ];
    let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
    let before = remote.round_trips();
    for (instance, out) in [(&mut local, &mut a), (&mut remote, &mut b)] {
        instance.save(0).unwrap();
        instance.run_batch(&runs, out).unwrap();
    }
    assert_eq!(remote.round_trips() - before, 1, "the save and the batch");
    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    // Forward Euler with k = 1 and internal steps of 0.1 from x = 1.
    assert!(
        (a[0] - 0.9).abs() < 1e-15 && (a[1] - 0.81).abs() < 1e-15,
        "{a:?}"
    );
    assert_eq!(a[2].to_bits(), a[1].to_bits());

    let failing = [RunRequest {
        restore: Some(0),
        step: Some((0.0, 0.1)),
        outputs: &[9999],
        ..Default::default()
    }];
    let mut out = [0.0];
    let in_process = local.run_batch(&failing, &mut out).unwrap_err();
    let isolated = remote.run_batch(&failing, &mut out).unwrap_err();
    assert_eq!(isolated.function(), Some("fmi3GetFloat64"), "{isolated}");
    assert_eq!(isolated.to_string(), in_process.to_string());

    let Some(stair) = reference3("Stair") else {
        return;
    };
    let counter = [stair
        .model_description()
        .value_reference("counter")
        .unwrap()];
    let ended = |placement| {
        let mut i = instantiate(&stair, "m", Default::default(), placement).unwrap();
        i.setup(None, 0.0, Some(20.0)).unwrap();
        i.enter_initialization().unwrap();
        i.exit_initialization().unwrap();
        let mut value = [0];
        for n in 0..20 {
            // In process the step fails; isolated, the read after it.
            let stepped = i.step(f64::from(n), 1.0);
            if let Err(e) = stepped.and_then(|()| i.get_integers(&counter, &mut value)) {
                return e;
            }
        }
        panic!("no termination request");
    };
    let (in_process, isolated) = (
        ended(Placement::InProcess),
        ended(Placement::Process { timeout: None }),
    );
    assert!(
        matches!(isolated, tether_fmi::Error::TerminationRequested { .. }),
        "{isolated}"
    );
    assert_eq!(isolated.to_string(), in_process.to_string());
}

/// An FMI 3.0 instance takes polynomial inputs only if it was made for them
/// (`InstanceOptions::polynomial_inputs`: the intermediate update callback is
/// passed then only), in process and in a host process alike (the option
/// crosses with `INSTANTIATE`): without it a polynomial is refused by name,
/// with it the step takes the polynomial, the same in both places.
#[test]
fn fmi3_polynomial_inputs_need_the_instance_option_in_process_and_in_the_host() {
    use tether_fmi::InstanceOptions;
    let fmu = Fmu::open(tether_fmu_build::workspace_fmu3("oscillator").unwrap()).unwrap();
    let md = fmu.model_description();
    let (x, force) = (
        md.value_reference("x").unwrap(),
        md.value_reference("F").unwrap(),
    );
    let force = [force];
    let polynomial = Inputs {
        vrs: &force,
        values: &[1.0],
        derivative_vrs: &force,
        orders: &[1],
        derivatives: &[200.0],
    };
    let mut ends = Vec::new();
    for placement in [Placement::InProcess, Placement::Process { timeout: None }] {
        for polynomial_inputs in [false, true] {
            let options = InstanceOptions::default().with_polynomial_inputs(polynomial_inputs);
            let mut i = instantiate(&fmu, "m", options, placement.clone()).unwrap();
            i.setup(None, 0.0, Some(1.0)).unwrap();
            i.enter_initialization().unwrap();
            i.exit_initialization().unwrap();
            // In the host the inputs and the step travel with the read (they
            // answer nothing).
            let mut out = [0.0];
            let set = i
                .set_inputs(&polynomial)
                .and_then(|()| i.step(0.0, 0.01))
                .and_then(|()| i.get_reals(&[x], &mut out));
            if !polynomial_inputs {
                let e = set.expect_err(&format!("{placement:?}")).to_string();
                assert!(
                    e.contains("input 'F' cannot take a polynomial")
                        && e.contains("instantiated for values only"),
                    "{placement:?}: {e}"
                );
                continue;
            }
            set.unwrap();
            ends.push(out[0]);
        }
    }
    // The same step in both places, and not the step with the force held at 1.
    assert_eq!(ends[0].to_bits(), ends[1].to_bits(), "{ends:?}");
    let mut held = started(&fmu, Placement::InProcess);
    held.set_reals(&force, &[1.0]).unwrap();
    held.step(0.0, 0.01).unwrap();
    let mut out = [0.0];
    held.get_reals(&[x], &mut out).unwrap();
    assert_ne!(
        out[0].to_bits(),
        ends[0].to_bits(),
        "the polynomial changed nothing"
    );
}
