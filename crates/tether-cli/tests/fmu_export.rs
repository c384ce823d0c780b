//! `tether fmu export` (docs/fmu-export.md): the rigid oscillator pair
//! exported as one FMI 2.0 co-simulation FMU and run by fmpy gives `tether
//! run`'s numbers bit for bit; fmpy validates it, repeats a step from a
//! saved state bit for bit (also through serialized bytes read by a fresh
//! instance; cut or changed bytes are refused), gets fmi2Error for a step off the grid and runs
//! two independent instances in one process (tests/fmpy/exported_fmu.py).
//! Bad `[export]` tables get one clear line each.

mod common;

use std::path::{Path, PathBuf};

use common::{error_line, oscillator, read_csv, success, tether};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn the_exported_rigid_pair_runs_in_fmpy_bit_for_bit_as_tether_run() {
    oscillator();
    let dir = tempfile::tempdir().unwrap();
    let fmu = dir.path().join("rigid_pair.fmu");
    let ours = dir.path().join("run.csv");
    let theirs = dir.path().join("fmpy.csv");
    let system = "examples/rigid_pair_export.toml";
    let fmu_arg = fmu.to_str().unwrap();
    success(&tether(
        &["fmu", "export", system, "--out", fmu_arg],
        &root(),
    ));
    let ours_arg = ours.to_str().unwrap();
    success(&tether(&["run", system, "--out", ours_arg], &root()));
    let args = [fmu.as_os_str(), theirs.as_os_str()];
    fmpy_checks(
        "exported_fmu.py",
        &args,
        &[
            "validate: no problems",
            "state: repeated step identical",
            "doStep of 1.5 H: fmi2Error",
            "two instances: independent",
            "wrong GUID: NULL, logged",
            "member error: fmi2Error, forwarded",
            "repeated step identical in a fresh instance",
            "serialized state cut short: fmi2Error",
            "serialized state one byte changed: fmi2Error",
            "serialized state empty: fmi2Error",
            "dependencies: a and lambda on F, x and v on none",
            "feedthrough: a and lambda follow F at once",
            "interpolation: ramp within",
        ],
    );
    same_columns(&ours, &theirs, &PAIR_COLUMNS, 1001);
}

/// The rigid pair exported as FMI 3.0 (`--fmi 3`): fmpy validates it, its
/// `simulate_fmu` gives `tether run`'s numbers bit for bit, get/set and
/// serialized state repeat a step bit for bit, bad calls give fmi3Error
/// with a message naming the fmi3 function, a ramp input set in fmpy's
/// intermediate update callback reaches every inner step at its own time
/// (tests/fmpy/exported_fmu3.py);
/// nested as an instance of another system (examples/nested_three_masses.toml)
/// it gives the FMI 2.0 export's CSV bit for bit.
#[test]
fn the_fmi3_export_runs_in_fmpy_as_tether_run_and_nests_as_the_fmi2_export() {
    let osc = oscillator();
    let dir = tempfile::tempdir().unwrap();
    let system = "examples/rigid_pair_export.toml";
    let fmu = |version: &str| dir.path().join(format!("rigid_pair{version}.fmu"));
    for version in ["2", "3"] {
        let out = fmu(version);
        let export = ["fmu", "export", system, "--out", out.to_str().unwrap()];
        let export: Vec<&str> = match version {
            "3" => export.into_iter().chain(["--fmi", "3"]).collect(),
            _ => export.to_vec(),
        };
        success(&tether(&export, &root()));
    }
    let ours = dir.path().join("run.csv");
    let theirs = dir.path().join("fmpy.csv");
    success(&tether(
        &["run", system, "--out", ours.to_str().unwrap()],
        &root(),
    ));
    let args = [fmu("3").into_os_string(), theirs.clone().into_os_string()];
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    fmpy_checks(
        "exported_fmu3.py",
        &args,
        &[
        "validate: no problems",
        "state: repeated step identical",
        "repeated step identical in a fresh instance",
        "serialized state cut short: fmi3Error, logged: fmi3DeserializeFMUState: not a state of this FMU",
        "doStep of 1.5 H: fmi3Error, logged: fmi3DoStep: communication step",
        "unsupported function: fmi3Error, logged: fmi3GetInt32: not supported",
        "wrong token: NULL, logged: fmi3InstantiateCoSimulation:",
        "intermediate update: 1000 callbacks at the inner steps' starts",
        ],
    );
    same_columns(&ours, &theirs, &PAIR_COLUMNS, 1001);
    let nested = std::fs::read_to_string(root().join("examples/nested_three_masses.toml")).unwrap();
    let mut csvs = Vec::new();
    for version in ["2", "3"] {
        let text = nested
            .replace(
                "\"../target/rigid_pair.fmu\"",
                &format!("{:?}", fmu(version)),
            )
            .replace("\"../target/fmus/oscillator.fmu\"", &format!("{osc:?}"));
        let system = dir.path().join(format!("nested{version}.toml"));
        std::fs::write(&system, text).unwrap();
        let csv = dir.path().join(format!("nested{version}.csv"));
        let run = [
            "run",
            system.to_str().unwrap(),
            "--out",
            csv.to_str().unwrap(),
        ];
        success(&tether(&run, dir.path()));
        csvs.push(std::fs::read_to_string(&csv).unwrap());
    }
    assert_eq!(csvs[0].lines().count(), 1002);
    assert!(
        csvs[0] == csvs[1],
        "the nested FMI 3.0 export differs from the FMI 2.0 one"
    );
}

