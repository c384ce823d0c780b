//! `tether info FILE.fmu`: what an FMU is and what it can do, for a person.

use std::path::PathBuf;

use anyhow::Result;
use tether_fmi::{
    Causality, Fmu, Initial, ModelDescription, ScalarVariable, Variability, VariableKind,
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
    line(format!("FMI         {} co-simulation", md.fmi_version));
    line(format!("GUID        {}", md.guid));
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
    let cs = &md.co_simulation;
    line(String::new());
    line("Co-simulation".into());
    line(format!(
        "  modelIdentifier                    {}",
        cs.model_identifier
    ));
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
    if md.model_exchange.is_some() {
        line("  (also offers model exchange, which Tether does not use)".into());
    }
    line(String::new());
    line("Tether methods".into());
    let rollback = cs.can_get_and_set_fmu_state;
    line(format!(
        "  predictor/corrector (baumgarte, weighted)  {}",
        if rollback {
            "yes"
        } else {
            "no: needs canGetAndSetFMUstate"
        }
    ));
    line(format!(
        "  coupling polynomials k > 0                 {}",
        if cs.can_interpolate_inputs {
            "yes"
        } else {
            "no: needs canInterpolateInputs"
        }
    ));
    line("  explicit                                   yes".into());
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
        line(variable_line(v));
    }
    out
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

fn variable_line(v: &ScalarVariable) -> String {
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
    let (ty, start, unit) = match &v.kind {
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
    format!(
        "  {:<24} {:>6}  {:<12} {:<11} {:<10} {:<8} {:>12}  {:<8} {}",
        v.name,
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
