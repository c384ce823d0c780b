//! Maps an FMI 3.0 `modelDescription.xml` onto [`ModelDescription`].
//!
//! The FMI 3.0 schema differs from FMI 2.0's in shape (one element per type instead of
//! `ScalarVariable` with a type child, `<Dimension>`s, value references instead of
//! indices in `derivative` and `ModelStructure`), not much in meaning. The result uses
//! the FMI 2.0 types callers know, with the FMI 3.0 additions beside them (see
//! [`types`](super::types)); the standard's defaults are applied as for FMI 2.0.

use std::collections::HashMap;

use super::attrs::Attrs;
use super::common::{self, dependency_kind};
use super::type_attrs::real_type;
use super::types::*;
use super::variables::{declared, initial_case, InitialCase, CAUSALITIES, INITIALS, VARIABILITIES};
use crate::error::Result;
use crate::xml::Element;

/// Builds the model description from the parsed root element of an FMI 3.0 file.
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
            .children
            .iter()
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
    let Some(variables_element) = root.child("ModelVariables") else {
        return Err(at.invalid(root, "no <ModelVariables> element"));
    };
    let mut model_variables = Vec::with_capacity(variables_element.children.len());
    // The 1-based index of each variable's `derivative` value reference, resolved below.
    let mut derivatives = Vec::with_capacity(variables_element.children.len());
    for e in &variables_element.children {
        let (v, derivative) = variable(at, e, &type_definitions)?;
        // `<Alias>` children (from FMI 3.0.x development builds, read by fmpy too):
        // more names of the same variable, with their own description and display unit.
        let aliases = e
            .children_named("Alias")
            .map(|a| {
                let mut alias = v.clone();
                alias.name = at.required(a, "name")?;
                if let Some(d) = a.attr("description") {
                    alias.description = Some(d.to_owned());
                }
                if let (Some(unit), VariableKind::Real(r)) =
                    (a.attr("displayUnit"), &mut alias.kind)
                {
                    r.attributes.display_unit = Some(unit.to_owned());
                }
                alias.line = a.line;
                Ok(alias)
            })
            .collect::<Result<Vec<_>>>()?;
        model_variables.push(v);
        derivatives.push((derivative, e));
        for alias in aliases {
            model_variables.push(alias);
            derivatives.push((derivative, e));
        }
    }
    let by_name = common::by_name(at, &model_variables)?;
    // FMI 3.0 aliases share a value reference: the first variable stands for it.
    let mut by_vr: HashMap<ValueReference, usize> = HashMap::with_capacity(model_variables.len());
    for (i, v) in model_variables.iter().enumerate() {
        by_vr.entry(v.value_reference).or_insert(i + 1);
    }
    let index_of = |vr: ValueReference, e: &Element, what: &str| -> Result<usize> {
        by_vr.get(&vr).copied().ok_or_else(|| {
            at.invalid(
                e,
                format!("{what} names value reference {vr}, which no variable has"),
            )
        })
    };
    for (v, (derivative, e)) in model_variables.iter_mut().zip(&derivatives) {
        if let Some(vr) = *derivative {
            let index = index_of(vr, e, &format!("variable '{}': derivative", v.name))?;
            if let VariableKind::Real(r) = &mut v.kind {
                r.derivative = Some(index);
            }
        }
    }
    for v in &model_variables {
        for d in &v.dimensions {
            if let Dimension::Parameter(vr) = d {
                let i = by_vr.get(vr).copied().ok_or_else(|| {
                    at.invalid_at(
                        v.line,
                        format!(
                            "variable '{}' has a <Dimension> of value reference {vr}, which no variable has",
                            v.name
                        ),
                    )
                })?;
                let p = &model_variables[i - 1];
                let fits = p.value_type.is_integer()
                    && (p.structural_parameter || p.variability == Variability::Constant);
                if !fits {
                    return Err(at.invalid_at(
                        v.line,
                        format!(
                            "variable '{}' has a <Dimension> given by '{}', which is not an integer structural parameter or constant",
                            v.name, p.name
                        ),
                    ));
                }
            }
        }
    }
    let model_structure = match root.child("ModelStructure") {
        Some(s) => model_structure(at, s, &index_of)?,
        None => ModelStructure::default(),
    };
    let model_exchange = match me_element {
        Some(me) => Some(model_exchange(at, me, &model_structure)?),
        None => None,
    };
    Ok(ModelDescription {
        fmi_version,
        standard: FmiStandard::Fmi3,
        model_name,
        guid: at.required(root, "instantiationToken")?,
        description,
        author,
        version,
        copyright,
        license,
        generation_tool,
        generation_date_and_time,
        variable_naming_convention,
        number_of_event_indicators: None,
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
        // FMI 3.0 has no input derivatives (intermediate update replaces them).
        can_interpolate_inputs: false,
        max_output_derivative_order: at.parsed(cs, "maxOutputDerivativeOrder")?.unwrap_or(0),
        can_run_asynchronuously: false,
        can_be_instantiated_only_once_per_process: at.flag(
            cs,
            "canBeInstantiatedOnlyOncePerProcess",
            false,
        )?,
        can_not_use_memory_management_functions: false,
        can_get_and_set_fmu_state: at.flag(cs, "canGetAndSetFMUState", false)?,
        can_serialize_fmu_state: at.flag(cs, "canSerializeFMUState", false)?,
        provides_directional_derivative: at.flag(cs, "providesDirectionalDerivatives", false)?,
        provides_adjoint_derivatives: at.flag(cs, "providesAdjointDerivatives", false)?,
        provides_per_element_dependencies: at.flag(cs, "providesPerElementDependencies", false)?,
        fixed_internal_step_size: at.parsed(cs, "fixedInternalStepSize")?,
        recommended_intermediate_input_smoothness: at
            .parsed(cs, "recommendedIntermediateInputSmoothness")?
            .unwrap_or(0),
        provides_intermediate_update: at.flag(cs, "providesIntermediateUpdate", false)?,
        might_return_early_from_do_step: at.flag(cs, "mightReturnEarlyFromDoStep", false)?,
        can_return_early_after_intermediate_update: at.flag(
            cs,
            "canReturnEarlyAfterIntermediateUpdate",
            false,
        )?,
        has_event_mode: at.flag(cs, "hasEventMode", false)?,
        provides_evaluate_discrete_states: at.flag(cs, "providesEvaluateDiscreteStates", false)?,
    })
}