/// Runs the fmpy script `script` (tests/fmpy) with `args`: it must succeed and
/// report every one of `checks`.
fn fmpy_checks(script: &str, args: &[&std::ffi::OsStr], checks: &[&str]) {
    let out = tether_tests::fmpy::run_script(script, args).expect("run fmpy");
    let report = script_report(&out);
    for check in checks {
        assert!(report.contains(check), "{check}: {report}");
    }
}

/// The report (stdout) of an fmpy script that must have succeeded, shown.
fn script_report(out: &std::process::Output) -> String {
    let report = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!("{report}");
    assert!(
        out.status.success(),
        "{report}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    report
}

/// Zips `dir` as the archive `out` (an `.ssp`).
fn zip_dir(dir: &Path, out: &Path) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(out).unwrap());
    let options = zip::write::SimpleFileOptions::default();
    for entry in ["SystemStructure.ssd", "resources/oscillator.fmu"] {
        zip.start_file(entry, options).unwrap();
        let bytes = std::fs::read(dir.join(entry)).unwrap();
        std::io::Write::write_all(&mut zip, &bytes).unwrap();
    }
    zip.finish().unwrap();
}

/// An `.ssp` without `[export]` (examples/rigid_pair_ssp packed as an
/// archive with its member FMU in resources/: the rigid pair, the root
/// system's connectors F, m1, x, v, a) exported: the
/// FMU's variables are those connectors, fmpy validates it and its
/// `simulate_fmu` gives `tether run`'s numbers of the same `.ssp` bit for
/// bit (tests/fmpy/exported_fmu.py).
#[test]
fn an_ssp_exports_with_its_root_connectors_as_the_interface() {
    let osc = oscillator();
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("ssp");
    std::fs::create_dir_all(folder.join("resources")).unwrap();
    let ssd = std::fs::read_to_string(root().join("examples/rigid_pair_ssp/SystemStructure.ssd"))
        .unwrap()
        .replace(
            "../../target/fmus/oscillator.fmu",
            "resources/oscillator.fmu",
        );
    std::fs::write(folder.join("SystemStructure.ssd"), ssd).unwrap();
    std::fs::copy(&osc, folder.join("resources/oscillator.fmu")).unwrap();
    let ssp = dir.path().join("rigid_pair.ssp");
    zip_dir(&folder, &ssp);
    let fmu = dir.path().join("rigid_pair_ssp.fmu");
    let ours = dir.path().join("run.csv");
    let theirs = dir.path().join("fmpy.csv");
    let (ssp_arg, fmu_arg) = (ssp.to_str().unwrap(), fmu.to_str().unwrap());
    let export = tether(&["fmu", "export", ssp_arg, "--out", fmu_arg], dir.path());
    success(&export);
    let said = String::from_utf8_lossy(&export.stderr).to_string()
        + &String::from_utf8_lossy(&export.stdout);
    assert!(said.contains("1 parameters, 1 inputs, 3 outputs"), "{said}");
    success(&tether(
        &["run", ssp_arg, "--out", ours.to_str().unwrap()],
        dir.path(),
    ));
    let args = [fmu.as_os_str(), theirs.as_os_str()];
    fmpy_checks("exported_fmu.py", &args, &["validate: no problems"]);
    // `tether ssp import` writes the same interface as an [export] table.
    let imported = dir.path().join("imported/system.toml");
    let import = [
        "ssp",
        "import",
        ssp_arg,
        "--out",
        imported.to_str().unwrap(),
    ];
    success(&tether(&import, dir.path()));
    let spec = tether_master::SystemSpec::from_file(&imported).unwrap();
    let export = spec.export.expect("[export] from the root connectors");
    assert_eq!(export.model_name, "rigid_pair_ssp");
    let names: Vec<(&str, &str, &str)> = export.variables().collect();
    assert_eq!(
        names,
        [
            ("parameter", "m1", "mass1.m"),
            ("input", "F", "mass1.F_ext"),
            ("output", "x", "mass1.x"),
            ("output", "v", "mass1.v"),
            ("output", "a", "mass1.a"),
        ]
    );
    assert_eq!(read_csv(&theirs).0, ["time", "x", "v", "a"]);
    same_columns(&ours, &theirs, &PAIR_COLUMNS[..4], 501);
}

