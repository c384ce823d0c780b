//! `tether info FILE.fmu`: what an FMU is and what it can do, for a person.

use std::path::PathBuf;

use anyhow::Result;
use tether_fmi::{
    Causality, Dimension, FmiStandard, Fmu, Initial, ModelDescription, ScalarVariable, Values,
    Variability, VariableKind,
};

#[derive(clap::Args)]
pub struct Args {
    /// The `.fmu` file or unpacked FMU directory.
    fmu: PathBuf,
}

pub fn main(args: Args) -> Result<()> {
    let fmu = Fmu::open(&args.fmu)?;
    crate::stdout(format_args!("{}", describe(fmu.model_description())))?;
    Ok(())
}

fn yes_no(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}

/// The whole report as text.
pub fn describe(md: &ModelDescription) -> String {
    let mut out = String::new();
    let mut line = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    line(format!("Model       {}", md.model_name));
    if let Some(d) = &md.description {
        line(format!("            {d}"));
    }
    let interfaces: Vec<&str> = [
        (md.co_simulation.is_some(), "co-simulation"),
        (md.model_exchange.is_some(), "model exchange"),
    ]
    .iter()
    .filter(|(has, _)| *has)
    .map(|&(_, name)| name)
    .collect();
    line(format!(
        "FMI         {} {}",
        md.fmi_version,
        interfaces.join(", ")
    ));
    let fmi3 = md.standard == FmiStandard::Fmi3;
    line(format!(
        "{}{}",
        if fmi3 { "Token       " } else { "GUID        " },
        md.guid
    ));
    for (label, value) in [
        ("Author", &md.author),
        ("Version", &md.version),
        ("Tool", &md.generation_tool),
        ("Generated", &md.generation_date_and_time),
        ("License", &md.license),
    ] {
        if let Some(v) = value {
            line(format!("{label:<11} {v}"));
        }
    }
    let cs = md.cs();
    line(String::new());
    line("Co-simulation".into());
    if md.co_simulation.is_none() {
        line("  none: the FMU offers model exchange only".into());
    }
    if md.co_simulation.is_some() {
        line(format!(
            "  modelIdentifier                    {}",
            cs.model_identifier
        ));
        if fmi3 {
            for (name, value) in [
                ("canGetAndSetFMUState", cs.can_get_and_set_fmu_state),
                ("canSerializeFMUState", cs.can_serialize_fmu_state),
                (
                    "canHandleVariableCommunicationStepSize",
                    cs.can_handle_variable_communication_step_size,
                ),
                (
                    "canBeInstantiatedOnlyOncePerProcess",
                    cs.can_be_instantiated_only_once_per_process,
                ),
                (
                    "providesDirectionalDerivatives",
                    cs.provides_directional_derivative,
                ),
                (
                    "providesAdjointDerivatives",
                    cs.provides_adjoint_derivatives,
                ),
                (
                    "providesPerElementDependencies",
                    cs.provides_per_element_dependencies,
                ),
                ("needsExecutionTool", cs.needs_execution_tool),
                (
                    "providesIntermediateUpdate",
                    cs.provides_intermediate_update,
                ),
                (
                    "mightReturnEarlyFromDoStep",
                    cs.might_return_early_from_do_step,
                ),
                (
                    "canReturnEarlyAfterIntermediateUpdate",
                    cs.can_return_early_after_intermediate_update,
                ),
                ("hasEventMode", cs.has_event_mode),
                (
                    "providesEvaluateDiscreteStates",
                    cs.provides_evaluate_discrete_states,
                ),
            ] {
                line(format!("  {name:<38} {}", yes_no(value)));
            }
            line(format!(
                "  {:<38} {}",
                "maxOutputDerivativeOrder", cs.max_output_derivative_order
            ));
            line(format!(
                "  {:<38} {}",
                "fixedInternalStepSize",
                cs.fixed_internal_step_size
                    .map_or_else(|| "-".to_string(), |h| h.to_string())
            ));
            line(format!(
                "  {:<38} {}",
                "recommendedIntermediateInputSmoothness",
                cs.recommended_intermediate_input_smoothness
            ));
            if cs.has_event_mode || cs.can_return_early_after_intermediate_update {
                line(
                    "  (Tether runs it without event mode and early return, as FMI 3.0 allows)"
                        .into(),
                );
            }
        } else {
            for (name, value) in [
                ("canGetAndSetFMUstate", cs.can_get_and_set_fmu_state),
                ("canSerializeFMUstate", cs.can_serialize_fmu_state),
                ("canInterpolateInputs", cs.can_interpolate_inputs),
                (
                    "canHandleVariableCommunicationStepSize",
                    cs.can_handle_variable_communication_step_size,
                ),
                (
                    "canBeInstantiatedOnlyOncePerProcess",
                    cs.can_be_instantiated_only_once_per_process,
                ),
                (
                    "canNotUseMemoryManagementFunctions",
                    cs.can_not_use_memory_management_functions,
                ),
                (
                    "providesDirectionalDerivative",
                    cs.provides_directional_derivative,
                ),
                ("needsExecutionTool", cs.needs_execution_tool),
                ("canRunAsynchronuously", cs.can_run_asynchronuously),
            ] {
                line(format!("  {name:<38} {}", yes_no(value)));
            }
            line(format!(
                "  {:<38} {}",
                "maxOutputDerivativeOrder", cs.max_output_derivative_order
            ));
        }
    }
    if let Some(me) = &md.model_exchange {
        line(String::new());
        line("Model exchange".into());
        line(format!(
            "  modelIdentifier                    {}",
            me.model_identifier
        ));
        let states = if fmi3 && me.number_of_continuous_states > 0 {
            let elements: u64 = md
                .model_structure
                .derivatives
                .iter()
                .filter_map(|d| md.variable_by_index(d.index))
                .map(|v| md.array_sizes(v).map_or(1, |s| s.iter().product::<u64>()))
                .sum();
            elements.to_string()
        } else {
            me.number_of_continuous_states.to_string()
        };
        line(format!("  {:<38} {states}", "continuous states"));
        line(format!(
            "  {:<38} {}",
            "event indicators", me.number_of_event_indicators
        ));
        let flags: Vec<(&str, bool)> = if fmi3 {
            vec![
                (
                    "needsCompletedIntegratorStep",
                    me.needs_completed_integrator_step,
                ),
                ("canGetAndSetFMUState", me.can_get_and_set_fmu_state),
                ("canSerializeFMUState", me.can_serialize_fmu_state),
                (
                    "providesDirectionalDerivatives",
                    me.provides_directional_derivative,
                ),
                (
                    "providesAdjointDerivatives",
                    me.provides_adjoint_derivatives,
                ),
                (
                    "providesEvaluateDiscreteStates",
                    me.provides_evaluate_discrete_states,
                ),
                (
                    "canBeInstantiatedOnlyOncePerProcess",
                    me.can_be_instantiated_only_once_per_process,
                ),
                ("needsExecutionTool", me.needs_execution_tool),
            ]
        } else {
            vec![
                (
                    "completedIntegratorStepNotNeeded",
                    me.completed_integrator_step_not_needed,
                ),
                ("canGetAndSetFMUstate", me.can_get_and_set_fmu_state),
                ("canSerializeFMUstate", me.can_serialize_fmu_state),
                (
                    "providesDirectionalDerivative",
                    me.provides_directional_derivative,
                ),
                (
                    "canBeInstantiatedOnlyOncePerProcess",
                    me.can_be_instantiated_only_once_per_process,
                ),
                (
                    "canNotUseMemoryManagementFunctions",
                    me.can_not_use_memory_management_functions,
                ),
                ("needsExecutionTool", me.needs_execution_tool),
            ]
        };
        for (name, value) in flags {
            line(format!("  {name:<38} {}", yes_no(value)));
        }
    }
    line(String::new());
    line("Tether methods".into());
    // Where the co-simulation interface falls short, `fmi_type = "auto"`
    // runs model exchange (docs/system-file.md, "Model exchange").
    let me = md.model_exchange.is_some();
    let through_me = "yes, through model exchange (fmi_type = \"auto\")";
    let rollback = cs.can_get_and_set_fmu_state;
    line(format!(
        "  predictor/corrector (baumgarte, weighted)  {}",
        if md.co_simulation.is_some() && rollback {
            "yes"
        } else if me {
            through_me
        } else if fmi3 {
            "no: needs canGetAndSetFMUState"
        } else {
            "no: needs canGetAndSetFMUstate"
        }
    ));
    let polynomials = tether_master::polynomial_inputs::summary(md);
    line(format!(
        "  coupling polynomials k > 0                 {}",
        // `auto` switches on the FMU's declaration, not on single inputs.
        if (md.co_simulation.is_some()
            && tether_master::polynomial_inputs::fmu_refusal(md).is_none())
            || !me
        {
            polynomials
        } else {
            through_me.to_string()
        }
    ));
    line(format!(
        "  explicit                                   {}",
        if md.co_simulation.is_some() {
            "yes"
        } else {
            through_me
        }
    ));
    if let Some(model_exchange) = &md.model_exchange {
        line(format!(
            "  tether simulate --fmi-type model-exchange  yes: built-in integrator ({}), \
                 time, state and step events",
            tether_fmi::Method::ALL.map(|(name, _)| name).join(", ")
        ));
        line(format!(
            "  model exchange coupled in a system         yes: fmi_type = \"model_exchange\"; rollback {}, polynomials on every input",
            if model_exchange.can_get_and_set_fmu_state {
                "with FMU states"
            } else {
                "from its states while no event falls in a step"
            }
        ));
    }
    let markers = markers(md);
    if !markers.is_empty() {
        line(String::new());
        line("Marker ports (docs/marker-ports.md)".into());
        for (name, ports) in markers {
            line(format!("  {name:<24} inputs: {}", ports.join(" ")));
        }
    }
    if let Some(de) = &md.default_experiment {
        line(String::new());
        let show = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_else(|| "-".into());
        line(format!(
            "Default experiment  start {}  stop {}  step {}  tolerance {}",
            show(de.start_time),
            show(de.stop_time),
            show(de.step_size),
            show(de.tolerance)
        ));
    }
    line(String::new());
    line(format!("Variables ({})", md.model_variables.len()));
    line(format!(
        "  {:<24} {:>6}  {:<12} {:<11} {:<10} {:<8} {:>12}  {:<8} description",
        "name", "vr", "causality", "variability", "initial", "type", "start", "unit"
    ));
    for v in &md.model_variables {
        line(variable_line(v, fmi3));
    }
    let arrays: Vec<&ScalarVariable> = md.model_variables.iter().filter(|v| v.is_array()).collect();
    if !arrays.is_empty() {
        line(String::new());
        line("Arrays (elements named y[1], A[2,3]: 1-based, row-major)".into());
        for v in arrays {
            line(array_line(md, v));
        }
    }
    out
}

