//! FMUs for the reliability tests, built at test time:
//!
//! - the *faulty oscillator*: a real mass-spring-damper FMU in C
//!   (`tests/fixtures/fmi/faulty_oscillator.c`) whose `fmi2DoStep` or `fmi2SetFMUstate`
//!   returns Discard, Error or Fatal from a chosen time on (chosen by parameters), and
//!   whose capability flags are chosen per archive;
//! - copies of the workspace oscillator FMU with edits to its `modelDescription.xml`
//!   (e.g. a capability flag switched off), repackaged as a new archive.

use std::path::{Path, PathBuf};

use crate::fmi::{compile_shared_library, oscillator_fmu, unzip, zip_directory};

/// Capability flags written into the faulty oscillator's `<CoSimulation>` element.
#[derive(Debug, Clone, Copy)]
pub struct Capabilities {
    /// `canGetAndSetFMUstate`.
    pub get_and_set_state: bool,
    /// `canBeInstantiatedOnlyOncePerProcess`.
    pub only_once_per_process: bool,
}

impl Default for Capabilities {
    fn default() -> Self {
        Capabilities {
            get_and_set_state: true,
            only_once_per_process: false,
        }
    }
}

/// The faulty oscillator's modelDescription.xml with these capability flags.
pub fn faulty_model_description(caps: Capabilities) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="faulty" guid="{{faulty-oscillator}}"
  description="Oscillator m x'' = F - c x - d v that fails on demand" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="faulty" canHandleVariableCommunicationStepSize="true"
    canGetAndSetFMUstate="{gs}" canInterpolateInputs="false" maxOutputDerivativeOrder="0"
    canBeInstantiatedOnlyOncePerProcess="{once}"/>
  <ModelVariables>
    <ScalarVariable name="m" valueReference="0" causality="parameter" variability="fixed" initial="exact"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="c" valueReference="1" causality="parameter" variability="fixed" initial="exact"><Real start="1000" min="0"/></ScalarVariable>
    <ScalarVariable name="d" valueReference="2" causality="parameter" variability="fixed" initial="exact"><Real start="10" min="0"/></ScalarVariable>
    <ScalarVariable name="x0" valueReference="3" causality="parameter" variability="fixed" initial="exact"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="v0" valueReference="4" causality="parameter" variability="fixed" initial="exact"><Real start="100"/></ScalarVariable>
    <ScalarVariable name="F" valueReference="5" causality="input" variability="continuous"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="x" valueReference="6" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="v" valueReference="7" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="a" valueReference="8" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="fail_time" valueReference="9" causality="parameter" variability="fixed" initial="exact"><Real start="1e300"/></ScalarVariable>
    <ScalarVariable name="fail_status" valueReference="10" causality="parameter" variability="fixed" initial="exact"><Integer start="3" min="2" max="4"/></ScalarVariable>
    <ScalarVariable name="fail_in" valueReference="11" causality="parameter" variability="fixed" initial="exact"><Integer start="0" min="0" max="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="7"/><Unknown index="8"/><Unknown index="9"/></Outputs>
    <InitialUnknowns><Unknown index="7"/><Unknown index="8"/><Unknown index="9"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"#,
        gs = caps.get_and_set_state,
        once = caps.only_once_per_process,
    )
}

/// Compiles the faulty oscillator and packages it as `<dir>/<name>.fmu` with `caps`.
pub fn faulty_fmu(dir: &Path, name: &str, caps: Capabilities) -> PathBuf {
    let root = dir.join(format!("{name}-unpacked"));
    let binaries = root.join("binaries").join("linux64");
    std::fs::create_dir_all(&binaries).expect("mkdir binaries");
    compile_shared_library(
        &binaries,
        "faulty",
        include_str!("../fixtures/fmi/faulty_oscillator.c"),
        &[],
    );
    std::fs::remove_file(binaries.join("faulty.c")).expect("remove the C source");
    std::fs::write(
        root.join("modelDescription.xml"),
        faulty_model_description(caps),
    )
    .expect("write modelDescription.xml");
    let archive = dir.join(format!("{name}.fmu"));
    zip_directory(&root, &archive);
    std::fs::remove_dir_all(&root).expect("remove the unpacked copy");
    archive
}

/// A copy of the workspace oscillator FMU at `<dir>/<name>.fmu` whose
/// `modelDescription.xml` went through `edit` (which must change it).
pub fn edited_oscillator(dir: &Path, name: &str, edit: impl Fn(&str) -> String) -> PathBuf {
    edited_fmu(&oscillator_fmu(), dir, name, edit)
}

/// A copy of the FMU `source` at `<dir>/<name>.fmu` whose
/// `modelDescription.xml` went through `edit` (which must change it).
pub fn edited_fmu(source: &Path, dir: &Path, name: &str, edit: impl Fn(&str) -> String) -> PathBuf {
    let root = dir.join(format!("{name}-unpacked"));
    unzip(source, &root);
    let xml_path = root.join("modelDescription.xml");
    let xml = std::fs::read_to_string(&xml_path).expect("read modelDescription.xml");
    let edited = edit(&xml);
    assert_ne!(edited, xml, "the edit changed nothing");
    std::fs::write(&xml_path, edited).expect("write modelDescription.xml");
    let archive = dir.join(format!("{name}.fmu"));
    zip_directory(&root, &archive);
    std::fs::remove_dir_all(&root).expect("remove the unpacked copy");
    archive
}