/// A system whose member runs isolated (`isolation = "process"`) exported:
/// the host program travels in the FMU (`resources/tether-fmi-host`); fmpy
/// (which unpacks without exec bits) runs a copy of the `.fmu` alone in a
/// temporary folder with a PATH and environment that hold nothing of the
/// build tree, and gives `tether run`'s numbers bit for bit
/// (tests/fmpy/exported_fmu.py, all its checks).
#[test]
fn an_exported_system_with_an_isolated_member_runs_from_the_fmu_alone() {
    let dir = tempfile::tempdir().unwrap();
    let (fmu, ours) = export_and_run(dir.path(), "isolated", |text| {
        let text = text.replace(
            "name = \"mass2\"\n",
            "name = \"mass2\"\nisolation = \"process\"\n",
        );
        assert!(text.contains("isolation = \"process\""));
        text
    });
    let mut archive = zip::ZipArchive::new(std::fs::File::open(&fmu).unwrap()).unwrap();
    let names: Vec<String> = (0..archive.len())
        .map(|i| archive.by_index(i).unwrap().name().unwrap().to_string())
        .collect();
    assert!(
        names.iter().any(|n| n == "resources/tether-fmi-host"),
        "{names:?}"
    );
    // The .fmu alone, elsewhere; no TETHER_FMI_HOST, no build tree on PATH.
    let alone = tempfile::tempdir().unwrap();
    let copy = alone.path().join("isolated.fmu");
    std::fs::copy(&fmu, &copy).unwrap();
    let theirs = alone.path().join("fmpy.csv");
    let python = tether_tests::fmpy::python().expect("fmpy");
    let out = std::process::Command::new(python)
        .env_clear()
        .env("PATH", "/usr/bin:/bin")
        .env("HOME", alone.path())
        .current_dir(alone.path())
        .arg(tether_tests::fmpy::script("exported_fmu.py"))
        .args([&copy, &theirs])
        .output()
        .unwrap();
    script_report(&out);
    same_columns(&ours, &theirs, &PAIR_COLUMNS, 1001);
}

