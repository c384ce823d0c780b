//! Statuses, the fatal state and the call protocol, observed with a C stub FMU compiled
//! at test time (tests/fixtures/fmi/stub_fmu.c) that logs the calls it receives.

use tether_fmi::{Error, Fmu, InstanceOptions, Status, StatusKind};
use tether_tests::fmi::{self, assert_one_line_naming, stub_calls, stub_fmu_dir};

fn initialized(fmu: &Fmu, name: &str) -> tether_fmi::Instance {
    fmi::initialized(fmu, name, InstanceOptions::default().with_logging(true))
}

fn stub() -> (tempfile::TempDir, Fmu, std::path::PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    let (root, log) = stub_fmu_dir(dir.path());
    let fmu = Fmu::open(&root).expect("open the stub FMU");
    (dir, fmu, log)
}

#[test]
fn ok_and_warning_are_ok_and_the_time_advances() {
    let (_dir, fmu, _log) = stub();
    let mut a = initialized(&fmu, "a");
    a.do_step(0.0, 0.5, true).expect("OK step");
    a.do_step(1.0, 0.5, true)
        .expect("a warning is not an error");
    assert_eq!(a.time(), 1.5);
    let mut out = [0.0; 2];
    a.get_real(&[0, 1], &mut out).expect("get_real");
    assert_eq!(out, [1.0, 1.5]);
    assert_eq!(a.last_successful_time().expect("real status"), 1.5);
    assert_eq!(a.do_step_status().expect("status"), Status::Ok);
    assert!(!a.terminated().expect("boolean status"));
    assert_eq!(
        a.get_string_status(StatusKind::PendingStatus)
            .expect("string status"),
        "idle"
    );
}

#[test]
fn discard_error_and_pending_are_typed_errors_naming_function_instance_and_time() {
    let (_dir, fmu, _log) = stub();
    let mut a = initialized(&fmu, "alpha");
    let err = a.do_step(2.0, 0.5, true).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Discard {
                function: "fmi2DoStep",
                time: 2.0,
                ..
            }
        ),
        "{err:?}"
    );
    assert_one_line_naming(&err, &["fmi2DoStep", "fmi2Discard", "'alpha'", "t=2"]);
    let err = a.do_step(3.0, 0.5, true).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Failed {
                function: "fmi2DoStep",
                time: 3.0,
                ..
            }
        ),
        "{err:?}"
    );
    assert_one_line_naming(&err, &["fmi2DoStep", "fmi2Error", "'alpha'", "t=3"]);
    let err = a.do_step(4.0, 0.5, true).unwrap_err();
    assert!(matches!(err, Error::Pending { .. }), "{err:?}");
    let err = a.set_real(&[0], &[f64::NAN]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Discard {
                function: "fmi2SetReal",
                ..
            }
        ),
        "{err:?}"
    );
    let err = a
        .get_integer_status(StatusKind::LastSuccessfulTime)
        .unwrap_err();
    assert!(matches!(
        err,
        Error::Discard {
            function: "fmi2GetIntegerStatus",
            ..
        }
    ));
    // Still usable after non-fatal errors.
    a.do_step(0.0, 0.1, true).expect("step after errors");
}

#[test]
fn after_fatal_every_call_on_every_instance_is_refused_and_nothing_is_freed() {
    let (_dir, fmu, log) = stub();
    let mut a = initialized(&fmu, "a");
    let mut b = initialized(&fmu, "b");
    let state = a.get_fmu_state().expect("state");
    let err = a.do_step(5.0, 0.5, true).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Fatal {
                function: "fmi2DoStep",
                ..
            }
        ),
        "{err:?}"
    );
    assert!(a.is_fatal() && b.is_fatal());
    let err = a.do_step(0.0, 0.1, true).unwrap_err();
    assert!(
        matches!(
            err,
            Error::FmuDead {
                function: "fmi2DoStep",
                ..
            }
        ),
        "{err:?}"
    );
    assert_one_line_naming(&err, &["fmi2DoStep", "'a'", "fmi2Fatal"]);
    let mut out = [0.0];
    assert!(matches!(
        b.get_real(&[0], &mut out),
        Err(Error::FmuDead { .. })
    ));
    assert!(matches!(
        fmu.instantiate("c", InstanceOptions::default()),
        Err(Error::FmuDead { .. })
    ));
    drop(state);
    drop(a);
    drop(b);
    drop(fmu);
    let calls = stub_calls(&log);
    assert!(
        !calls
            .iter()
            .any(|c| c.starts_with("fmi2FreeInstance") || c.starts_with("fmi2FreeFMUstate")),
        "{calls:?}"
    );
}

#[test]
fn free_instance_runs_once_when_the_last_holder_drops() {
    let (_dir, fmu, log) = stub();
    let mut a = initialized(&fmu, "a");
    let state = a.get_fmu_state().expect("state");
    drop(fmu);
    a.do_step(0.0, 0.5, true)
        .expect("the instance outlives the Fmu value");
    drop(a);
    assert!(!stub_calls(&log)
        .iter()
        .any(|c| c.starts_with("fmi2FreeInstance")));
    drop(state);
    let calls = stub_calls(&log);
    let frees: Vec<_> = calls.iter().filter(|c| c.starts_with("fmi2Free")).collect();
    assert_eq!(
        frees,
        ["fmi2FreeFMUstate a", "fmi2FreeInstance a"],
        "{calls:?}"
    );
}