fn model_exchange(at: Attrs<'_>, me: &Element, s: &ModelStructure) -> Result<ModelExchange> {
    let needed = at.flag(me, "needsCompletedIntegratorStep", false)?;
    Ok(ModelExchange {
        model_identifier: at.required(me, "modelIdentifier")?,
        needs_execution_tool: at.flag(me, "needsExecutionTool", false)?,
        completed_integrator_step_not_needed: !needed,
        needs_completed_integrator_step: needed,
        can_be_instantiated_only_once_per_process: at.flag(
            me,
            "canBeInstantiatedOnlyOncePerProcess",
            false,
        )?,
        can_not_use_memory_management_functions: false,
        can_get_and_set_fmu_state: at.flag(me, "canGetAndSetFMUState", false)?,
        can_serialize_fmu_state: at.flag(me, "canSerializeFMUState", false)?,
        provides_directional_derivative: at.flag(me, "providesDirectionalDerivatives", false)?,
        provides_adjoint_derivatives: at.flag(me, "providesAdjointDerivatives", false)?,
        provides_evaluate_discrete_states: at.flag(me, "providesEvaluateDiscreteStates", false)?,
        number_of_continuous_states: s.derivatives.len(),
        number_of_event_indicators: s.event_indicators.len(),
    })
}

/// An integer attribute of any FMI 3.0 width, kept where it fits the FMI 2.0 `i32`.
fn narrow(at: Attrs<'_>, e: &Element, key: &str) -> Result<Option<i32>> {
    let wide: Option<i128> = at.parsed(e, key)?;
    Ok(wide.and_then(|w| i32::try_from(w).ok()))
}

fn integer_type(at: Attrs<'_>, e: &Element, base: Option<&IntegerType>) -> Result<IntegerType> {
    let base = base.cloned().unwrap_or_default();
    Ok(IntegerType {
        quantity: at.string(e, "quantity").or(base.quantity),
        min: narrow(at, e, "min")?.or(base.min),
        max: narrow(at, e, "max")?.or(base.max),
    })
}