/// The rigid pair with both members on the oscillator's model-exchange
/// interface, exported: fmpy validates it and its run gives `tether run`'s
/// numbers bit for bit; a step repeated from a saved state (the members'
/// time, continuous states and FMU states), also through serialized bytes
/// in a fresh instance, is identical.
#[test]
fn an_exported_system_of_model_exchange_members_runs_in_fmpy_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let me = "fmi_type = \"model_exchange\"\nintegrator = { method = \"rk45\", rtol = 1e-10 }\n";
    let (fmu, ours) = export_and_run(dir.path(), "me", |text| {
        let text = text
            .replace("name = \"mass1\"\n", &format!("name = \"mass1\"\n{me}"))
            .replace("name = \"mass2\"\n", &format!("name = \"mass2\"\n{me}"));
        assert_eq!(text.matches("model_exchange").count(), 2);
        text
    });
    let theirs = dir.path().join("fmpy.csv");
    fmpy_checks(
        "exported_fmu.py",
        &[fmu.as_os_str(), theirs.as_os_str()],
        &[
            "validate: no problems",
            "state: repeated step identical",
            "repeated step identical in a fresh instance",
        ],
    );
    same_columns(&ours, &theirs, &PAIR_COLUMNS, 1001);
}

/// examples/rigid_pair_export.toml on the workspace oscillator, through
/// `edit`, as `<dir>/<name>.toml`: exported to `<dir>/<name>.fmu` and run by
/// `tether run` into `<dir>/run.csv`; the FMU's and the CSV's paths.
fn export_and_run(dir: &Path, name: &str, edit: impl Fn(String) -> String) -> (PathBuf, PathBuf) {
    let osc = oscillator();
    let text = std::fs::read_to_string(root().join("examples/rigid_pair_export.toml")).unwrap();
    let text = edit(text.replace("\"../target/fmus/oscillator.fmu\"", &format!("{osc:?}")));
    let system = dir.join(format!("{name}.toml"));
    std::fs::write(&system, text).unwrap();
    let fmu = dir.join(format!("{name}.fmu"));
    let ours = dir.join("run.csv");
    let system_arg = system.to_str().unwrap();
    success(&tether(
        &["fmu", "export", system_arg, "--out", fmu.to_str().unwrap()],
        dir,
    ));
    success(&tether(
        &["run", system_arg, "--out", ours.to_str().unwrap()],
        dir,
    ));
    (fmu, ours)
}

