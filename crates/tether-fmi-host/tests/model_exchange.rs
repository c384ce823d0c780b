//! Model-exchange instances in a host process (`Interface::ModelExchange`
//! with `Placement::Process`): the host integrates the FMU, each step is one
//! call, the results are those of the same instance in process bit for bit,
//! rollback included, and each fault (an error status, NaN derivatives, an
//! integrator that cannot reach its tolerance, a chattering event) is the
//! same one line as in process, naming the instance, the time and the cause.

use std::path::{Path, PathBuf};
use std::process::Command;

use tether_fmi::{
    instantiate, Error, Fmu, FmuInstance, InstanceOptions, Integrator, Interface, Placement,
};

/// Options for a model-exchange instance with the default integrator.
fn model_exchange() -> InstanceOptions {
    InstanceOptions::default().with_interface(Interface::ModelExchange(Integrator::default()))
}

/// In process, then in a host process.
fn placements() -> [Placement; 2] {
    [Placement::InProcess, Placement::Process { timeout: None }]
}

/// The model-exchange-only sawtooth of `tests/fixtures/fmi/me_sawtooth.c`
/// (its `mode` parameter misbehaves on purpose), compiled into `dir`.
fn sawtooth(dir: &Path) -> PathBuf {
    let root = dir.join("sawtooth");
    let binaries = root.join("binaries").join("linux64");
    std::fs::create_dir_all(&binaries).unwrap();
    std::fs::create_dir_all(root.join("resources")).unwrap();
    let source = dir.join("sawtooth.c");
    std::fs::write(
        &source,
        include_str!("../../../tests/fixtures/fmi/me_sawtooth.c"),
    )
    .unwrap();
    let compiler = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let status = Command::new(compiler)
        .args(["-shared", "-fPIC", "-O1", "-o"])
        .arg(binaries.join("sawtooth.so"))
        .arg(&source)
        .status()
        .expect("run the C compiler");
    assert!(status.success(), "compiling {} failed", source.display());
    std::fs::write(
        root.join("modelDescription.xml"),
        include_str!("../../../tests/fixtures/fmi/me_sawtooth.xml"),
    )
    .unwrap();
    root
}

/// A sawtooth instance with `mode` set, initialized at t = 0 where
/// `placement` says.
fn started(fmu: &Fmu, mode: i128, placement: Placement) -> Result<Box<dyn FmuInstance>, Error> {
    let mut a = instantiate(fmu, "saw", model_exchange(), placement)?;
    a.setup(Some(1e-8), 0.0, Some(5.0))?;
    a.enter_initialization()?;
    a.set_integers(&[2], &[mode])?;
    a.exit_initialization()?;
    Ok(a)
}

/// Steps of 0.25 (each followed by reading x) until an error or t = 5.
fn run(a: &mut dyn FmuInstance) -> Option<Error> {
    for n in 0..20 {
        let step = a.step(n as f64 * 0.25, 0.25);
        let mut x = [0.0];
        if let Err(e) = step.and_then(|()| a.get_reals(&[0], &mut x)) {
            return Some(e);
        }
    }
    None
}

/// The error that sawtooth `mode` ends with in process and in a host
/// process: the same error, the same line (asserted); returned as the host's.
fn fault(mode: i128) -> Error {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    let mut errors = Vec::new();
    for placement in placements() {
        let isolated = placement != Placement::InProcess;
        let e = match started(&fmu, mode, placement) {
            Ok(mut a) => {
                assert_eq!(a.is_remote(), isolated);
                run(&mut *a).unwrap_or_else(|| panic!("mode {mode} runs to the end"))
            }
            Err(e) => e,
        };
        let line = e.to_string();
        assert!(!line.contains('\n'), "{line}");
        errors.push(e);
    }
    assert_eq!(errors[0].to_string(), errors[1].to_string(), "mode {mode}");
    assert_eq!(
        format!("{:?}", errors[0]),
        format!("{:?}", errors[1]),
        "mode {mode}"
    );
    errors.pop().unwrap()
}

fn assert_naming(e: &Error, parts: &[&str]) {
    let line = e.to_string();
    for part in parts {
        assert!(line.contains(part), "{line:?} lacks {part:?}");
    }
}

/// fmi2GetDerivatives returns fmi2Error after t = 0.5 (mode 2): the FMU's
/// error, with its message, from the step that starts at 0.5.
#[test]
fn an_error_status_is_the_same_line_isolated() {
    let e = fault(2);
    assert!(
        matches!(e, Error::Failed { time, .. } if time > 0.5 && time < 0.75),
        "{e:?}"
    );
    assert_naming(
        &e,
        &[
            "fmi2GetDerivatives returned fmi2Error",
            "'saw'",
            "at t=0.5",
            "the derivative fails after t = 0.5",
        ],
    );
}