#[test]
fn every_state_obtained_is_freed_exactly_once() {
    let (_dir, fmu, log) = stub();
    let mut a = initialized(&fmu, "a");
    let mut reused = a.get_fmu_state().expect("state");
    for _ in 0..10 {
        a.update_fmu_state(&mut reused).expect("update in place");
    }
    let bytes = a.serialize_fmu_state(&reused).expect("serialize");
    let copy = a.deserialize_fmu_state(&bytes).expect("deserialize");
    let many: Vec<_> = (0..5).map(|_| a.get_fmu_state().expect("state")).collect();
    drop((reused, copy, many, a));
    let calls = stub_calls(&log);
    let created = calls
        .iter()
        .filter(|c| c.starts_with("fmi2GetFMUstate"))
        .count();
    let freed = calls
        .iter()
        .filter(|c| c.starts_with("fmi2FreeFMUstate"))
        .count();
    assert_eq!((created, freed), (7, 7), "{calls:?}");
}

#[test]
fn resource_location_is_a_file_uri_of_the_resources_directory() {
    let (_dir, fmu, log) = stub();
    let _a = fmu
        .instantiate("a", InstanceOptions::default())
        .expect("instantiate");
    let expected = format!("fmi2Instantiate {}", fmu.resource_location());
    assert!(fmu.resource_location().starts_with("file:///"));
    assert!(fmu.resource_location().ends_with("/stub/resources"));
    assert!(stub_calls(&log).contains(&expected));
}

#[test]
fn other_base_types_round_trip_through_the_c_api() {
    let (_dir, fmu, _log) = stub();
    let mut a = initialized(&fmu, "named");
    let mut ints = [0; 3];
    a.get_integer(&[5, 6, 7], &mut ints).expect("ints");
    assert_eq!(ints, [7, 7, 7]);
    let mut bools = [true; 3];
    a.get_boolean(&[5, 6, 7], &mut bools).expect("bools");
    assert_eq!(bools, [false, true, false]);
    let mut strings = vec![String::from("old contents"); 2];
    a.get_string(&[1, 2], &mut strings).expect("strings");
    assert_eq!(strings, ["named", "named"]);
    a.set_integer(&[1], &[3]).expect("set int");
    a.set_boolean(&[1], &[true]).expect("set bool");
    a.set_string(&[1], &["text"]).expect("set string");
    let err = a.set_string(&[1], &["nul\0byte"]).unwrap_err();
    assert!(matches!(
        err,
        Error::InvalidArgument {
            function: "fmi2SetString",
            ..
        }
    ));
    let err = a.get_real(&[0, 1], &mut [0.0]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::LengthMismatch {
                expected: 2,
                got: 1,
                ..
            }
        ),
        "{err:?}"
    );
    let mut d = [1.0];
    a.get_real_output_derivatives(&[0], &[1], &mut d)
        .expect("output derivatives");
    assert_eq!(d, [0.0]);
    a.terminate().expect("terminate");
    a.reset().expect("reset");
}

#[test]
fn missing_capabilities_are_refused_before_calling_the_fmu() {
    let (_dir, fmu, _log) = stub();
    let mut a = initialized(&fmu, "a");
    let err = a
        .set_real_input_derivatives(&[0], &[1], &[1.0])
        .unwrap_err();
    match &err {
        Error::MissingCapability { capability, .. } => {
            assert_eq!(*capability, "canInterpolateInputs")
        }
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &["canInterpolateInputs", "'stub'"]);
    let err = a
        .get_directional_derivative(&[0], &[1], &[1.0], &mut [0.0])
        .unwrap_err();
    assert!(matches!(
        err,
        Error::MissingCapability {
            capability: "providesDirectionalDerivative",
            ..
        }
    ));
}

#[test]
fn the_oscillators_state_machine_errors_surface_as_typed_errors() {
    let fmu = Fmu::open(tether_tests::fmi::oscillator_fmu()).expect("open oscillator");
    let mut osc = fmu
        .instantiate("early", InstanceOptions::default())
        .expect("instantiate");
    // fmi2DoStep before initialization is refused by the FMU's state machine.
    let err = osc.do_step(0.0, 1e-3, true).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Failed {
                function: "fmi2DoStep",
                time: 0.0,
                ..
            }
        ),
        "{err:?}"
    );
    assert_one_line_naming(&err, &["fmi2DoStep", "fmi2Error", "'early'", "t=0"]);
    assert!(!osc.is_fatal());
    // A bad value reference is an error too, and the instance stays usable.
    let err = osc.get_real(&[9999], &mut [0.0]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Failed {
                function: "fmi2GetReal",
                ..
            }
        ),
        "{err:?}"
    );
    osc.setup_experiment(None, 0.5, None)
        .expect("setup after errors");
    osc.enter_initialization_mode().expect("enter init");
    osc.exit_initialization_mode().expect("exit init");
    osc.do_step(0.5, 1e-3, true).expect("step");
    assert_eq!(osc.time(), 0.5 + 1e-3);
}