/// The rigid pair with `export` as its [export] table.
fn system_with(dir: &Path, export: &str) -> PathBuf {
    let fmu = oscillator();
    let text = format!(
        "[experiment]\nstop = 0.1\nstep = 1e-3\n\n\
         [[instance]]\nname = \"mass1\"\nfmu = {fmu:?}\n\n\
         [[instance]]\nname = \"mass2\"\nfmu = {fmu:?}\n\n\
         [[constraint]]\nname = \"link\"\nposition = \"mass2.x - mass1.x\"\n\
         velocity = \"mass2.v - mass1.v\"\nacceleration = \"mass2.a - mass1.a\"\n\
         drives = \"mass1.F - mass2.F\"\n\n{export}"
    );
    let path = dir.join("system.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn bad_export_tables_get_one_clear_line_each() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.fmu");
    let head = "[export]\nmodel_name = \"pair\"\n";
    for (export, expected) in [
        (
            "[[export.input]]\nname = \"F\"\nto = \"mass1.F_ex\"\n",
            "did you mean",
        ),
        (
            "[[export.input]]\nname = \"F\"\nto = \"mass1.F\"\n",
            "'mass1.F' is driven by the coupling",
        ),
        (
            "[[export.output]]\nname = \"x\"\nfrom = \"mass1.x\"\n[[export.output]]\nname = \"x\"\nfrom = \"mass2.x\"\n",
            "name 'x' is used twice",
        ),
        (
            "[[export.output]]\nname = \"x\"\nfrom = \"mass1.xx\"\n",
            "'mass1.xx' is not a column of the system; did you mean 'mass1.x'",
        ),
        (
            "[[export.parameter]]\nname = \"m\"\nto = \"mass1.x\"\n",
            "'mass1.x' is a Real output, not a parameter",
        ),
    ] {
        let system = system_with(dir.path(), &format!("{head}{export}"));
        let args = ["fmu", "export", system.to_str().unwrap(), "--out", out.to_str().unwrap()];
        let line = error_line(&tether(&args, dir.path()));
        assert!(line.contains(expected), "{expected}: {line}");
        assert!(!out.exists());
    }
    let system = system_with(dir.path(), "");
    let args = [
        "fmu",
        "export",
        system.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    let line = error_line(&tether(&args, dir.path()));
    assert!(line.contains("no [export] table"), "{line}");
}

/// x(t) of one mass m on a spring c and damper d from x = 0, v = v0.
fn damped(m: f64, c: f64, d: f64, v0: f64, t: f64) -> f64 {
    let delta = d / (2.0 * m);
    let omega = (c / m - delta * delta).sqrt();
    (-delta * t).exp() * v0 / omega * (omega * t).sin()
}

/// `[step_control]` exported (examples/rigid_pair_adaptive_export.toml,
/// output grid 0.0123 s): fmpy's `simulate_fmu` with that communication step,
/// which is no multiple of the experiment's step 1e-3, gives `tether run`'s
/// time, x, v, a and lambda at every point of the grid bit for bit (the
/// inner steps land on the same points; the last one on the stop time).
/// With a communication step of 0.0071 s, unrelated to both, the inner
/// steps land on t + h too; x follows the closed form of the joined masses
/// (m = 3, c = 2000, d = 20) within the step control's tolerance there as
/// `tether run` does on its own grid.
#[test]
fn an_exported_system_with_adaptive_steps_takes_any_communication_step() {
    oscillator();
    let dir = tempfile::tempdir().unwrap();
    let fmu = dir.path().join("rigid_pair_adaptive.fmu");
    let system = "examples/rigid_pair_adaptive_export.toml";
    let fmu_arg = fmu.to_str().unwrap();
    success(&tether(
        &["fmu", "export", system, "--out", fmu_arg],
        &root(),
    ));
    let ours = dir.path().join("run.csv");
    success(&tether(
        &["run", system, "--out", ours.to_str().unwrap()],
        &root(),
    ));
    let simulate = |step: &str, out: &Path| {
        let args = [
            fmu.as_os_str(),
            out.as_os_str(),
            "--stop".as_ref(),
            "1".as_ref(),
            "--step".as_ref(),
            step.as_ref(),
        ];
        let run = tether_tests::fmpy::run_script("simulate.py", &args).expect("run fmpy");
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
    };
    let theirs = dir.path().join("fmpy.csv");
    simulate("0.0123", &theirs);
    // 0, 0.0123, …, 0.9963 and the stop time.
    let (h1, r1) = same_columns(&ours, &theirs, &PAIR_COLUMNS, 83);
    let x = h1.iter().position(|c| c == "mass1.x").unwrap();
    let closed = |t: f64| damped(3.0, 2000.0, 20.0, 100.0, t);
    let run_error = r1
        .iter()
        .map(|r| (r[x] - closed(r[0])).abs())
        .fold(0.0, f64::max);
    let other = dir.path().join("other.csv");
    simulate("0.0071", &other);
    let (h3, r3) = read_csv(&other);
    let j = h3.iter().position(|c| c == "x").unwrap();
    // 0, 0.0071, …, 0.9940 and the stop time.
    assert_eq!(r3.len(), 142);
    let error = r3
        .iter()
        .map(|r| (r[j] - closed(r[0])).abs())
        .fold(0.0, f64::max);
    eprintln!("max |x - closed form|: tether run {run_error:e}, fmpy h = 0.0071 {error:e}");
    // Amplitude 4.5 m, rtol = 1e-6: both within 5e-6 m (the fixed-step pair
    // with H = 1e-3 is off by 1.9e-5 m).
    assert!(run_error < 5e-6, "{run_error:e}");
    assert!(error < 5e-6, "{error:e}");
}

/// Nesting: the exported pair as an instance of another Tether system,
/// joined by a rigid link to a third mass (examples/nested_three_masses.toml):
/// the three joined masses follow the closed form of one mass with the
/// summed m = 1 + 2 + 3, c = 3·1000, d = 3·10 (docs/algorithm.md).
#[test]
fn the_exported_pair_nested_with_a_third_mass_follows_the_closed_form() {
    oscillator();
    let dir = tempfile::tempdir().unwrap();
    let fmu = dir.path().join("rigid_pair.fmu");
    let fmu_arg = fmu.to_str().unwrap();
    let export = [
        "fmu",
        "export",
        "examples/rigid_pair_export.toml",
        "--out",
        fmu_arg,
    ];
    success(&tether(&export, &root()));
    let text = std::fs::read_to_string(root().join("examples/nested_three_masses.toml")).unwrap();
    let osc = oscillator();
    let text = text
        .replace("\"../target/rigid_pair.fmu\"", &format!("{fmu:?}"))
        .replace("\"../target/fmus/oscillator.fmu\"", &format!("{osc:?}"));
    let system = dir.path().join("nested.toml");
    std::fs::write(&system, text).unwrap();
    let csv = dir.path().join("nested.csv");
    let run = [
        "run",
        system.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ];
    success(&tether(&run, dir.path()));
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 1001);
    for column in ["pair.x", "mass3.x"] {
        let j = header.iter().position(|c| c == column).unwrap();
        let worst = rows
            .iter()
            .map(|r| (r[j] - damped(6.0, 3000.0, 30.0, 100.0, r[0])).abs())
            .fold(0.0, f64::max);
        // Amplitude 4.5 m; the un-nested rigid pair (examples/oscillator.toml
        // method and step) is off its closed form by 1.9e-5 m.
        eprintln!("{column}: max |x - closed form| = {worst:e}");
        assert!(worst < 1e-4, "{column}: {worst:e}");
    }
}

