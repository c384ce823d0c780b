//! SSP in and out (docs/ssp.md): a hand-written SSD after the standard's
//! examples is read and runs like the equivalent system file; export and
//! import round-trip a system with constraints and signals bit for bit;
//! what Tether cannot honour is one clear line naming the element and line.

use std::path::{Path, PathBuf};

use tether_master::{MemoryRecorder, Simulation, SystemSpec};

fn fmu(name: &str) -> PathBuf {
    tether_fmu_build::workspace_fmu(name).expect("package the workspace FMU")
}

fn run(spec: &SystemSpec) -> MemoryRecorder {
    let mut sim = Simulation::new(spec).unwrap();
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
    rec
}

fn assert_same(a: &MemoryRecorder, b: &MemoryRecorder) {
    assert_eq!(a.columns, b.columns);
    assert_eq!(a.times.len(), b.times.len());
    for (ra, rb) in a.rows.iter().zip(&b.rows) {
        for (x, y) in ra.iter().zip(rb) {
            assert_eq!(x.to_bits(), y.to_bits(), "{x} vs {y}");
        }
    }
}

/// The nested fixture in a folder with the workspace FMUs and the .ssv in
/// resources/.
fn fixture() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ssp");
    std::fs::create_dir(dir.path().join("resources")).unwrap();
    let ssd = src.join("nested/SystemStructure.ssd");
    std::fs::copy(ssd, dir.path().join("SystemStructure.ssd")).unwrap();
    let ssv = src.join("controlled_mass/resources/mass.ssv");
    std::fs::copy(ssv, dir.path().join("resources/mass.ssv")).unwrap();
    for name in ["oscillator", "controller"] {
        std::fs::copy(fmu(name), dir.path().join(format!("resources/{name}.fmu"))).unwrap();
    }
    dir
}

const EQUIVALENT: &str = r#"
    name = "plant_and_controller"
    [experiment]
    stop = 0.5
    step = 1e-3

    [[instance]]
    name = "mass"
    fmu = "OSC"
    parameters = { m = 2.0, c = 800.0, d = 5.0, v0 = 0.0, exact = true }

    [[instance]]
    name = "control_pi"
    fmu = "CTRL"
    parameters = { kp = 500.0, ki = 2000.0 }

    [[connection]]
    from = "mass.x"
    to = "control_pi.y"

    [[connection]]
    from = "control_pi.u"
    to = "mass.F_ext"
"#;

#[test]
fn a_hand_written_ssd_runs_like_the_equivalent_system_file() {
    let dir = fixture();
    let loaded = tether_ssp::read(dir.path(), Some(1e-3), None).unwrap();
    assert_eq!(
        loaded.skipped,
        ["com.example.layout (SystemStructure.ssd:58)"]
    );
    let spec = &loaded.spec;
    let names: Vec<&str> = spec.instances.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(
        names,
        ["mass", "control_pi"],
        "the nested system is flattened"
    );
    assert_eq!(spec.experiment.stop, 0.5);
    let text = EQUIVALENT
        .replace(
            "OSC",
            &dir.path()
                .join("resources/oscillator.fmu")
                .display()
                .to_string(),
        )
        .replace(
            "CTRL",
            &dir.path()
                .join("resources/controller.fmu")
                .display()
                .to_string(),
        );
    let reference = SystemSpec::from_toml(&text).unwrap();
    let sorted = |mut c: Vec<tether_master::ConnectionSpec>| {
        c.sort_by(|a, b| a.from.cmp(&b.from));
        c
    };
    assert_eq!(
        sorted(spec.connections.clone()),
        sorted(reference.connections.clone())
    );
    assert_eq!(
        spec.instances[0].parameters,
        reference.instances[0].parameters
    );
    assert_same(&run(spec), &run(&reference));
    // The same through the SSD's own path.
    let by_file =
        tether_ssp::read(&dir.path().join("SystemStructure.ssd"), Some(1e-3), None).unwrap();
    assert_eq!(by_file.spec.instances.len(), 2);
}

#[test]
fn without_a_step_reading_fails_with_one_line() {
    let dir = fixture();
    let err = tether_ssp::read(dir.path(), None, None)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("no macro-step size") && err.contains("--step"),
        "{err}"
    );
}