fn simple_type(at: Attrs<'_>, t: &Element) -> Result<SimpleType> {
    let Some(value_type) = t.name.strip_suffix("Type").and_then(ValueType::from_name) else {
        return Err(at.invalid(t, format!("unknown type definition <{}>", t.name)));
    };
    let kind = match value_type {
        ValueType::Float32 | ValueType::Float64 => SimpleTypeKind::Real(real_type(at, t, None)?),
        ValueType::Boolean => SimpleTypeKind::Boolean,
        ValueType::String => SimpleTypeKind::String,
        ValueType::Binary => SimpleTypeKind::Binary,
        ValueType::Clock => SimpleTypeKind::Clock,
        ValueType::Enumeration => SimpleTypeKind::Enumeration {
            quantity: at.string(t, "quantity"),
            items: t
                .children_named("Item")
                .map(|i| {
                    let value: i64 = at
                        .parsed(i, "value")?
                        .ok_or_else(|| at.invalid(i, "<Item> lacks the attribute 'value'"))?;
                    Ok(EnumerationItem {
                        name: at.required(i, "name")?,
                        value: i32::try_from(value).map_err(|_| {
                            at.invalid(i, format!("<Item> value {value} is outside the 32-bit range Tether supports for enumerations"))
                        })?,
                        description: at.string(i, "description"),
                    })
                })
                .collect::<Result<_>>()?,
        },
        _ => SimpleTypeKind::Integer(integer_type(at, t, None)?),
    };
    Ok(SimpleType {
        name: at.required(t, "name")?,
        description: at.string(t, "description"),
        kind,
        value_type,
    })
}

/// The start values of `e` (the `start` attribute, or `<Start value>` children for
/// String and Binary), row-major.
fn start_values(at: Attrs<'_>, e: &Element, ty: ValueType, name: &str) -> Result<Option<Values>> {
    let bad = |item: &str| {
        at.invalid(
            e,
            format!(
                "variable '{name}' has the start value \"{item}\", not a valid {}",
                ty.name()
            ),
        )
    };
    if matches!(ty, ValueType::String | ValueType::Binary) {
        let starts: Vec<&Element> = e.children_named("Start").collect();
        if starts.is_empty() {
            return Ok(None);
        }
        let texts = starts
            .iter()
            .map(|s| at.required(s, "value"))
            .collect::<Result<Vec<String>>>()?;
        return Ok(Some(if ty == ValueType::String {
            Values::String(texts)
        } else {
            Values::Binary(
                texts
                    .iter()
                    .map(|t| hex_decode(t).ok_or_else(|| bad(t)))
                    .collect::<Result<_>>()?,
            )
        }));
    }
    let Some(raw) = e.attr("start") else {
        return Ok(None);
    };
    let items = raw.split_whitespace();
    Ok(Some(match ty {
        ValueType::Float32 | ValueType::Float64 => Values::Float(
            items
                .map(|i| i.parse::<f64>().map_err(|_| bad(i)))
                .collect::<Result<_>>()?,
        ),
        ValueType::UInt8 | ValueType::UInt16 | ValueType::UInt32 | ValueType::UInt64 => {
            Values::UInt(
                items
                    .map(|i| i.parse::<u64>().map_err(|_| bad(i)))
                    .collect::<Result<_>>()?,
            )
        }
        ValueType::Boolean => Values::Boolean(
            items
                .map(|i| match i {
                    "true" | "1" => Ok(true),
                    "false" | "0" => Ok(false),
                    other => Err(bad(other)),
                })
                .collect::<Result<_>>()?,
        ),
        ValueType::Clock => return Ok(None),
        _ => Values::Int(
            items
                .map(|i| i.parse::<i64>().map_err(|_| bad(i)))
                .collect::<Result<_>>()?,
        ),
    }))
}