/// A direct-feedthrough loop through the exported FMU
/// (examples/exported_pair_feedback.toml): the pair of
/// examples/rigid_pair_accel_export.toml, whose acceleration a its
/// ModelStructure declares as depending on the force input F, with a fed back
/// as F = −3·a through the workspace's LTI block as a pure gain. Tether finds
/// the loop from the declared dependency, solves it at every macro point
/// (`[signals] solver = "newton"`) and passes F as a polynomial, which the
/// exported FMU interpolates; the pair then moves as one mass of
/// m = 1 + 2 + 3 with c = 2000, d = 20: within 2e-5 m of that closed form
/// (amplitude 4.8 m), the loop closed at every recorded point to 1e-8.
#[test]
fn an_outer_system_solves_a_loop_through_the_exported_feedthrough() {
    oscillator();
    let dir = tempfile::tempdir().unwrap();
    let fmu = dir.path().join("rigid_pair_accel.fmu");
    let export = [
        "fmu",
        "export",
        "examples/rigid_pair_accel_export.toml",
        "--out",
        fmu.to_str().unwrap(),
    ];
    success(&tether(&export, &root()));
    let text =
        std::fs::read_to_string(root().join("examples/exported_pair_feedback.toml")).unwrap();
    let lti = tether_fmu_build::workspace_fmu("lti").expect("package the LTI FMU");
    let text = text
        .replace("\"../target/rigid_pair_accel.fmu\"", &format!("{fmu:?}"))
        .replace("\"../target/fmus/lti.fmu\"", &format!("{lti:?}"));
    let system = dir.path().join("loop.toml");
    std::fs::write(&system, text).unwrap();
    let csv = dir.path().join("loop.csv");
    let run = [
        "run",
        system.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ];
    let out = tether(&run, dir.path());
    success(&out);
    let notes = String::from_utf8_lossy(&out.stderr);
    assert!(notes.contains("loop"), "no loop found: {notes}");
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 1001);
    let x = header.iter().position(|c| c == "pair.x").unwrap();
    let (a, y) = (
        header.iter().position(|c| c == "pair.a").unwrap(),
        header.iter().position(|c| c == "gain.y").unwrap(),
    );
    let worst = rows
        .iter()
        .map(|r| (r[x] - damped(6.0, 2000.0, 20.0, 100.0, r[0])).abs())
        .fold(0.0, f64::max);
    let loop_residual = rows
        .iter()
        .map(|r| (r[y] + 3.0 * r[a]).abs() / r[a].abs().max(1.0))
        .fold(0.0, f64::max);
    eprintln!("max |x - closed form| = {worst:e}, max |F + 3 a| / |a| = {loop_residual:e}");
    assert!(loop_residual < 1e-8, "{loop_residual:e}");
    assert!(worst < 2e-5, "{worst:e}");
}