/// NaN derivatives after t = 0.5 (mode 4).
#[test]
fn nan_derivatives_are_the_same_line_isolated() {
    let e = fault(4);
    assert!(
        matches!(e, Error::ModelExchange { time, .. } if time > 0.5 && time < 0.75),
        "{e:?}"
    );
    assert_naming(
        &e,
        &[
            "model-exchange instance 'saw' stopped at t = 0.5",
            "fmi2GetDerivatives returned NaN for the derivative of continuous state 1 of 1",
        ],
    );
}

/// x runs to infinity at t = 0.9 (mode 5): the integrator's steps fall below
/// the resolution of time before it.
#[test]
fn an_integrator_that_cannot_reach_the_tolerance_is_the_same_line_isolated() {
    let e = fault(5);
    assert!(
        matches!(e, Error::ModelExchange { time, .. } if time > 0.75 && time < 0.9),
        "{e:?}"
    );
    assert_naming(
        &e,
        &[
            "model-exchange instance 'saw' stopped at t = 0.",
            "the integrator (bdf, rtol 0.00000001",
            "cannot reach the tolerance",
        ],
    );
}

/// Mode 1 asks for new discrete states forever, from the initialization on.
#[test]
fn a_chattering_event_is_the_same_line_isolated() {
    let e = fault(1);
    assert!(
        matches!(e, Error::ModelExchange { time, .. } if time == 0.0),
        "{e:?}"
    );
    assert_naming(
        &e,
        &[
            "model-exchange instance 'saw' stopped at t = 0",
            "more than 100 event iterations at this time (fmi2NewDiscreteStates): the model chatters",
        ],
    );
}

/// The sawtooth's events in a host process: the same bits as in process,
/// and each step with its read one round trip.
#[test]
fn an_isolated_step_is_one_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    let mut runs = Vec::new();
    for placement in placements() {
        let mut a = started(&fmu, 0, placement).unwrap();
        let before = a.round_trips();
        let mut rows = Vec::new();
        for n in 0..13 {
            a.step(n as f64 * 0.35, 0.35).unwrap();
            let mut x = [0.0];
            a.get_reals(&[0], &mut x).unwrap();
            rows.push(x[0].to_bits());
        }
        let mut events = [0];
        a.get_integers(&[3], &mut events).unwrap();
        assert_eq!(events[0], 4, "events at t = 1, 2, 3, 4");
        if a.is_remote() {
            assert_eq!(
                a.round_trips() - before,
                14,
                "13 steps and reads, the count"
            );
        }
        a.terminate().unwrap();
        runs.push(rows);
    }
    assert_eq!(runs[0], runs[1]);
}

/// The Reference BouncingBall (FMI 2.0 and 3.0) integrated in a host process
/// gives the bits it gives in process, across its first bounce, and a state
/// saved and restored in the host repeats the steps bit for bit; it answers
/// the model-exchange capabilities in both placements.
#[test]
fn isolated_results_and_rollback_equal_in_process_bit_for_bit() {
    for standard in ["fmi2", "fmi3"] {
        let Some(path) =
            tether_fmu_build::fixture_fmu(&format!("reference-fmus/{standard}/BouncingBall.fmu"))
        else {
            return;
        };
        let fmu = Fmu::open(path).unwrap();
        let md = fmu.model_description();
        let vrs = [
            md.value_reference("h").unwrap(),
            md.value_reference("v").unwrap(),
        ];
        let mut runs = Vec::new();
        for placement in placements() {
            let mut a = instantiate(&fmu, "bb", model_exchange(), placement).unwrap();
            // The instance in the host says what the one in process says.
            assert_eq!(
                a.capabilities(),
                tether_fmi::Capabilities::model_exchange(md),
                "{standard}"
            );
            a.setup(Some(1e-8), 0.0, Some(3.0)).unwrap();
            a.enter_initialization().unwrap();
            a.exit_initialization().unwrap();
            let mut rows = Vec::new();
            let mut steps = |a: &mut dyn FmuInstance, from: usize, to: usize| {
                for n in from..to {
                    a.step(n as f64 * 0.01, 0.01).unwrap();
                    let mut out = [0.0; 2];
                    a.get_reals(&vrs, &mut out).unwrap();
                    rows.push(out.map(f64::to_bits));
                }
            };
            steps(&mut *a, 0, 40);
            a.save(0).unwrap();
            steps(&mut *a, 40, 60);
            a.restore(0).unwrap();
            steps(&mut *a, 40, 60);
            a.free(0).unwrap();
            assert_eq!(rows[40..60], rows[60..80], "{standard}: the rollback");
            // The bounce (at 0.4515 s) is in the repeated steps.
            let v = |n: usize| f64::from_bits(rows[n][1]);
            assert!(v(44) < 0.0 && v(45) > 0.0, "{standard}: the bounce");
            a.terminate().unwrap();
            runs.push(rows);
        }
        assert_eq!(runs[0], runs[1], "{standard}: isolated against in process");
    }
}

