//! Maps the element tree of modelDescription.xml onto [`ModelDescription`].

use super::attrs::Attrs;
use super::common;
use super::type_attrs::{integer_type, real_type};
use super::types::*;
use super::variables::parse_variables;
use crate::error::Result;
use crate::xml::Element;

/// Builds the model description from the parsed root element.
pub(crate) fn model_description(at: Attrs<'_>, root: &Element) -> Result<ModelDescription> {
    common::check_root(at, root)?;
    let co_simulation = match root.child("CoSimulation") {
        Some(cs) => Some(co_simulation(at, cs)?),
        None => None,
    };
    let me_element = root.child("ModelExchange");
    if co_simulation.is_none() && me_element.is_none() {
        return Err(at.invalid(root, "no <CoSimulation> or <ModelExchange> element"));
    }
    let type_definitions: Vec<SimpleType> = match root.child("TypeDefinitions") {
        Some(types) => types
            .children_named("SimpleType")
            .map(|t| simple_type(at, t))
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    let common::Header {
        fmi_version,
        model_name,
        description,
        author,
        version,
        copyright,
        license,
        generation_tool,
        generation_date_and_time,
        variable_naming_convention,
        unit_definitions,
        log_categories,
        default_experiment,
    } = common::header(at, root)?;
    let number_of_event_indicators: Option<u32> = at.parsed(root, "numberOfEventIndicators")?;
    let Some(variables_element) = root.child("ModelVariables") else {
        return Err(at.invalid(root, "no <ModelVariables> element"));
    };
    let model_variables = parse_variables(at, variables_element, &type_definitions)?;
    let by_name = common::by_name(at, &model_variables)?;
    let model_structure = match root.child("ModelStructure") {
        Some(s) => model_structure(at, s, &model_variables)?,
        None => return Err(at.invalid(root, "no <ModelStructure> element")),
    };
    let model_exchange = match me_element {
        Some(me) => Some(model_exchange(
            at,
            me,
            model_structure.derivatives.len(),
            number_of_event_indicators.unwrap_or(0) as usize,
        )?),
        None => None,
    };
    Ok(ModelDescription {
        fmi_version,
        standard: FmiStandard::Fmi2,
        model_name,
        guid: at.required(root, "guid")?,
        description,
        author,
        version,
        copyright,
        license,
        generation_tool,
        generation_date_and_time,
        variable_naming_convention,
        number_of_event_indicators,
        co_simulation,
        model_exchange,
        unit_definitions,
        type_definitions,
        log_categories,
        default_experiment,
        model_variables,
        model_structure,
        quirks: Vec::new(),
        by_name,
    })
}

fn co_simulation(at: Attrs<'_>, cs: &Element) -> Result<CoSimulation> {
    Ok(CoSimulation {
        model_identifier: at.required(cs, "modelIdentifier")?,
        needs_execution_tool: at.flag(cs, "needsExecutionTool", false)?,
        can_handle_variable_communication_step_size: at.flag(
            cs,
            "canHandleVariableCommunicationStepSize",
            false,
        )?,
        can_interpolate_inputs: at.flag(cs, "canInterpolateInputs", false)?,
        max_output_derivative_order: at.parsed(cs, "maxOutputDerivativeOrder")?.unwrap_or(0),
        can_run_asynchronuously: at.flag(cs, "canRunAsynchronuously", false)?,
        can_be_instantiated_only_once_per_process: at.flag(
            cs,
            "canBeInstantiatedOnlyOncePerProcess",
            false,
        )?,
        can_not_use_memory_management_functions: at.flag(
            cs,
            "canNotUseMemoryManagementFunctions",
            false,
        )?,
        can_get_and_set_fmu_state: at.flag(cs, "canGetAndSetFMUstate", false)?,
        can_serialize_fmu_state: at.flag(cs, "canSerializeFMUstate", false)?,
        provides_directional_derivative: at.flag(cs, "providesDirectionalDerivative", false)?,
        ..CoSimulation::default()
    })
}

fn model_exchange(
    at: Attrs<'_>,
    me: &Element,
    states: usize,
    event_indicators: usize,
) -> Result<ModelExchange> {
    let not_needed = at.flag(me, "completedIntegratorStepNotNeeded", false)?;
    Ok(ModelExchange {
        model_identifier: at.required(me, "modelIdentifier")?,
        needs_execution_tool: at.flag(me, "needsExecutionTool", false)?,
        completed_integrator_step_not_needed: not_needed,
        needs_completed_integrator_step: !not_needed,
        can_be_instantiated_only_once_per_process: at.flag(
            me,
            "canBeInstantiatedOnlyOncePerProcess",
            false,
        )?,
        can_not_use_memory_management_functions: at.flag(
            me,
            "canNotUseMemoryManagementFunctions",
            false,
        )?,
        can_get_and_set_fmu_state: at.flag(me, "canGetAndSetFMUstate", false)?,
        can_serialize_fmu_state: at.flag(me, "canSerializeFMUstate", false)?,
        provides_directional_derivative: at.flag(me, "providesDirectionalDerivative", false)?,
        provides_adjoint_derivatives: false,
        provides_evaluate_discrete_states: false,
        number_of_continuous_states: states,
        number_of_event_indicators: event_indicators,
    })
}

fn simple_type(at: Attrs<'_>, t: &Element) -> Result<SimpleType> {
    let Some(element) = t.children.first() else {
        return Err(at.invalid(t, "<SimpleType> has no type element"));
    };
    let value_type = match element.name.as_str() {
        "Real" => ValueType::Float64,
        "Integer" => ValueType::Int32,
        "Boolean" => ValueType::Boolean,
        "String" => ValueType::String,
        _ => ValueType::Enumeration,
    };
    let kind = match element.name.as_str() {
        "Real" => SimpleTypeKind::Real(real_type(at, element, None)?),
        "Integer" => SimpleTypeKind::Integer(integer_type(at, element, None)?),
        "Boolean" => SimpleTypeKind::Boolean,
        "String" => SimpleTypeKind::String,
        "Enumeration" => SimpleTypeKind::Enumeration {
            quantity: at.string(element, "quantity"),
            items: element
                .children_named("Item")
                .map(|i| {
                    Ok(EnumerationItem {
                        name: at.required(i, "name")?,
                        value: at
                            .parsed(i, "value")?
                            .ok_or_else(|| at.invalid(i, "<Item> lacks the attribute 'value'"))?,
                        description: at.string(i, "description"),
                    })
                })
                .collect::<Result<_>>()?,
        },
        other => {
            return Err(at.invalid(element, format!("unknown type element <{other}>")));
        }
    };
    Ok(SimpleType {
        name: at.required(t, "name")?,
        description: at.string(t, "description"),
        kind,
        value_type,
    })
}

fn model_structure(
    at: Attrs<'_>,
    s: &Element,
    variables: &[ScalarVariable],
) -> Result<ModelStructure> {
    let list = |name: &str| -> Result<Vec<Unknown>> {
        match s.child(name) {
            Some(section) => section
                .children_named("Unknown")
                .map(|u| unknown(at, u, variables))
                .collect(),
            None => Ok(Vec::new()),
        }
    };
    let structure = ModelStructure {
        outputs: list("Outputs")?,
        derivatives: list("Derivatives")?,
        initial_unknowns: list("InitialUnknowns")?,
        ..ModelStructure::default()
    };
    if let Some(outputs) = s.child("Outputs") {
        for (u, e) in structure
            .outputs
            .iter()
            .zip(outputs.children_named("Unknown"))
        {
            let v = &variables[u.index - 1];
            if v.causality != Causality::Output {
                return Err(at.invalid(
                    e,
                    format!(
                        "<Outputs> lists variable {} ('{}') whose causality is not output",
                        u.index, v.name
                    ),
                ));
            }
        }
    }
    Ok(structure)
}

fn unknown(at: Attrs<'_>, u: &Element, variables: &[ScalarVariable]) -> Result<Unknown> {
    let n = variables.len();
    let in_range = |i: usize| (1..=n).contains(&i);
    let index: usize = at
        .parsed(u, "index")?
        .ok_or_else(|| at.invalid(u, "<Unknown> lacks the attribute 'index'"))?;
    if !in_range(index) {
        return Err(at.invalid(u, format!("<Unknown> index {index} is outside 1..={n}")));
    }
    let dependencies: Option<Vec<usize>> = at.list(u, "dependencies")?;
    if let Some(bad) = dependencies.iter().flatten().find(|&&d| !in_range(d)) {
        return Err(at.invalid(
            u,
            format!("<Unknown index=\"{index}\"> dependency {bad} is outside 1..={n}"),
        ));
    }
    let dependencies_kind = match at.list::<String>(u, "dependenciesKind")? {
        None => None,
        Some(kinds) => Some(
            kinds
                .iter()
                .map(|k| {
                    Ok(match k.as_str() {
                        "dependent" => DependencyKind::Dependent,
                        "constant" => DependencyKind::Constant,
                        "fixed" => DependencyKind::Fixed,
                        "tunable" => DependencyKind::Tunable,
                        "discrete" => DependencyKind::Discrete,
                        other => {
                            return Err(
                                at.invalid(u, format!("unknown dependenciesKind \"{other}\""))
                            )
                        }
                    })
                })
                .collect::<Result<Vec<_>>>()?,
        ),
    };
    if let (Some(d), Some(k)) = (&dependencies, &dependencies_kind) {
        if d.len() != k.len() {
            return Err(at.invalid(
                u,
                format!(
                    "<Unknown index=\"{index}\"> has {} dependencies but {} dependenciesKind entries",
                    d.len(),
                    k.len()
                ),
            ));
        }
    }
    Ok(Unknown {
        index,
        dependencies,
        dependencies_kind,
    })
}