/// libcosim (the Open Simulation Platform's master, through libcosimpy) runs
/// the exported rigid pair in a signal-coupled system: its position measured
/// by the workspace's PI controller, whose command is the pair's force
/// input, exchanged at macro points with inputs held (Jacobi) in both
/// masters. The system goes to libcosim as an SSP (tether-ssp) and to
/// `tether run` as a system file; both give the same numbers at every step
/// bit for bit. The step is 2⁻⁹ s (1953125 ns): libcosim counts time in
/// nanoseconds and passes h = t_{n+1} − t_n of the converted time points,
/// which is H exactly only when the points are exact doubles. (With H = 1e-3
/// the controller's h is off by ulps from step 22 on, and over 0.5 s the runs
/// differ by up to 2e-10 relative in x, v and u, 2e-7 in the multiplier.)
#[test]
fn libcosim_runs_the_exported_pair_under_control_as_tether_run_does() {
    let Some(python) = tether_tests::tools::libcosimpy() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let step = "0.001953125";
    let pair = std::fs::read_to_string(root().join("examples/rigid_pair_export.toml")).unwrap();
    let pair = pair
        .replace("step = 1e-3", &format!("step = {step}"))
        .replace(
            "\"../target/fmus/oscillator.fmu\"",
            &format!("{:?}", oscillator()),
        );
    let pair_toml = dir.path().join("rigid_pair_export.toml");
    std::fs::write(&pair_toml, pair).unwrap();
    let fmu = dir.path().join("rigid_pair.fmu");
    let export = [
        "fmu",
        "export",
        pair_toml.to_str().unwrap(),
        "--out",
        fmu.to_str().unwrap(),
    ];
    success(&tether(&export, dir.path()));
    let controller = tether_fmu_build::workspace_fmu("controller").expect("package the controller");
    let text = format!(
        "name = \"controlled pair\"\n\
         [experiment]\nstop = 0.5\nstep = {step}\n\n\
         [signals]\nscheme = \"jacobi\"\n\n\
         [[instance]]\nname = \"pair\"\nfmu = {fmu:?}\n\n\
         [[instance]]\nname = \"ctrl\"\nfmu = {controller:?}\n\
         parameters = {{ kp = 1000.0, ki = 10000.0, r = 0.1 }}\n\n\
         [[connection]]\nfrom = \"pair.x\"\nto = \"ctrl.y\"\n\n\
         [[connection]]\nfrom = \"ctrl.u\"\nto = \"pair.F\"\n"
    );
    let system = dir.path().join("controlled_pair.toml");
    std::fs::write(&system, text).unwrap();
    let csv = dir.path().join("tether.csv");
    let run = [
        "run",
        system.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ];
    success(&tether(&run, dir.path()));
    // libcosim reads unpacked SSP folders.
    let spec = tether_master::SystemSpec::from_file(&system).unwrap();
    let ssp = dir.path().join("controlled_pair.ssp");
    tether_ssp::write(&spec, &ssp).unwrap();
    let unpacked = dir.path().join("unpacked");
    zip::ZipArchive::new(std::fs::File::open(&ssp).unwrap())
        .unwrap()
        .extract(&unpacked)
        .unwrap();
    let theirs = dir.path().join("libcosim.csv");
    let columns = ["pair.x", "pair.v", "pair.lambda", "ctrl.u"];
    let out = std::process::Command::new(&python)
        .arg(root().join("tests/libcosim/run_ssp.py"))
        .args([
            unpacked.as_os_str(),
            step.as_ref(),
            "0.5".as_ref(),
            theirs.as_os_str(),
        ])
        .args(columns)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "libcosim failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (h1, ours) = read_csv(&csv);
    let (h2, theirs) = read_csv(&theirs);
    // libcosim's rows begin after the first step.
    assert_eq!(ours.len(), 257);
    assert_eq!(theirs.len(), 256);
    for column in ["time"].iter().chain(&columns) {
        let i = h1.iter().position(|c| c == column).unwrap();
        let j = h2.iter().position(|c| c == column).unwrap();
        for (a, b) in ours[1..].iter().zip(&theirs) {
            assert_eq!(
                a[i].to_bits(),
                b[j].to_bits(),
                "{column} at t = {}: Tether {}, libcosim {}",
                a[0],
                a[i],
                b[j]
            );
        }
    }
}

