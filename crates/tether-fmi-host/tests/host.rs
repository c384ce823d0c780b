//! The host executable through the library: how `tether_fmi::remote` finds it,
//! and that a remote instance computes what an in-process one does, bit for
//! bit, states included.

use tether_fmi::remote::{host_command, RemoteInstance, HOST_ENV};
use tether_fmi::{Fmu, Instance};

/// One test, since it changes the process's environment.
#[test]
fn the_host_is_found_and_computes_what_in_process_instances_do() {
    let host = env!("CARGO_BIN_EXE_tether-fmi-host");
    // Without the variable: next to the test executable's directory
    // (target/debug/deps → target/debug), where cargo put the host.
    std::env::remove_var(HOST_ENV);
    let found = host_command().expect("found next to the executable");
    assert_eq!(
        found.program.canonicalize().unwrap(),
        std::path::Path::new(host).canonicalize().unwrap()
    );
    // The variable wins over every other place.
    std::env::set_var(HOST_ENV, "/nonexistent/tether-fmi-host");
    assert_eq!(
        host_command().unwrap().program,
        std::path::Path::new("/nonexistent/tether-fmi-host")
    );
    let fmu = Fmu::open(tether_fmu_build::workspace_fmu("oscillator").unwrap()).unwrap();
    let missing = RemoteInstance::new(&fmu, "m", Default::default(), None).unwrap_err();
    assert!(
        missing.to_string().starts_with(
            "cannot start the host process of instance 'm': /nonexistent/tether-fmi-host:"
        ),
        "{missing}"
    );
    std::env::set_var(HOST_ENV, host);

    let mut local = fmu.instantiate("m", Default::default()).unwrap();
    let mut remote = RemoteInstance::new(&fmu, "m", Default::default(), None).unwrap();
    let md = fmu.model_description();
    let vr = |name: &str| md.value_reference(name).unwrap();
    let (x, v, force) = (vr("x"), vr("v"), vr("F"));
    local.setup_experiment(None, 0.0, Some(1.0)).unwrap();
    remote.setup_experiment(None, 0.0, Some(1.0)).unwrap();
    local.enter_initialization_mode().unwrap();
    local.exit_initialization_mode().unwrap();
    remote.enter_initialization_mode().unwrap();
    remote.exit_initialization_mode().unwrap();
    let step = |l: &mut Instance, r: &mut RemoteInstance, t: f64, f: f64| {
        l.set_real(&[force], &[f]).unwrap();
        r.set_real(&[force], &[f]).unwrap();
        l.do_step(t, 0.01, true).unwrap();
        r.do_step(t, 0.01, true).unwrap();
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        l.get_real(&[x, v], &mut a).unwrap();
        r.get_real(&[x, v], &mut b).unwrap();
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "t = {t}");
        a
    };
    step(&mut local, &mut remote, 0.0, 1.0);
    // A state saved in the host, restored, serialised and loaded again.
    let saved = local.get_fmu_state().unwrap();
    remote.save_state(0).unwrap();
    let first = step(&mut local, &mut remote, 0.01, 2.0);
    local.set_fmu_state(&saved).unwrap();
    remote.restore_state(0).unwrap();
    assert_eq!(step(&mut local, &mut remote, 0.01, 2.0), first);
    let mut bytes = Vec::new();
    remote.serialize_state(0, &mut bytes).unwrap();
    assert_eq!(bytes, local.serialize_fmu_state(&saved).unwrap());
    remote.deserialize_state(1, &bytes).unwrap();
    remote.restore_state(1).unwrap();
    local.set_fmu_state(&saved).unwrap();
    assert_eq!(step(&mut local, &mut remote, 0.01, 2.0), first);
    // FMI errors cross with their kind; a missing state is one line, and
    // so is a slot the instance does not have; the host goes on.
    let e = remote.restore_state(3).unwrap_err();
    assert_eq!(
        e.to_string(),
        "fmi2SetFMUstate on instance 'm': no FMU state saved in slot 3"
    );
    let e = remote.restore_state(7).unwrap_err();
    assert_eq!(
        e.to_string(),
        "fmi2SetFMUstate on instance 'm': no state slot 7 (an instance has 4)"
    );
    remote.ping().unwrap();
    remote.terminate().unwrap();
    let pid = remote.host_pid();
    drop(remote);
    // The host ended with the instance.
    assert!(!std::path::Path::new(&format!("/proc/{pid}")).exists());
}