/// An array's sizes and where they come from: `A  3x3  (n = 3, n = 3)`.
fn array_line(md: &ModelDescription, v: &ScalarVariable) -> String {
    let sizes = match md.array_sizes(v) {
        Ok(sizes) => sizes
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join("x"),
        Err(e) => format!("? ({e})"),
    };
    let from: Vec<String> = v
        .dimensions
        .iter()
        .map(|d| match d {
            Dimension::Fixed(n) => n.to_string(),
            Dimension::Parameter(vr) => match md.variable_by_vr(*vr) {
                Some(p) => format!("structural parameter {}", p.name),
                None => format!("value reference {vr}"),
            },
        })
        .collect();
    format!("  {:<24} {:<10} ({})", v.name, sizes, from.join(", "))
}

/// FMI 3.0 start values the FMI 2.0 view holds none of (arrays, wide integers).
fn start_text(values: &Values) -> String {
    let items: Vec<String> = match values {
        Values::Float(v) => v.iter().map(f64::to_string).collect(),
        Values::Int(v) => v.iter().map(i64::to_string).collect(),
        Values::UInt(v) => v.iter().map(u64::to_string).collect(),
        Values::Boolean(v) => v.iter().map(bool::to_string).collect(),
        Values::String(v) => v.clone(),
        Values::Binary(v) => v.iter().map(|b| format!("{} bytes", b.len())).collect(),
    };
    let text = items.join(" ");
    if text.chars().count() > 12 {
        let cut: String = text.chars().take(11).collect();
        format!("{cut}…")
    } else {
        text
    }
}