/// fmpy's columns of the exported pair (time, x, v, a, lambda) and the
/// `tether run` columns they stand for.
const PAIR_COLUMNS: [(&str, &str); 5] = [
    ("time", "time"),
    ("x", "mass1.x"),
    ("v", "mass1.v"),
    ("a", "mass1.a"),
    ("lambda", "link.lambda"),
];

/// `rows` rows in both CSVs, and each of `columns` (fmpy's name, `tether
/// run`'s column) in `theirs` equal to its column in `ours` bit for bit;
/// returns `ours` (header, rows).
fn same_columns(
    ours: &Path,
    theirs: &Path,
    columns: &[(&str, &str)],
    rows: usize,
) -> (Vec<String>, Vec<Vec<f64>>) {
    let (h1, r1) = read_csv(ours);
    let (h2, r2) = read_csv(theirs);
    assert_eq!(r1.len(), rows);
    assert_eq!(r1.len(), r2.len(), "same rows");
    for &(name, column) in columns {
        let i = h1.iter().position(|c| c == column).unwrap();
        let j = h2.iter().position(|c| c == name).unwrap();
        for (a, b) in r1.iter().zip(&r2) {
            assert_eq!(a[i].to_bits(), b[j].to_bits(), "{name} at t = {}", a[0]);
        }
    }
    (h1, r1)
}

/// An `[[export.output]]` without `name` is named as its column: the exported
/// FMU nested as instance `pair` gives `pair.mass1.x`, `pair.link.lambda`, and
/// one `--map 'pair.*=*'` compares them with the system's own run (bit for bit).
#[test]
fn exported_outputs_named_as_their_columns_compare_with_one_map() {
    let dir = tempfile::tempdir().unwrap();
    let system = system_with(
        dir.path(),
        "[export]\nmodel_name = \"pair\"\n\
         [[export.output]]\nfrom = \"mass1.x\"\n\
         [[export.output]]\nfrom = \"link.lambda\"\n",
    );
    let fmu = dir.path().join("pair.fmu");
    let s = system.to_str().unwrap();
    success(&tether(
        &["fmu", "export", s, "--out", fmu.to_str().unwrap()],
        dir.path(),
    ));
    success(&tether(&["run", s, "--out", "run.csv"], dir.path()));
    let outer = dir.path().join("outer.toml");
    std::fs::write(
        &outer,
        format!(
            "[experiment]\nstop = 0.1\nstep = 1e-3\n\n[method]\nkind = \"explicit\"\nmu = 1e-3\n\n\
             [[instance]]\nname = \"pair\"\nfmu = {fmu:?}\n"
        ),
    )
    .unwrap();
    success(&tether(
        &["run", outer.to_str().unwrap(), "--out", "outer.csv"],
        dir.path(),
    ));
    let header = std::fs::read_to_string(dir.path().join("outer.csv")).unwrap();
    assert!(
        header.starts_with("time,pair.mass1.x,pair.link.lambda\n"),
        "{}",
        header.lines().next().unwrap()
    );
    let out = tether(
        &["compare", "outer.csv", "run.csv", "--map", "pair.*=*"],
        dir.path(),
    );
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{table}");
    assert!(table.contains("pair.mass1.x=mass1.x "), "{table}");
    assert!(table.contains("pair.link.lambda=link.lambda "), "{table}");
    assert!(table.contains("largest relative deviation 0 "), "{table}");
}
