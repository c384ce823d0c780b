//! The exported FMU's `modelDescription.xml`: FMI 2.0 co-simulation, the
//! `[export]` variables as Real parameters, inputs and outputs, with the
//! member FMUs' units and descriptions. Its GUID is the hash of the system
//! file in `resources/`, which the binary checks at `fmi2Instantiate`.

use std::fmt::Write;

use tether_fmu_kit::xml::{escape, text_guid, units_and_log_categories};
use tether_master::{ExportKind, ExportVariable, SystemSpec};

/// The GUID of an exported system: the hash of its system file's text.
pub fn guid(system_text: &str) -> String {
    text_guid(system_text)
}

/// What the model description says besides the variables.
pub struct Capabilities {
    /// `canGetAndSetFMUstate` and `canSerializeFMUstate`: every member can
    /// save, restore and serialize its state.
    pub state: bool,
    /// Per variable, the inputs (indices into the variables) an output
    /// depends on directly (`Simulation::export_dependencies`).
    pub dependencies: Vec<Vec<usize>>,
}

/// The `modelDescription.xml` of `spec` exported with `variables` (value
/// reference = index).
pub fn model_description(
    spec: &SystemSpec,
    system_text: &str,
    variables: &[ExportVariable],
    capabilities: &Capabilities,
) -> String {
    let export = spec.export.as_ref();
    let name = export.map_or("system", |e| e.model_name.as_str());
    let e = &spec.experiment;
    let yes = |b: bool| if b { "true" } else { "false" };
    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="2.0" modelName="{}" guid="{}" description="{}" generationTool="tether {}" variableNamingConvention="flat" numberOfEventIndicators="0">"#,
        escape(name),
        guid(system_text),
        escape(&format!(
            "Tether system{} exported as one FMU: its members and system file are in resources/",
            spec.name
                .as_deref()
                .map(|n| format!(" '{n}'"))
                .unwrap_or_default()
        )),
        env!("CARGO_PKG_VERSION"),
    );
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{}" needsExecutionTool="false" canHandleVariableCommunicationStepSize="true" canInterpolateInputs="true" maxOutputDerivativeOrder="0" canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="{}" canSerializeFMUstate="{}" providesDirectionalDerivative="false"/>"#,
        escape(name),
        yes(capabilities.state),
        yes(capabilities.state),
    );
    let mut units: Vec<&str> = variables.iter().filter_map(|v| v.unit.as_deref()).collect();
    units.sort_unstable();
    units.dedup();
    units_and_log_categories(&mut x, &units);
    let _ = writeln!(
        x,
        r#"  <DefaultExperiment startTime="{:?}" stopTime="{:?}" stepSize="{:?}"/>"#,
        e.start,
        spec.end_time(),
        e.step
    );
    let _ = writeln!(x, "  <ModelVariables>");
    for (vr, v) in variables.iter().enumerate() {
        let (causality, variability, initial) = match v.kind {
            ExportKind::Parameter => ("parameter", "fixed", r#" initial="exact""#),
            ExportKind::Input => ("input", "continuous", ""),
            ExportKind::Output => ("output", "continuous", r#" initial="calculated""#),
        };
        let description = v
            .description
            .as_deref()
            .map(|d| {
                format!(
                    r#" description="{}""#,
                    escape(&format!("{d} ({})", v.target))
                )
            })
            .unwrap_or_else(|| format!(r#" description="{}""#, escape(&v.target)));
        let _ = writeln!(
            x,
            r#"    <ScalarVariable name="{}" valueReference="{vr}"{description} causality="{causality}" variability="{variability}"{initial}>"#,
            escape(&v.name)
        );
        let unit = v
            .unit
            .as_deref()
            .map(|u| format!(r#" unit="{}""#, escape(u)))
            .unwrap_or_default();
        let start = v
            .start
            .map(|s| format!(r#" start="{s:?}""#))
            .unwrap_or_default();
        let _ = writeln!(x, r#"      <Real{unit}{start}/>"#);
        let _ = writeln!(x, "    </ScalarVariable>");
    }
    let _ = writeln!(x, "  </ModelVariables>");
    let _ = writeln!(x, "  <ModelStructure>");
    let outputs: Vec<usize> = (0..variables.len())
        .filter(|&i| variables[i].kind == ExportKind::Output)
        .collect();
    // An output depends directly on the inputs that reach it through the
    // members' feedthrough, the signal connections and the coupling
    // (`Simulation::export_dependencies`); at initialization also on the
    // parameters. Indices are 1-based and ascending.
    let list = |mut indices: Vec<usize>| {
        indices.sort_unstable();
        indices.dedup();
        let indices: Vec<String> = indices.iter().map(|i| (i + 1).to_string()).collect();
        indices.join(" ")
    };
    let parameters = (0..variables.len()).filter(|&i| variables[i].kind == ExportKind::Parameter);
    let parameters: Vec<usize> = parameters.collect();
    let inputs_of = |i: usize| {
        capabilities
            .dependencies
            .get(i)
            .cloned()
            .unwrap_or_default()
    };
    if !outputs.is_empty() {
        let _ = writeln!(x, "    <Outputs>");
        for &i in &outputs {
            let dependencies = list(inputs_of(i));
            let _ = writeln!(
                x,
                r#"      <Unknown index="{}" dependencies="{dependencies}"/>"#,
                i + 1
            );
        }
        let _ = writeln!(x, "    </Outputs>");
        let _ = writeln!(x, "    <InitialUnknowns>");
        for &i in &outputs {
            let dependencies = list([parameters.clone(), inputs_of(i)].concat());
            let _ = writeln!(
                x,
                r#"      <Unknown index="{}" dependencies="{dependencies}"/>"#,
                i + 1
            );
        }
        let _ = writeln!(x, "    </InitialUnknowns>");
    }
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}