/// An FMU without a `ModelExchange` element (the Reference BouncingBall's
/// with the element removed) is refused in one line when model exchange is
/// asked, in process and before a host is started; so are integrator
/// settings out of range.
#[test]
fn model_exchange_without_the_interface_is_refused_in_one_line() {
    let Some(path) = tether_fmu_build::fixture_fmu("reference-fmus/fmi2/BouncingBall.fmu") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut archive = zip::ZipArchive::new(std::fs::File::open(path).unwrap()).unwrap();
    archive.extract(dir.path()).unwrap();
    let xml_path = dir.path().join("modelDescription.xml");
    let xml = std::fs::read_to_string(&xml_path).unwrap();
    let start = xml.find("<ModelExchange").unwrap();
    let end = start + xml[start..].find("</ModelExchange>").unwrap() + "</ModelExchange>".len();
    std::fs::write(&xml_path, format!("{}{}", &xml[..start], &xml[end..])).unwrap();
    let fmu = Fmu::open(dir.path()).unwrap();
    assert!(fmu.model_description().model_exchange.is_none());
    for placement in placements() {
        let e = instantiate(&fmu, "bb", model_exchange(), placement.clone()).unwrap_err();
        assert!(matches!(e, Error::Unsupported { .. }), "{e:?}");
        assert_eq!(
            e.to_string(),
            "model 'BouncingBall' cannot run in Tether: it has no model-exchange interface (no <ModelExchange> element)"
        );
        let options =
            InstanceOptions::default().with_interface(Interface::ModelExchange(Integrator {
                rtol: Some(f64::NAN),
                ..Integrator::default()
            }));
        let sawtooth_dir = tempfile::tempdir().unwrap();
        let saw = Fmu::open(sawtooth(sawtooth_dir.path())).unwrap();
        let e = instantiate(&saw, "saw", options, placement).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the integrator on instance 'saw': rtol = NaN: expected a finite number > 0"
        );
    }
}

