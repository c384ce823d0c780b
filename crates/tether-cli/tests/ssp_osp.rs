//! OSP's annotations in SSP (type `com.opensimulationplatform`, as libcosim
//! reads them, docs/ssp.md): the macro step of `osp:FixedStepAlgorithm`, the
//! components' `osp:StepSizeHint`, the others noted as ignored; and the
//! annotation `tether ssp export` writes. On the hand-written SSD of
//! tests/fixtures/ssp/controlled_mass with the workspace FMUs.

use std::path::Path;
use std::process::{Command, Output};

const OSP: &str = r#"xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations""#;

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tether")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The controlled mass in `dir` with `experiment` as the default
/// experiment's annotations and `mass` as the component `mass`'s.
fn system(dir: &Path, experiment: &str, mass: &str) {
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/ssp/controlled_mass");
    std::fs::create_dir_all(dir.join("resources")).unwrap();
    std::fs::copy(
        fixture.join("resources/mass.ssv"),
        dir.join("resources/mass.ssv"),
    )
    .unwrap();
    for name in ["oscillator", "controller"] {
        let fmu = tether_fmu_build::workspace_fmu(name).unwrap();
        std::fs::copy(fmu, dir.join(format!("resources/{name}.fmu"))).unwrap();
    }
    let ssd = std::fs::read_to_string(fixture.join("SystemStructure.ssd"))
        .unwrap()
        .replace(
            r#"version="1.0" name="controlled_mass">"#,
            &format!(r#"{OSP} version="1.0" name="controlled_mass">"#),
        )
        .replace(
            r#"<ssd:DefaultExperiment startTime="0.0" stopTime="0.5"/>"#,
            &format!(
                r#"<ssd:DefaultExperiment startTime="0.0" stopTime="0.5">
    <ssd:Annotations>
      <ssc:Annotation type="com.opensimulationplatform">
{experiment}
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>"#
            ),
        )
        .replace(
            r#"<ssd:ParameterBinding source="resources/mass.ssv"/>
        </ssd:ParameterBindings>"#,
            &format!(
                r#"<ssd:ParameterBinding source="resources/mass.ssv"/>
        </ssd:ParameterBindings>
        <ssd:Annotations>
          <ssc:Annotation type="com.opensimulationplatform">{mass}</ssc:Annotation>
        </ssd:Annotations>"#
            ),
        );
    std::fs::write(dir.join("SystemStructure.ssd"), ssd).unwrap();
}

const ALGORITHM: &str =
    r#"<osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="1e-3"/></osp:Algorithm>"#;

fn times(csv: &Path) -> Vec<f64> {
    std::fs::read_to_string(csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect()
}

/// Without `--step`, the macro step is OSP's `baseStepSize`; the run equals
/// the one with `--step` bit for bit.
#[test]
fn the_osp_base_step_is_the_macro_step() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    system(d, ALGORITHM, "");
    let out = tether(&["run", ".", "--out", "osp.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("note:"), "{}", stderr(&out));
    let t = times(&d.join("osp.csv"));
    assert_eq!(t.len(), 501);
    assert_eq!(t[1], 1e-3);
    let out = tether(&["run", ".", "--step", "1e-3", "--out", "step.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        std::fs::read(d.join("osp.csv")).unwrap(),
        std::fs::read(d.join("step.csv")).unwrap()
    );
    // `tether ssp import` takes it too.
    let out = tether(&["ssp", "import", ".", "-o", "system.toml"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let toml = std::fs::read_to_string(d.join("system.toml")).unwrap();
    assert!(toml.contains("step = 0.001"), "{toml}");
}

/// A `StepSizeHint` gives the instance its own step n·H, n = max(1,
/// ⌈hint/H⌉) as libcosim computes it: equal to the system file's `step`
/// key, bit for bit; a hint that is not n·H is noted.
#[test]
fn a_step_size_hint_is_the_instances_step() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    system(d, ALGORITHM, r#"<osp:StepSizeHint value="0.003"/>"#);
    let out = tether(&["run", ".", "--out", "hint.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("note:"), "{}", stderr(&out));
    let out = tether(&["ssp", "import", ".", "-o", "system.toml"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let toml = std::fs::read_to_string(d.join("system.toml")).unwrap();
    assert!(toml.contains("step = 0.003"), "{toml}");
    let out = tether(&["run", "system.toml", "--out", "toml.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        std::fs::read(d.join("hint.csv")).unwrap(),
        std::fs::read(d.join("toml.csv")).unwrap()
    );
    // 0.0025 is no multiple of H: n = 3, as libcosim, with a note.
    system(d, ALGORITHM, r#"<osp:StepSizeHint value="0.0025"/>"#);
    let out = tether(&["run", ".", "--out", "out.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stderr(&out);
    let notes = notes(&text);
    assert_eq!(notes.len(), 1, "{text}");
    assert!(
        notes[0].starts_with("note: SystemStructure.ssd:")
            && notes[0].ends_with(
                ": component 'mass': OSP's StepSizeHint 0.0025 is not a multiple of H = 0.001: \
                 it steps at 3·H = 0.003, as libcosim does"
            ),
        "{}",
        notes[0]
    );
    assert_eq!(
        std::fs::read(d.join("out.csv")).unwrap(),
        std::fs::read(d.join("hint.csv")).unwrap()
    );
}

/// A hint equal to H is what every instance does: accepted, no line; one
/// below H steps at H (n = 1, as libcosim), with a note.
#[test]
fn a_step_size_hint_of_h_is_accepted_and_one_below_is_noted() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    system(d, ALGORITHM, r#"<osp:StepSizeHint value="1e-3"/>"#);
    let out = tether(&["run", ".", "--out", "out.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("note:"), "{}", stderr(&out));
    system(d, ALGORITHM, r#"<osp:StepSizeHint value="4e-4"/>"#);
    let out = tether(&["run", ".", "--out", "out.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let notes = notes(&stderr(&out));
    assert_eq!(notes.len(), 1, "{}", stderr(&out));
    assert!(
        notes[0].starts_with("note: SystemStructure.ssd:")
            && notes[0].ends_with(
                ": component 'mass': OSP's StepSizeHint 0.0004 is not a multiple of H = 0.001: \
                 it steps at 1·H = 0.001, as libcosim does"
            ),
        "{}",
        notes[0]
    );
}

/// OSP's other annotations: one note naming them, the run as without them.
#[test]
fn other_osp_annotations_are_ignored_with_one_note() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let experiment = format!("{ALGORITHM}<osp:RealTime factor=\"1\"/>");
    system(d, &experiment, r#"<osp:Decoration color="red"/>"#);
    let out = tether(&["run", ".", "--out", "out.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let notes = notes(&stderr(&out));
    assert_eq!(notes.len(), 1, "{}", stderr(&out));
    let line = &notes[0];
    assert!(
        line.starts_with(
            "note: SystemStructure.ssd: OSP annotations Tether does not use, ignored: <osp:Decoration> (line "
        ) && line.contains("<osp:RealTime> (line "),
        "{line}"
    );
    assert_eq!(times(&d.join("out.csv")).len(), 501);
}

/// A refused baseStepSize names the element.
#[test]
fn a_base_step_that_is_not_a_time_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    system(
        d,
        r#"<osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="-1"/></osp:Algorithm>"#,
        "",
    );
    let out = tether(&["run", ".", "--out", "out.csv"], d);
    assert_eq!(out.status.code(), Some(1));
    let text = stderr(&out);
    assert_eq!(text.lines().count(), 1, "{text}");
    assert!(
        text.starts_with("error: SystemStructure.ssd:")
            && text
                .trim_end()
                .ends_with(": <osp:FixedStepAlgorithm> baseStepSize=\"-1\": expected a time > 0"),
        "{text}"
    );
}

/// `tether ssp export` writes the macro step and the instances' own steps
/// as OSP's annotations, which Tether reads back (and libcosim runs:
/// tests/libcosim_ssp.rs).
#[test]
fn ssp_export_writes_the_osp_base_step() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    system(d, ALGORITHM, r#"<osp:StepSizeHint value="0.002"/>"#);
    let out = tether(&["ssp", "import", ".", "-o", "system.toml"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = tether(&["ssp", "export", "system.toml", "-o", "out.ssp"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let mut archive =
        zip::ZipArchive::new(std::fs::File::open(d.join("out.ssp")).unwrap()).unwrap();
    let mut ssd = String::new();
    std::io::Read::read_to_string(
        &mut archive.by_name("SystemStructure.ssd").unwrap(),
        &mut ssd,
    )
    .unwrap();
    assert!(
        ssd.contains(r#"<ssc:Annotation type="com.opensimulationplatform" xmlns:osp="#)
            && ssd.contains(r#"<osp:FixedStepAlgorithm baseStepSize="0.001"/>"#)
            && ssd.contains(r#"<osp:StepSizeHint value="0.002"/>"#),
        "{ssd}"
    );
    let out = tether(&["run", "out.ssp", "--out", "again.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = tether(&["run", "system.toml", "--out", "toml.csv"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        std::fs::read(d.join("again.csv")).unwrap(),
        std::fs::read(d.join("toml.csv")).unwrap()
    );
}

/// The CLI's notes, each with its wrapped lines (indented, docs/run-summary.md)
/// joined back into one.
fn notes(text: &str) -> Vec<String> {
    let mut notes: Vec<String> = Vec::new();
    let mut in_note = false;
    for line in text.lines() {
        if line.starts_with("note:") {
            notes.push(line.to_string());
            in_note = true;
        } else if in_note && line.starts_with("  ") {
            let last = notes.last_mut().expect("a note before its continuation");
            last.push(' ');
            last.push_str(line.trim_start());
        } else {
            in_note = false;
        }
    }
    notes
}