/// Markers (outputs named `M.r[1]`) with the force/torque inputs each declares.
fn markers(md: &ModelDescription) -> Vec<(String, Vec<String>)> {
    let mut found = Vec::new();
    for v in &md.model_variables {
        if v.causality != Causality::Output {
            continue;
        }
        if let Some(marker) = v.name.strip_suffix(".r[1]") {
            let ports: Vec<String> = md
                .model_variables
                .iter()
                .filter(|p| p.causality == Causality::Input)
                .filter_map(|p| p.name.strip_prefix(&format!("{marker}.")))
                .filter(|rest| rest.starts_with("F[") || rest.starts_with("T["))
                .map(str::to_string)
                .collect();
            found.push((marker.to_string(), ports));
        }
    }
    found
}

fn variable_line(v: &ScalarVariable, fmi3: bool) -> String {
    let causality = match v.causality {
        Causality::Parameter => "parameter",
        Causality::CalculatedParameter => "calculated",
        Causality::Input => "input",
        Causality::Output => "output",
        Causality::Local => "local",
        Causality::Independent => "independent",
    };
    let variability = match v.variability {
        Variability::Constant => "constant",
        Variability::Fixed => "fixed",
        Variability::Tunable => "tunable",
        Variability::Discrete => "discrete",
        Variability::Continuous => "continuous",
    };
    let initial = match v.initial {
        Some(Initial::Exact) => "exact",
        Some(Initial::Approx) => "approx",
        Some(Initial::Calculated) => "calculated",
        None => "",
    };
    let (mut ty, start, unit) = match &v.kind {
        VariableKind::Real(r) => (
            "Real",
            r.start.map(|s| s.to_string()),
            r.attributes.unit.clone().unwrap_or_default(),
        ),
        VariableKind::Integer(i) => ("Integer", i.start.map(|s| s.to_string()), String::new()),
        VariableKind::Enumeration(i) => ("Enum", i.start.map(|s| s.to_string()), String::new()),
        VariableKind::Boolean(b) => ("Boolean", b.start.map(|s| s.to_string()), String::new()),
        VariableKind::String(s) => ("String", s.start.clone(), String::new()),
    };
    let fmi3_type = v.value_type.name();
    let start = start.or_else(|| v.start_values.as_ref().map(start_text));
    let causality = if v.structural_parameter {
        "structural"
    } else {
        causality
    };
    if fmi3 {
        ty = fmi3_type;
    }
    let name = if v.is_array() {
        let dims: Vec<String> = v
            .dimensions
            .iter()
            .map(|d| match d {
                Dimension::Fixed(n) => n.to_string(),
                Dimension::Parameter(_) => ":".to_string(),
            })
            .collect();
        format!("{}[{}]", v.name, dims.join(","))
    } else {
        v.name.clone()
    };
    format!(
        "  {:<24} {:>6}  {:<12} {:<11} {:<10} {:<8} {:>12}  {:<8} {}",
        name,
        v.value_reference,
        causality,
        variability,
        initial,
        ty,
        start.unwrap_or_default(),
        unit,
        v.description.clone().unwrap_or_default()
    )
}