/// Every element Tether cannot honour is named with its line.
#[test]
fn unsupported_elements_are_errors_naming_element_and_line() {
    let cases = [
        (
            r#"<ssd:Connection startElement="mass" startConnector="x" endElement="control" endConnector="measured"/>"#,
            r#"<ssd:Connection startElement="mass" startConnector="x" endElement="control" endConnector="measured"><ssc:BooleanMappingTransformation/></ssd:Connection>"#,
            "SystemStructure.ssd:54: <ssc:BooleanMappingTransformation> in <ssd:Connection> is not supported",
        ),
        (
            r#"<ssd:ParameterBinding source="resources/mass.ssv"/>"#,
            r#"<ssd:ParameterBinding source="resources/mass.ssv" prefix="mass."/>"#,
            "SystemStructure.ssd:19: <ssd:ParameterBinding> prefix=\"mass.\" is not supported",
        ),
        (
            r#"<ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>"#,
            r#"<ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit><ssc:Unit name="s"><ssc:BaseUnit s="1"/></ssc:Unit>"#,
            "",
        ),
        (
            r#"<ssc:Real unit="m"/></ssd:Connector>
          <ssd:Connector name="command""#,
            r#"<ssc:Real unit="s"/></ssd:Connector>
          <ssd:Connector name="command""#,
            "units 's' and 'm' differ and there is no conversion between them",
        ),
        (
            r#"source="resources/controller.fmu""#,
            r#"source="resources/controller.fmu" implementation="ScheduledExecution""#,
            "implementation=\"ScheduledExecution\" is not supported",
        ),
    ];
    let dir = fixture();
    let ssd = dir.path().join("SystemStructure.ssd");
    let original = std::fs::read_to_string(&ssd).unwrap();
    let mut text = original.clone();
    for (from, to, expected) in cases {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
        std::fs::write(&ssd, &text).unwrap();
        let result = tether_ssp::read(dir.path(), Some(1e-3), None);
        if expected.is_empty() {
            result.unwrap();
        } else {
            let err = result.err().expect("rejected").to_string();
            assert!(err.contains(expected), "{err}");
            assert!(!err.contains('\n'), "{err}");
        }
        text = original.clone();
        if expected.is_empty() {
            text = text.replacen(from, to, 1);
        }
    }
}

/// SSP's `implementation` of a component is its `fmi_type`: read, run
/// (the oscillator through its model-exchange interface) and written back.
#[test]
fn a_component_s_implementation_is_its_fmi_type() {
    let dir = fixture();
    let ssd = dir.path().join("SystemStructure.ssd");
    let text = std::fs::read_to_string(&ssd).unwrap();
    let from = r#"source="resources/oscillator.fmu">"#;
    assert!(text.contains(from));
    let text = text.replacen(
        from,
        r#"source="resources/oscillator.fmu" implementation="ModelExchange">"#,
        1,
    );
    std::fs::write(&ssd, text).unwrap();
    let loaded = tether_ssp::read(dir.path(), Some(1e-3), Some(0.1)).unwrap();
    let kinds: Vec<_> = loaded
        .spec
        .instances
        .iter()
        .map(|i| (i.name.as_str(), i.fmi_type))
        .collect();
    assert!(
        kinds.contains(&("mass", tether_master::InterfaceChoice::ModelExchange)),
        "{kinds:?}"
    );
    assert!(
        kinds
            .iter()
            .filter(|(n, _)| *n != "mass")
            .all(|(_, k)| *k == tether_master::InterfaceChoice::Auto),
        "{kinds:?}"
    );
    let mut sim = tether_master::Simulation::new(&loaded.spec).unwrap();
    sim.run(&mut [], &mut |_, _| {}).unwrap();
    let out = dir.path().join("again.ssp");
    tether_ssp::write(&loaded.spec, &out).unwrap();
    let again = tether_ssp::read(&out, Some(1e-3), Some(0.1)).unwrap();
    let kinds_again: Vec<_> = again
        .spec
        .instances
        .iter()
        .map(|i| (i.name.as_str(), i.fmi_type))
        .collect();
    assert_eq!(kinds, kinds_again);
}

/// The paper's oscillator pair under PI control (a joint-free constraint, a
/// controller without FMU states, signals): exported to .ssp, read back and
/// imported to a system file, it gives the same results bit for bit.
#[test]
fn export_and_import_round_trip_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/controlled_oscillator.toml");
    let text = std::fs::read_to_string(example)
        .unwrap()
        .replace(
            "../target/fmus/oscillator.fmu",
            &fmu("oscillator").display().to_string(),
        )
        .replace(
            "../target/fmus/controller.fmu",
            &fmu("controller").display().to_string(),
        )
        .replace("stop = 1.0", "stop = 0.2");
    let toml = dir.path().join("system.toml");
    std::fs::write(&toml, text).unwrap();
    let spec = SystemSpec::from_file(&toml).unwrap();
    let ssp = dir.path().join("system.ssp");
    tether_ssp::write(&spec, &ssp).unwrap();
    let loaded = tether_ssp::read(&ssp, None, None).unwrap();
    assert!(loaded.skipped.is_empty());
    let imported = dir.path().join("imported/system.toml");
    std::fs::create_dir(dir.path().join("imported")).unwrap();
    tether_ssp::write_toml(&loaded, &imported).unwrap();
    let again = SystemSpec::from_file(&imported).unwrap();
    for other in [&loaded.spec, &again] {
        assert_eq!(other.instances.len(), spec.instances.len());
        for (a, b) in other.instances.iter().zip(&spec.instances) {
            assert_eq!((&a.name, &a.parameters), (&b.name, &b.parameters));
        }
        assert_eq!(other.connections, spec.connections);
        assert_eq!(other.signals, spec.signals);
        assert_eq!(other.method, spec.method);
        assert_eq!(
            toml::to_string(&other.constraints).ok(),
            toml::to_string(&spec.constraints).ok()
        );
        assert_eq!(
            other.experiment.step.to_bits(),
            spec.experiment.step.to_bits()
        );
    }
    let reference = run(&spec);
    assert_same(&run(&loaded.spec), &reference);
    assert_same(&run(&again), &reference);
}

