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
    let yes = |b: bool| if b { "true" } else { "false" };
    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="2.0" {} guid="{}" variableNamingConvention="flat" numberOfEventIndicators="0">"#,
        header(spec),
        guid(system_text),
    );
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{}" needsExecutionTool="false" canHandleVariableCommunicationStepSize="true" canInterpolateInputs="true" maxOutputDerivativeOrder="0" canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="{}" canSerializeFMUstate="{}" providesDirectionalDerivative="false"/>"#,
        escape(name),
        yes(capabilities.state),
        yes(capabilities.state),
    );
    units_and_experiment(&mut x, spec, variables);
    let _ = writeln!(x, "  <ModelVariables>");
    for (vr, v) in variables.iter().enumerate() {
        let (causality, variability, initial) = match v.kind {
            ExportKind::Parameter => ("parameter", "fixed", r#" initial="exact""#),
            ExportKind::Input => ("input", "continuous", ""),
            ExportKind::Output => ("output", "continuous", r#" initial="calculated""#),
        };
        let description = description_attribute(v);
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
    let structure = structure(variables, &capabilities.dependencies);
    if !structure.is_empty() {
        let index = |list: &[usize]| {
            list.iter()
                .map(|i| (i + 1).to_string())
                .collect::<Vec<_>>()
                .join(" ")
        };
        let _ = writeln!(x, "    <Outputs>");
        for o in &structure {
            let _ = writeln!(
                x,
                r#"      <Unknown index="{}" dependencies="{}"/>"#,
                o.output + 1,
                index(&o.stepping)
            );
        }
        let _ = writeln!(x, "    </Outputs>");
        let _ = writeln!(x, "    <InitialUnknowns>");
        for o in &structure {
            let _ = writeln!(
                x,
                r#"      <Unknown index="{}" dependencies="{}"/>"#,
                o.output + 1,
                index(&o.initial)
            );
        }
        let _ = writeln!(x, "    </InitialUnknowns>");
    }
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}

/// ` description="…"`: the member variable's description and what the
/// variable sets or reads.
fn description_attribute(v: &ExportVariable) -> String {
    let text = match &v.description {
        Some(d) => format!("{d} ({})", v.target),
        None => v.target.clone(),
    };
    format!(r#" description="{}""#, escape(&text))
}

/// The `<fmiModelDescription …>` attributes both versions share besides
/// the version and the GUID: the model name, the description and the tool.
/// The units the variables use, the log categories and the DefaultExperiment
/// (the same elements in FMI 2.0 and 3.0).
fn units_and_experiment(x: &mut String, spec: &SystemSpec, variables: &[ExportVariable]) {
    let mut units: Vec<&str> = variables.iter().filter_map(|v| v.unit.as_deref()).collect();
    units.sort_unstable();
    units.dedup();
    units_and_log_categories(x, &units);
    let e = &spec.experiment;
    let _ = writeln!(
        x,
        r#"  <DefaultExperiment startTime="{:?}" stopTime="{:?}" stepSize="{:?}"/>"#,
        e.start,
        spec.end_time(),
        e.step
    );
}

fn header(spec: &SystemSpec) -> String {
    let export = spec.export.as_ref();
    let name = export.map_or("system", |e| e.model_name.as_str());
    format!(
        r#"modelName="{}" description="{}" generationTool="tether {}""#,
        escape(name),
        escape(&format!(
            "Tether system{} exported as one FMU: its members and system file are in resources/",
            spec.name
                .as_deref()
                .map(|n| format!(" '{n}'"))
                .unwrap_or_default()
        )),
        env!("CARGO_PKG_VERSION"),
    )
}

/// The FMI 3.0 `modelDescription.xml` of `spec` exported with `variables`
/// (value reference = index; `time`, the independent variable, after
/// them): Float64 variables, the same structure, units, default experiment
/// and capabilities as the FMI 2.0 one, the GUID as `instantiationToken`.
pub fn model_description_fmi3(
    spec: &SystemSpec,
    system_text: &str,
    variables: &[ExportVariable],
    capabilities: &Capabilities,
) -> String {
    let name = spec
        .export
        .as_ref()
        .map_or("system", |e| e.model_name.as_str());
    let yes = |b: bool| if b { "true" } else { "false" };
    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="3.0" {} instantiationToken="{}" variableNamingConvention="flat">"#,
        header(spec),
        guid(system_text),
    );
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{}" needsExecutionTool="false" canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="{}" canSerializeFMUState="{}" providesDirectionalDerivatives="false" providesAdjointDerivatives="false" providesPerElementDependencies="false" canHandleVariableCommunicationStepSize="true" maxOutputDerivativeOrder="0" providesIntermediateUpdate="true" canReturnEarlyAfterIntermediateUpdate="false" hasEventMode="false" providesEvaluateDiscreteStates="false"/>"#,
        escape(name),
        yes(capabilities.state),
        yes(capabilities.state),
    );
    units_and_experiment(&mut x, spec, variables);
    let _ = writeln!(x, "  <ModelVariables>");
    for (vr, v) in variables.iter().enumerate() {
        let kind = match v.kind {
            ExportKind::Parameter => {
                r#" causality="parameter" variability="fixed" initial="exact""#
            }
            ExportKind::Input => {
                r#" causality="input" variability="continuous" intermediateUpdate="true""#
            }
            ExportKind::Output => {
                r#" causality="output" variability="continuous" initial="calculated""#
            }
        };
        let unit = v
            .unit
            .as_deref()
            .map(|u| format!(r#" unit="{}""#, escape(u)))
            .unwrap_or_default();
        let start = v
            .start
            .filter(|_| v.kind != ExportKind::Output)
            .map(|s| format!(r#" start="{s:?}""#))
            .unwrap_or_default();
        let _ = writeln!(
            x,
            r#"    <Float64 name="{}" valueReference="{vr}"{}{kind}{unit}{start}/>"#,
            escape(&v.name),
            description_attribute(v),
        );
    }
    let _ = writeln!(
        x,
        r#"    <Float64 name="time" valueReference="{}" description="Simulation time" causality="independent" variability="continuous"/>"#,
        variables.len()
    );
    let _ = writeln!(x, "  </ModelVariables>");
    let _ = writeln!(x, "  <ModelStructure>");
    let list = |list: &[usize]| {
        list.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    };
    let structure = structure(variables, &capabilities.dependencies);
    for o in &structure {
        let _ = writeln!(
            x,
            r#"    <Output valueReference="{}" dependencies="{}"/>"#,
            o.output,
            list(&o.stepping)
        );
    }
    for o in &structure {
        let _ = writeln!(
            x,
            r#"    <InitialUnknown valueReference="{}" dependencies="{}"/>"#,
            o.output,
            list(&o.initial)
        );
    }
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}

/// One exported output's dependencies, as value references (indices into
/// the exported variables).
pub struct OutputDependencies {
    pub output: usize,
    /// While stepping (`<Outputs>`).
    pub stepping: Vec<usize>,
    /// At initialization (`<InitialUnknowns>`).
    pub initial: Vec<usize>,
}

/// The `ModelStructure` of both FMI versions. An output depends directly on
/// the inputs that reach it through the members' feedthrough, the signal
/// connections and the coupling (`dependencies`, from
/// `Simulation::export_dependencies`); at initialization also on the
/// parameters. Ascending, without repeats.
pub fn structure(
    variables: &[ExportVariable],
    dependencies: &[Vec<usize>],
) -> Vec<OutputDependencies> {
    let of_kind = |kind: ExportKind| {
        (0..variables.len())
            .filter(|&i| variables[i].kind == kind)
            .collect::<Vec<_>>()
    };
    let sorted = |mut indices: Vec<usize>| {
        indices.sort_unstable();
        indices.dedup();
        indices
    };
    let parameters = of_kind(ExportKind::Parameter);
    of_kind(ExportKind::Output)
        .into_iter()
        .map(|output| {
            let inputs = dependencies.get(output).cloned().unwrap_or_default();
            OutputDependencies {
                output,
                stepping: sorted(inputs.clone()),
                initial: sorted([parameters.clone(), inputs].concat()),
            }
        })
        .collect()
}