/// Hexadecimal text (as FMI 3.0 writes Binary start values) to bytes.
pub(crate) fn hex_decode(text: &str) -> Option<Vec<u8>> {
    let text = text.trim();
    let text = text
        .strip_prefix("0x")
        .or_else(|| text.strip_prefix("0X"))
        .unwrap_or(text);
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

/// Bytes as lowercase hexadecimal text.
pub(crate) fn hex_encode(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// One variable element, and the value reference its `derivative` names.
fn variable(
    at: Attrs<'_>,
    e: &Element,
    types: &[SimpleType],
) -> Result<(ScalarVariable, Option<ValueReference>)> {
    let Some(value_type) = ValueType::from_name(&e.name) else {
        return Err(at.invalid(
            e,
            format!("unknown variable element <{}> in <ModelVariables>", e.name),
        ));
    };
    let name = at.required(e, "name")?;
    let value_reference = at
        .parsed(e, "valueReference")?
        .ok_or_else(|| at.invalid(e, format!("variable '{name}' lacks 'valueReference'")))?;
    let structural_parameter = e.attr("causality").map(str::trim) == Some("structuralParameter");
    let causality = if structural_parameter {
        Causality::Parameter
    } else {
        at.choice(e, "causality", CAUSALITIES)?.unwrap_or_default()
    };
    let float = matches!(value_type, ValueType::Float32 | ValueType::Float64);
    let variability = at
        .choice(e, "variability", VARIABILITIES)?
        .unwrap_or(if float {
            Variability::Continuous
        } else {
            Variability::Discrete
        });
    if variability == Variability::Continuous && !float {
        return Err(at.invalid(
            e,
            format!("variable '{name}' is continuous but not of type Float32 or Float64"),
        ));
    }
    let Some(case) = initial_case(causality, variability) else {
        return Err(at.invalid(
            e,
            format!(
                "variable '{name}' combines causality {} with variability {variability:?}, which FMI 3.0 forbids",
                e.attr("causality").unwrap_or("local")
            ),
        ));
    };
    let initial = match at.choice(e, "initial", INITIALS)? {
        // FMI 3.0 lets inputs say initial="exact" (their start value is used).
        Some(Initial::Exact) if case == InitialCase::None => Some(Initial::Exact),
        Some(explicit) if case.allows(explicit) => Some(explicit),
        Some(explicit) => {
            at.quirk(
                "initial",
                e.line,
                format!(
                    "variable '{name}' declares initial={explicit:?}, not allowed for its \
                     causality and variability; using the default"
                ),
            );
            case.default_initial()
        }
        None => case.default_initial(),
    };
    let mut dimensions = Vec::new();
    for d in e.children_named("Dimension") {
        let start: Option<u64> = at.parsed(d, "start")?;
        let vr: Option<ValueReference> = at.parsed(d, "valueReference")?;
        dimensions.push(match (start, vr) {
            (Some(n), None) => Dimension::Fixed(n),
            (None, Some(vr)) => Dimension::Parameter(vr),
            _ => {
                return Err(at.invalid(
                    d,
                    format!("a <Dimension> of variable '{name}' must have exactly one of 'start' and 'valueReference'"),
                ))
            }
        });
    }
    let starts = start_values(at, e, value_type, &name)?;
    if let (true, Some(s)) = (dimensions.is_empty(), &starts) {
        if s.len() != 1 {
            return Err(at.invalid(
                e,
                format!(
                    "scalar variable '{name}' has {} start values, expected one",
                    s.len()
                ),
            ));
        }
    }
    let scalar = dimensions.is_empty();
    let simple = declared(at, e, &name, types)?;
    if let Some(t) = simple {
        let matches = t.value_type == value_type
            || (value_type == ValueType::Enumeration
                && matches!(t.kind, SimpleTypeKind::Enumeration { .. }));
        if !matches {
            return Err(at.invalid(
                e,
                format!(
                    "variable '{name}' is <{}> but its declaredType '{}' is a {}Type",
                    e.name,
                    t.name,
                    t.value_type.name()
                ),
            ));
        }
    }
    let declared_type = at.string(e, "declaredType");
    let mut derivative = None;
    let kind = match value_type {
        ValueType::Float32 | ValueType::Float64 => {
            let base = match simple.map(|t| &t.kind) {
                Some(SimpleTypeKind::Real(r)) => Some(r),
                _ => None,
            };
            derivative = at.parsed(e, "derivative")?;
            VariableKind::Real(RealVariable {
                declared_type,
                attributes: real_type(at, e, base)?,
                start: match (&starts, scalar) {
                    (Some(Values::Float(v)), true) => v.first().copied(),
                    _ => None,
                },
                derivative: None,
                reinit: at.flag(e, "reinit", false)?,
            })
        }
        ValueType::Boolean | ValueType::Clock => VariableKind::Boolean(BooleanVariable {
            declared_type,
            start: match (&starts, scalar) {
                (Some(Values::Boolean(v)), true) => v.first().copied(),
                _ => None,
            },
        }),
        ValueType::String | ValueType::Binary => VariableKind::String(StringVariable {
            declared_type,
            start: match (&starts, scalar) {
                (Some(Values::String(v)), true) => v.first().cloned(),
                (Some(Values::Binary(v)), true) => v.first().map(|b| hex_encode(b)),
                _ => None,
            },
        }),
        ValueType::Enumeration => {
            let quantity = match simple.map(|t| &t.kind) {
                Some(SimpleTypeKind::Enumeration { quantity, .. }) => quantity.clone(),
                _ => {
                    return Err(at.invalid(
                        e,
                        format!("enumeration variable '{name}' lacks the required declaredType"),
                    ))
                }
            };
            let base = IntegerType {
                quantity,
                min: None,
                max: None,
            };
            VariableKind::Enumeration(IntegerVariable {
                declared_type,
                attributes: integer_type(at, e, Some(&base))?,
                start: narrow_start(&starts, scalar),
            })
        }
        _ => {
            let base = match simple.map(|t| &t.kind) {
                Some(SimpleTypeKind::Integer(i)) => Some(i),
                _ => None,
            };
            VariableKind::Integer(IntegerVariable {
                declared_type,
                attributes: integer_type(at, e, base)?,
                start: narrow_start(&starts, scalar),
            })
        }
    };
    let variable = ScalarVariable {
        value_reference,
        description: at.string(e, "description"),
        causality,
        variability,
        initial,
        can_handle_multiple_set_per_time_instant: at
            .boolean(e, "canHandleMultipleSetPerTimeInstant")?,
        kind,
        value_type,
        dimensions,
        structural_parameter,
        intermediate_update: at.flag(e, "intermediateUpdate", false)?,
        previous: at.parsed(e, "previous")?,
        clocks: at.list(e, "clocks")?.unwrap_or_default(),
        start_values: starts,
        line: e.line,
        name,
    };
    Ok((variable, derivative))
}

/// A scalar integer start value where it fits the FMI 2.0 `i32`.
fn narrow_start(starts: &Option<Values>, scalar: bool) -> Option<i32> {
    if !scalar {
        return None;
    }
    match starts {
        Some(Values::Int(v)) => v.first().and_then(|&x| i32::try_from(x).ok()),
        Some(Values::UInt(v)) => v.first().and_then(|&x| i32::try_from(x).ok()),
        _ => None,
    }
}

fn model_structure(
    at: Attrs<'_>,
    s: &Element,
    index_of: &dyn Fn(ValueReference, &Element, &str) -> Result<usize>,
) -> Result<ModelStructure> {
    let mut structure = ModelStructure::default();
    for u in &s.children {
        let list = match u.name.as_str() {
            "Output" => &mut structure.outputs,
            "ContinuousStateDerivative" => &mut structure.derivatives,
            "ClockedState" => &mut structure.clocked_states,
            "InitialUnknown" => &mut structure.initial_unknowns,
            "EventIndicator" => &mut structure.event_indicators,
            other => {
                return Err(at.invalid(u, format!("unknown <ModelStructure> element <{other}>")))
            }
        };
        let vr: ValueReference = at
            .parsed(u, "valueReference")?
            .ok_or_else(|| at.invalid(u, format!("<{}> lacks 'valueReference'", u.name)))?;
        let index = index_of(vr, u, &format!("<{}>", u.name))?;
        let dependencies = match at.list::<ValueReference>(u, "dependencies")? {
            None => None,
            Some(vrs) => Some(
                vrs.into_iter()
                    .map(|d| {
                        index_of(
                            d,
                            u,
                            &format!("<{} valueReference=\"{vr}\"> dependency", u.name),
                        )
                    })
                    .collect::<Result<Vec<_>>>()?,
            ),
        };
        let dependencies_kind = match at.list::<String>(u, "dependenciesKind")? {
            None => None,
            Some(kinds) => Some(
                kinds
                    .iter()
                    .map(|k| dependency_kind(at, u, k))
                    .collect::<Result<Vec<_>>>()?,
            ),
        };
        if let (Some(d), Some(k)) = (&dependencies, &dependencies_kind) {
            if d.len() != k.len() {
                return Err(at.invalid(
                    u,
                    format!(
                        "<{} valueReference=\"{vr}\"> has {} dependencies but {} dependenciesKind entries",
                        u.name,
                        d.len(),
                        k.len()
                    ),
                ));
            }
        }
        list.push(Unknown {
            index,
            dependencies,
            dependencies_kind,
        });
    }
    Ok(structure)
}