/// Instantiate requests a master of this version would not send, straight to
/// the host executable: an unknown interface or integration method,
/// integrator settings cut short or out of range. Each is answered with one
/// error line naming the instance, the host goes on, and a good request
/// after them instantiates.
#[test]
fn hostile_instantiate_requests_are_one_error_line() {
    use std::io::BufReader;
    use std::process::Stdio;
    use tether_fmi::remote::protocol::{self, op, In, Out};

    let dir = tempfile::tempdir().unwrap();
    let root = sawtooth(dir.path());
    let mut host = Command::new(env!("CARGO_BIN_EXE_tether-fmi-host"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut to = host.stdin.take().unwrap();
    let mut from = BufReader::new(host.stdout.take().unwrap());
    let mut frame = Vec::new();
    Out::default()
        .start(op::HELLO)
        .u32(protocol::VERSION)
        .u8(2)
        .u8(2)
        .send(&mut to)
        .unwrap();
    assert!(protocol::receive(&mut from, &mut frame).unwrap());
    assert_eq!(frame[0], protocol::OK);
    // An instantiate request whose interface is what `interface` writes.
    let request = |interface: &mut dyn FnMut(&mut Out)| {
        let mut out = Out::default();
        out.start(op::INSTANTIATE)
            .str(root.to_str().unwrap())
            .str("saw")
            .bool(false)
            .bool(false)
            .bool(false)
            .f64(0.0)
            .bool(false)
            .u32(0);
        interface(&mut out);
        out
    };
    let refused = "instance 'saw': its host refused the instantiate request: ";
    let out_of_range = Interface::ModelExchange(Integrator {
        atol: Some(-1.0),
        ..Integrator::default()
    });
    for (case, expected) in [
        (0, format!("{refused}an unknown interface 7")),
        (1, format!("{refused}an unknown integration method 'euler'")),
        (2, format!("{refused}a malformed message")),
        (3, format!("{refused}a malformed message")),
        (
            4,
            "the integrator on instance 'saw': atol = -1: expected a finite number > 0".into(),
        ),
    ] {
        let mut interface = |o: &mut Out| {
            match case {
                0 => o.u8(7),
                1 => o.u8(1).str("euler"),
                2 => o.u8(1).str("rk45").bool(true), // cut inside rtol
                3 => o,                              // no interface at all
                _ => o.interface(&out_of_range),
            };
        };
        request(&mut interface).send(&mut to).unwrap();
        assert!(protocol::receive(&mut from, &mut frame).unwrap());
        assert_eq!(frame[0], protocol::ERR, "{expected}");
        let mut reply = In::new(&frame[1..]);
        assert_eq!(reply.u32().unwrap(), 0);
        assert_eq!(reply.error("?").unwrap().to_string(), expected);
    }
    request(&mut |o: &mut Out| {
        o.interface(&Interface::ModelExchange(Integrator::default()));
    })
    .send(&mut to)
    .unwrap();
    assert!(protocol::receive(&mut from, &mut frame).unwrap());
    assert_eq!(frame[0], protocol::OK);
    drop(to);
    assert!(host.wait().unwrap().success());
}

/// A model-exchange instance on a remote host (`tether host --listen`, here
/// its library function on 127.0.0.1, the FMU already on the host): the
/// host integrates it, with the in-process bits, and its NaN derivatives are
/// the in-process line.
#[test]
fn a_remote_model_exchange_instance_integrates_on_its_host() {
    use std::os::unix::fs::PermissionsExt;
    use tether_fmi::remote::tcp::RemoteHost;

    let dir = tempfile::tempdir().unwrap();
    let root = sawtooth(dir.path());
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, "a-token-of-32-characters-for-me\n").unwrap();
    std::fs::set_permissions(&token_file, std::fs::Permissions::from_mode(0o600)).unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let address = format!("127.0.0.1:{port}");
    let options = tether_fmi_host::listen::ListenOptions {
        address: address.clone(),
        token_file: token_file.clone(),
        max_fmu_bytes: 1 << 20,
        max_frame_bytes: 1 << 20,
    };
    std::thread::spawn(move || tether_fmi_host::listen::listen(&options));
    let remote = Placement::Remote {
        timeout: Some(std::time::Duration::from_secs(30)),
        host: RemoteHost {
            address,
            token_file,
            fmu_on_host: Some(root.clone()),
        },
    };
    let fmu = Fmu::open(&root).unwrap();
    // The listener's thread may not be listening yet.
    let mut tries = 0;
    let mut a = loop {
        match started(&fmu, 0, remote.clone()) {
            Ok(a) => break a,
            Err(Error::HostStart { reason, .. }) if tries < 50 => {
                assert!(reason.contains("refused"), "{reason}");
                tries += 1;
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            Err(e) => panic!("{e}"),
        }
    };
    let mut local = started(&fmu, 0, Placement::InProcess).unwrap();
    assert!(a.is_remote());
    for instance in [&mut a, &mut local] {
        for n in 0..13 {
            instance.step(n as f64 * 0.35, 0.35).unwrap();
        }
    }
    let (mut x, mut y) = ([0.0], [0.0]);
    a.get_reals(&[0], &mut x).unwrap();
    local.get_reals(&[0], &mut y).unwrap();
    assert_eq!(x[0].to_bits(), y[0].to_bits());
    drop(a);
    let mut a = started(&fmu, 4, remote).unwrap();
    let mut local = started(&fmu, 4, Placement::InProcess).unwrap();
    let (remote_error, local_error) = (run(&mut *a).unwrap(), run(&mut *local).unwrap());
    assert!(matches!(remote_error, Error::ModelExchange { .. }));
    assert_eq!(remote_error.to_string(), local_error.to_string());
}

/// An isolated model-exchange step that hangs in fmi2GetDerivatives (mode 6,
/// from t = 0.5) is ended by the call time-out; the line names the
/// derivatives (an ME FMU has no fmi2DoStep) and the step's start.
#[test]
fn a_hanging_isolated_step_is_ended_by_the_call_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    let timeout = Some(std::time::Duration::from_millis(500));
    let mut a = started(&fmu, 6, Placement::Process { timeout }).unwrap();
    let started_at = std::time::Instant::now();
    let e = run(&mut *a).expect("the step from 0.5 hangs");
    assert!(started_at.elapsed().as_secs() < 10, "ended by the time-out");
    assert!(matches!(e, Error::CallTimeout { .. }), "{e:?}");
    assert_naming(
        &e,
        &[
            "instance 'saw'",
            "fmi2GetDerivatives at t=0.5 did not return within the call time-out of 0.5 s",
        ],
    );
    assert!(!e.to_string().contains('\n'));
}
