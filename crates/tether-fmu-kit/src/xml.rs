//! `modelDescription.xml` generated from a [`Declaration`].
//!
//! Variables (value reference = position, 0-based; index = position + 1):
//! Real parameters and `tolerance` (parameter, fixed, exact), Integer and Boolean
//! parameters (parameter, fixed, exact), inputs (input, continuous, start), outputs
//! (output, continuous, calculated), states (local, continuous, calculated) and their
//! derivatives `der(x)` (local, continuous, calculated, `derivative=`).
//! ModelStructure: Outputs with the declared dependencies, Derivatives (no
//! dependencies attribute = depends on everything), InitialUnknowns = outputs, states
//! and derivatives (all `calculated`), as FMI 2.0 §2.2.8 requires when Derivatives is
//! present.

use std::fmt::Write;

use crate::declaration::{Declaration, Slot, DEFAULT_TOLERANCE};

/// Log categories declared in `<LogCategories>` and accepted by `fmi2SetDebugLogging`.
pub const LOG_CATEGORIES: &[(&str, &str)] = &[
    (
        "logEvents",
        "Initialization, steps, state handling (fmi2OK messages)",
    ),
    ("logStatusWarning", "Messages with status fmi2Warning"),
    ("logStatusDiscard", "Messages with status fmi2Discard"),
    ("logStatusError", "Messages with status fmi2Error"),
    ("logStatusFatal", "Messages with status fmi2Fatal"),
    ("logAll", "All messages"),
];

const GUID_PLACEHOLDER: &str = "@GUID@";

/// The GUID: a 128-bit FNV-1a hash of the model description without the GUID, so the
/// same declaration always gives the same GUID and any change gives a new one.
pub fn guid(declaration: &Declaration) -> String {
    text_guid(&render(declaration, GUID_PLACEHOLDER))
}

/// A GUID in FMI's `{8-4-4-4-12}` form: the 128-bit FNV-1a hash of `text`.
pub fn text_guid(text: &str) -> String {
    let h1 = fnv1a64(text.as_bytes(), 0xcbf2_9ce4_8422_2325);
    let h2 = fnv1a64(text.as_bytes(), 0x6c62_272e_07bb_0142);
    let hex = format!("{h1:016x}{h2:016x}");
    format!(
        "{{{}-{}-{}-{}-{}}}",
        &hex[0..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..32]
    )
}

/// The complete `modelDescription.xml`, or why the declaration is invalid.
pub fn model_description(declaration: &Declaration) -> Result<String, String> {
    declaration.check()?;
    Ok(render(declaration, &guid(declaration)))
}

/// The GUID of model `M`, rendered and hashed once per process: instantiating
/// checks it and every instance keeps a fingerprint of it, and rendering a
/// large declaration (body3d's) is too slow to repeat per instance.
pub fn model_guid<M: crate::Model>() -> &'static str {
    use std::any::TypeId;
    use std::sync::{Mutex, PoisonError};
    // One entry per model type in the process (one in an FMU, a few in tests);
    // the strings live as long as the process, as the library does.
    static GUIDS: Mutex<Vec<(TypeId, &'static str)>> = Mutex::new(Vec::new());
    let mut guids = GUIDS.lock().unwrap_or_else(PoisonError::into_inner);
    let id = TypeId::of::<M>();
    if let Some(&(_, guid)) = guids.iter().find(|(t, _)| *t == id) {
        return guid;
    }
    let guid: &'static str = Box::leak(guid(&M::DECLARATION).into_boxed_str());
    guids.push((id, guid));
    guid
}

/// The 64-bit FNV-1a hash of `bytes` from `offset_basis`.
pub fn fnv1a64(bytes: &[u8], offset_basis: u64) -> u64 {
    bytes.iter().fold(offset_basis, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Escapes text for an XML attribute value.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\n' => out.push_str("&#10;"),
            c => out.push(c),
        }
    }
    out
}