/// Every example (joints in the plane and in 3D, constraints, signals)
/// survives export and import unchanged, key for key; the double pendulum's
/// results from the archive are the system file's bit for bit.
#[test]
fn every_example_round_trips_through_ssp() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let mut examples: Vec<PathBuf> = std::fs::read_dir(root.join("examples"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        // Their member is an FMU that `tether fmu export` writes first; the
        // CLI's tests/fmu_export.rs runs them.
        .filter(|p| {
            !p.ends_with("nested_three_masses.toml") && !p.ends_with("exported_pair_feedback.toml")
        })
        .collect();
    examples.sort();
    assert!(examples.len() >= 10);
    let fmus: Vec<(String, PathBuf)> = ["oscillator", "controller", "link", "body3d", "lti"]
        .iter()
        .map(|n| (format!("../target/fmus/{n}.fmu"), fmu(n)))
        .collect();
    for example in examples {
        let mut text = std::fs::read_to_string(&example).unwrap();
        for (from, to) in &fmus {
            text = text.replace(from, &to.display().to_string());
        }
        let toml = dir.path().join("system.toml");
        std::fs::write(&toml, &text).unwrap();
        let spec = SystemSpec::from_file(&toml).unwrap();
        let ssp = dir.path().join("system.ssp");
        tether_ssp::write(&spec, &ssp).unwrap();
        let loaded = tether_ssp::read(&ssp, None, None).unwrap();
        let mut back = loaded.spec.clone();
        for (a, b) in back.instances.iter_mut().zip(&spec.instances) {
            assert_eq!(
                std::fs::read(&a.fmu).unwrap(),
                std::fs::read(&b.fmu).unwrap(),
                "{}: the FMU in the archive",
                example.display()
            );
            a.fmu = b.fmu.clone();
        }
        // `[export]` (docs/fmu-export.md) and `[output]` (what a run
        // records) are Tether's own; an SSD has no place for them.
        let mut without_export = spec.clone();
        without_export.export = None;
        without_export.output = Default::default();
        assert_eq!(
            toml::to_string(&back).unwrap(),
            toml::to_string(&without_export).unwrap(),
            "{}",
            example.display()
        );
        if example.ends_with("double_pendulum.toml") {
            let mut short = spec.clone();
            short.experiment.stop = 0.05;
            let mut from_ssp = loaded.spec.clone();
            from_ssp.experiment.stop = 0.05;
            assert_same(&run(&from_ssp), &run(&short));
        }
    }
}

/// An SSP whose components are FMI 3.0 FMUs (the kit's FMI 3.0 builds of the
/// same models) runs like the system file with their FMI 2.0 builds, bit for
/// bit (inputs held over the step, k = 0): the rigid oscillator pair and the
/// double pendulum's joints.
#[test]
fn an_ssp_of_fmi3_components_runs_like_the_fmi2_system_bit_for_bit() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    for (example, model) in [
        ("oscillator.toml", "oscillator"),
        ("double_pendulum.toml", "link"),
    ] {
        let text = std::fs::read_to_string(root.join("examples").join(example))
            .unwrap()
            .replace("stop = 1.0", "stop = 0.1")
            .replace("stop = 2.0", "stop = 0.1");
        let from = format!("../target/fmus/{model}.fmu");
        let with = |fmu: PathBuf| {
            let toml = dir
                .path()
                .join(fmu.with_extension("toml").file_name().unwrap());
            std::fs::write(&toml, text.replace(&from, &fmu.display().to_string())).unwrap();
            SystemSpec::from_file(&toml).unwrap()
        };
        let fmi2 = with(fmu(model));
        let fmi3 = with(tether_fmu_build::workspace_fmu3(model).unwrap());
        let ssp = dir.path().join("system.ssp");
        tether_ssp::write(&fmi3, &ssp).unwrap();
        let loaded = tether_ssp::read(&ssp, None, None).unwrap();
        let reference = run(&fmi2);
        assert_eq!(reference.times.len(), 101, "{example}");
        assert_same(&run(&loaded.spec), &reference);
    }
}