/// Shortest text that parses back to the same f64 (Rust's `{:?}` is round-trip exact).
/// `<UnitDefinitions>` of `units` (each by name; none: no element) and the
/// `<LogCategories>` of [`LOG_CATEGORIES`], as every model description of
/// the kit (and the exported system's) has them.
pub fn units_and_log_categories(x: &mut String, units: &[&str]) {
    if !units.is_empty() {
        let _ = writeln!(x, "  <UnitDefinitions>");
        for unit in units {
            let _ = writeln!(x, r#"    <Unit name="{}"/>"#, escape(unit));
        }
        let _ = writeln!(x, "  </UnitDefinitions>");
    }
    let _ = writeln!(x, "  <LogCategories>");
    for (name, description) in LOG_CATEGORIES {
        let _ = writeln!(
            x,
            r#"    <Category name="{name}" description="{}"/>"#,
            escape(description)
        );
    }
    let _ = writeln!(x, "  </LogCategories>");
}

fn real(x: f64) -> String {
    format!("{x:?}")
}

fn opt_attr(name: &str, value: Option<String>) -> String {
    value
        .map(|v| format!(" {name}=\"{}\"", escape(&v)))
        .unwrap_or_default()
}

fn render(d: &Declaration, guid: &str) -> String {
    let mut x = String::new();
    let slots = d.slots();
    let index_of = |slot: Slot| slots.iter().position(|&s| s == slot).map_or(0, |p| p + 1);

    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="2.0" modelName="{}" guid="{guid}"{} generationTool="tether-fmu-kit {}" variableNamingConvention="structured" numberOfEventIndicators="0">"#,
        escape(d.model_name),
        opt_attr(
            "description",
            (!d.description.is_empty()).then(|| d.description.to_string())
        ),
        env!("CARGO_PKG_VERSION"),
    );
    if d.model_exchange {
        let _ = writeln!(
            x,
            r#"  <ModelExchange modelIdentifier="{}" needsExecutionTool="false" completedIntegratorStepNotNeeded="true" canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="false" canGetAndSetFMUstate="{}" canSerializeFMUstate="{}" providesDirectionalDerivative="false"/>"#,
            escape(d.model_identifier),
            d.capabilities.can_get_and_set_fmu_state,
            d.capabilities.can_get_and_set_fmu_state,
        );
    }
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{}" needsExecutionTool="false" canHandleVariableCommunicationStepSize="true" canInterpolateInputs="{}" maxOutputDerivativeOrder="{}" canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="false" canGetAndSetFMUstate="{}" canSerializeFMUstate="{}" providesDirectionalDerivative="false"/>"#,
        escape(d.model_identifier),
        d.capabilities.can_interpolate_inputs,
        d.max_output_derivative_order,
        d.capabilities.can_get_and_set_fmu_state,
        d.capabilities.can_get_and_set_fmu_state,
    );

    units_and_log_categories(&mut x, &used_units(d));

    let e = d.default_experiment;
    let _ = writeln!(
        x,
        r#"  <DefaultExperiment startTime="{}" stopTime="{}" tolerance="{}" stepSize="{}"/>"#,
        real(e.start_time),
        real(e.stop_time),
        real(DEFAULT_TOLERANCE),
        real(e.step_size)
    );

    let _ = writeln!(x, "  <ModelVariables>");
    let real_parameters = d.all_real_parameters();
    for (vr, &slot) in slots.iter().enumerate() {
        let name = d.name(slot);
        let _ = writeln!(x, "    <!-- index {} -->", vr + 1);
        let head = |description: &str, rest: &str| {
            format!(
                r#"    <ScalarVariable name="{}" valueReference="{vr}"{}{rest}>"#,
                escape(&name),
                opt_attr(
                    "description",
                    (!description.is_empty()).then(|| description.to_string())
                ),
            )
        };
        let fixed = r#" causality="parameter" variability="fixed" initial="exact""#;
        let calculated = |causality: &str| {
            format!(r#" causality="{causality}" variability="continuous" initial="calculated""#)
        };
        let (head, element) = match slot {
            Slot::RealParameter(i) => {
                let p = &real_parameters[i];
                let element = format!(
                    r#"<Real start="{}"{}{}{}/>"#,
                    real(p.start),
                    opt_attr("unit", p.unit.map(String::from)),
                    opt_attr("min", p.min.map(real)),
                    opt_attr("max", p.max.map(real)),
                );
                (head(p.description, fixed), element)
            }
            Slot::IntegerParameter(i) => {
                let p = &d.integer_parameters[i];
                let element = format!(
                    r#"<Integer start="{}"{}{}/>"#,
                    p.start,
                    opt_attr("min", p.min.map(|m| m.to_string())),
                    opt_attr("max", p.max.map(|m| m.to_string())),
                );
                (head(p.description, fixed), element)
            }
            Slot::BooleanParameter(i) => {
                let p = &d.boolean_parameters[i];
                (
                    head(p.description, fixed),
                    format!(r#"<Boolean start="{}"/>"#, p.start),
                )
            }
            Slot::Input(i) => {
                let u = &d.inputs[i];
                let element = format!(
                    r#"<Real start="{}"{}{}{}/>"#,
                    real(u.start),
                    opt_attr("unit", u.unit.map(String::from)),
                    opt_attr("min", u.min.map(real)),
                    opt_attr("max", u.max.map(real)),
                );
                (
                    head(
                        u.description,
                        r#" causality="input" variability="continuous""#,
                    ),
                    element,
                )
            }
            Slot::Output(i) => {
                let y = &d.outputs[i];
                let element = format!(r#"<Real{}/>"#, opt_attr("unit", y.unit.map(String::from)));
                (head(y.description, &calculated("output")), element)
            }
            Slot::State(i) => {
                let s = &d.states[i];
                let element = format!(r#"<Real{}/>"#, opt_attr("unit", s.unit.map(String::from)));
                (head(s.description, &calculated("local")), element)
            }
            Slot::Derivative(i) => {
                let s = &d.states[i];
                let element = format!(
                    r#"<Real{} derivative="{}"/>"#,
                    opt_attr("unit", s.derivative_unit.map(String::from)),
                    index_of(Slot::State(i))
                );
                let description = format!("Derivative of {}", s.name);
                (head(&description, &calculated("local")), element)
            }
            Slot::Time => continue,
        };
        let _ = writeln!(x, "{head}\n      {element}\n    </ScalarVariable>");
    }
    let _ = writeln!(x, "  </ModelVariables>");

    let _ = writeln!(x, "  <ModelStructure>");
    if !d.outputs.is_empty() {
        let _ = writeln!(x, "    <Outputs>");
        for (i, y) in d.outputs.iter().enumerate() {
            let _ = writeln!(
                x,
                r#"      <Unknown index="{}" dependencies="{}"/>"#,
                index_of(Slot::Output(i)),
                dependencies(d, y.depends_on, index_of)
            );
        }
        let _ = writeln!(x, "    </Outputs>");
    }
    if !d.states.is_empty() {
        let _ = writeln!(x, "    <Derivatives>");
        for i in 0..d.states.len() {
            let _ = writeln!(
                x,
                r#"      <Unknown index="{}"/>"#,
                index_of(Slot::Derivative(i))
            );
        }
        let _ = writeln!(x, "    </Derivatives>");
    }
    let initial_unknowns: Vec<usize> = slots
        .iter()
        .enumerate()
        .filter(|(_, s)| matches!(s, Slot::Output(_) | Slot::State(_) | Slot::Derivative(_)))
        .map(|(vr, _)| vr + 1)
        .collect();
    if !initial_unknowns.is_empty() {
        let _ = writeln!(x, "    <InitialUnknowns>");
        for index in initial_unknowns {
            let _ = writeln!(x, r#"      <Unknown index="{index}"/>"#);
        }
        let _ = writeln!(x, "    </InitialUnknowns>");
    }
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}

/// The FMI 3.0 `modelDescription.xml` of the same model (co-simulation), or why the
/// declaration is invalid. The variables keep their FMI 2.0 value references
/// (`Float64`, `Int32`, `Boolean`), `time` (causality `independent`) comes after
/// them; `<ModelStructure>` lists the outputs with their dependencies (value
/// references of states and inputs) and the outputs as initial unknowns. The
/// instantiation token is the FMI 2.0 GUID: the model is the same.
pub fn model_description_fmi3(declaration: &Declaration) -> Result<String, String> {
    declaration.check()?;
    Ok(render3(declaration, &guid(declaration)))
}

/// Whether the FMI 3.0 build provides intermediate update: it takes its inputs'
/// polynomial there (`ffi::fmi3::do_step`), as the FMI 2.0 build takes input
/// derivatives (`canInterpolateInputs`).
pub(crate) fn intermediate_update(d: &Declaration) -> bool {
    d.capabilities.can_interpolate_inputs && !d.inputs.is_empty()
}

fn render3(d: &Declaration, token: &str) -> String {
    let mut x = String::new();
    let slots = d.slots();
    let vr_of = |slot: Slot| slots.iter().position(|&s| s == slot).unwrap_or(0);

    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="3.0" modelName="{}" instantiationToken="{token}"{} generationTool="tether-fmu-kit {}" variableNamingConvention="structured">"#,
        escape(d.model_name),
        opt_attr(
            "description",
            (!d.description.is_empty()).then(|| d.description.to_string())
        ),
        env!("CARGO_PKG_VERSION"),
    );
    if d.model_exchange {
        let _ = writeln!(
            x,
            r#"  <ModelExchange modelIdentifier="{}" needsExecutionTool="false" canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="{}" canSerializeFMUState="{}" providesDirectionalDerivatives="false" providesAdjointDerivatives="false" providesPerElementDependencies="false" needsCompletedIntegratorStep="false" providesEvaluateDiscreteStates="false"/>"#,
            escape(d.model_identifier),
            d.capabilities.can_get_and_set_fmu_state,
            d.capabilities.can_get_and_set_fmu_state,
        );
    }
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{}" needsExecutionTool="false" canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="{}" canSerializeFMUState="{}" providesDirectionalDerivatives="false" providesAdjointDerivatives="false" providesPerElementDependencies="false" canHandleVariableCommunicationStepSize="true" maxOutputDerivativeOrder="{}" providesIntermediateUpdate="{}" canReturnEarlyAfterIntermediateUpdate="false" hasEventMode="false" providesEvaluateDiscreteStates="false"/>"#,
        escape(d.model_identifier),
        d.capabilities.can_get_and_set_fmu_state,
        d.capabilities.can_get_and_set_fmu_state,
        d.max_output_derivative_order,
        intermediate_update(d),
    );
    units_and_log_categories(&mut x, &used_units(d));
    let e = d.default_experiment;
    let _ = writeln!(
        x,
        r#"  <DefaultExperiment startTime="{}" stopTime="{}" tolerance="{}" stepSize="{}"/>"#,
        real(e.start_time),
        real(e.stop_time),
        real(DEFAULT_TOLERANCE),
        real(e.step_size)
    );

    let _ = writeln!(x, "  <ModelVariables>");
    let real_parameters = d.all_real_parameters();
    let description =
        |text: &str| opt_attr("description", (!text.is_empty()).then(|| text.to_string()));
    let fixed = r#" causality="parameter" variability="fixed" initial="exact""#;
    let calculated = |causality: &str| {
        format!(r#" causality="{causality}" variability="continuous" initial="calculated""#)
    };
    for (vr, &slot) in slots.iter().enumerate() {
        let name = escape(&d.name(slot));
        let line = match slot {
            Slot::RealParameter(i) => {
                let p = &real_parameters[i];
                format!(
                    r#"<Float64 name="{name}" valueReference="{vr}"{}{fixed} start="{}"{}{}{}/>"#,
                    description(p.description),
                    real(p.start),
                    opt_attr("unit", p.unit.map(String::from)),
                    opt_attr("min", p.min.map(real)),
                    opt_attr("max", p.max.map(real)),
                )
            }
            Slot::IntegerParameter(i) => {
                let p = &d.integer_parameters[i];
                format!(
                    r#"<Int32 name="{name}" valueReference="{vr}"{}{fixed} start="{}"{}{}/>"#,
                    description(p.description),
                    p.start,
                    opt_attr("min", p.min.map(|m| m.to_string())),
                    opt_attr("max", p.max.map(|m| m.to_string())),
                )
            }
            Slot::BooleanParameter(i) => {
                let p = &d.boolean_parameters[i];
                format!(
                    r#"<Boolean name="{name}" valueReference="{vr}"{}{fixed} start="{}"/>"#,
                    description(p.description),
                    p.start
                )
            }
            Slot::Input(i) => {
                let u = &d.inputs[i];
                format!(
                    r#"<Float64 name="{name}" valueReference="{vr}"{} causality="input" variability="continuous"{} start="{}"{}{}{}/>"#,
                    description(u.description),
                    if intermediate_update(d) {
                        r#" intermediateUpdate="true""#
                    } else {
                        ""
                    },
                    real(u.start),
                    opt_attr("unit", u.unit.map(String::from)),
                    opt_attr("min", u.min.map(real)),
                    opt_attr("max", u.max.map(real)),
                )
            }
            Slot::Output(i) => {
                let y = &d.outputs[i];
                format!(
                    r#"<Float64 name="{name}" valueReference="{vr}"{}{}{}/>"#,
                    description(y.description),
                    calculated("output"),
                    opt_attr("unit", y.unit.map(String::from)),
                )
            }
            Slot::State(i) => {
                let s = &d.states[i];
                format!(
                    r#"<Float64 name="{name}" valueReference="{vr}"{}{}{}/>"#,
                    description(s.description),
                    calculated("local"),
                    opt_attr("unit", s.unit.map(String::from)),
                )
            }
            Slot::Derivative(i) => {
                let s = &d.states[i];
                format!(
                    r#"<Float64 name="{name}" valueReference="{vr}"{}{}{} derivative="{}"/>"#,
                    description(&format!("Derivative of {}", s.name)),
                    calculated("local"),
                    opt_attr("unit", s.derivative_unit.map(String::from)),
                    vr_of(Slot::State(i))
                )
            }
            Slot::Time => continue,
        };
        let _ = writeln!(x, "    {line}");
    }
    let _ = writeln!(
        x,
        r#"    <Float64 name="time" valueReference="{}" description="Simulation time" causality="independent" variability="continuous"/>"#,
        slots.len()
    );
    let _ = writeln!(x, "  </ModelVariables>");

    let _ = writeln!(x, "  <ModelStructure>");
    for (i, y) in d.outputs.iter().enumerate() {
        let _ = writeln!(
            x,
            r#"    <Output valueReference="{}" dependencies="{}"/>"#,
            vr_of(Slot::Output(i)),
            dependencies(d, y.depends_on, vr_of)
        );
    }
    // Model exchange: the state derivatives, which depend on everything (no
    // dependencies attribute), and the states and derivatives are initial
    // unknowns (all `calculated`). Not written for co-simulation only, so that
    // its model description (and instantiation token) stays as it was.
    if d.model_exchange {
        for i in 0..d.states.len() {
            let _ = writeln!(
                x,
                r#"    <ContinuousStateDerivative valueReference="{}"/>"#,
                vr_of(Slot::Derivative(i))
            );
        }
    }
    let mut initial: Vec<usize> = (0..d.outputs.len())
        .map(Slot::Output)
        .chain(
            (0..d.states.len())
                .filter(|_| d.model_exchange)
                .flat_map(|i| [Slot::State(i), Slot::Derivative(i)]),
        )
        .map(vr_of)
        .collect();
    initial.sort_unstable();
    for vr in initial {
        let _ = writeln!(x, r#"    <InitialUnknown valueReference="{vr}"/>"#);
    }
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}

/// The states and inputs named in `depends_on`, as `number` numbers them
/// (FMI 2.0 indices or FMI 3.0 value references), sorted, space-separated.
fn dependencies(d: &Declaration, depends_on: &[&str], number: impl Fn(Slot) -> usize) -> String {
    let mut deps: Vec<usize> = depends_on
        .iter()
        .filter_map(|dep| {
            let state = d
                .states
                .iter()
                .position(|s| s.name == *dep)
                .map(Slot::State);
            let input = d
                .inputs
                .iter()
                .position(|u| u.name == *dep)
                .map(Slot::Input);
            state.or(input).map(&number)
        })
        .collect();
    deps.sort_unstable();
    deps.dedup();
    let deps: Vec<String> = deps.iter().map(usize::to_string).collect();
    deps.join(" ")
}

fn used_units(d: &Declaration) -> Vec<&'static str> {
    let mut units: Vec<&'static str> = Vec::new();
    let all = d
        .real_parameters
        .iter()
        .map(|p| p.unit)
        .chain(d.inputs.iter().map(|u| u.unit))
        .chain(d.outputs.iter().map(|y| y.unit))
        .chain(d.states.iter().flat_map(|s| [s.unit, s.derivative_unit]));
    for unit in all.flatten() {
        if !units.contains(&unit) {
            units.push(unit);
        }
    }
    units
}
