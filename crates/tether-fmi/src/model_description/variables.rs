//! `ModelVariables`: one `ScalarVariable` per child, with the FMI 2.0 defaults for
//! causality, variability and initial applied (standard, section 2.2.7).

use super::attrs::Attrs;
use super::type_attrs::{integer_type, real_type};
use super::types::*;
use crate::error::Result;
use crate::xml::Element;

pub(super) const CAUSALITIES: &[(&str, Causality)] = &[
    ("parameter", Causality::Parameter),
    ("calculatedParameter", Causality::CalculatedParameter),
    ("input", Causality::Input),
    ("output", Causality::Output),
    ("local", Causality::Local),
    ("independent", Causality::Independent),
];

pub(super) const VARIABILITIES: &[(&str, Variability)] = &[
    ("constant", Variability::Constant),
    ("fixed", Variability::Fixed),
    ("tunable", Variability::Tunable),
    ("discrete", Variability::Discrete),
    ("continuous", Variability::Continuous),
];

pub(super) const INITIALS: &[(&str, Initial)] = &[
    ("exact", Initial::Exact),
    ("approx", Initial::Approx),
    ("calculated", Initial::Calculated),
];

/// The cases of the standard's causality × variability table that decide `initial`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum InitialCase {
    /// Only `exact`, the default.
    A,
    /// `approx` or `calculated`; default `calculated`.
    B,
    /// `exact`, `approx` or `calculated`; default `calculated`.
    C,
    /// `initial` must not be given (inputs, the independent variable).
    None,
}

impl InitialCase {
    pub(super) fn default_initial(self) -> Option<Initial> {
        match self {
            InitialCase::A => Some(Initial::Exact),
            InitialCase::B | InitialCase::C => Some(Initial::Calculated),
            InitialCase::None => None,
        }
    }

    pub(super) fn allows(self, initial: Initial) -> bool {
        match self {
            InitialCase::A => initial == Initial::Exact,
            InitialCase::B => initial != Initial::Exact,
            InitialCase::C => true,
            InitialCase::None => false,
        }
    }
}

/// The table of section 2.2.7: `None` for combinations the standard forbids.
pub(super) fn initial_case(causality: Causality, variability: Variability) -> Option<InitialCase> {
    use Causality as C;
    use Variability as V;
    match (variability, causality) {
        (V::Constant, C::Output | C::Local) => Some(InitialCase::A),
        (V::Fixed | V::Tunable, C::Parameter) => Some(InitialCase::A),
        (V::Fixed | V::Tunable, C::CalculatedParameter | C::Local) => Some(InitialCase::B),
        (V::Discrete | V::Continuous, C::Output | C::Local) => Some(InitialCase::C),
        (V::Discrete | V::Continuous, C::Input) => Some(InitialCase::None),
        (V::Continuous, C::Independent) => Some(InitialCase::None),
        _ => None,
    }
}

/// Parses every `ScalarVariable` child of `ModelVariables`.
pub(crate) fn parse_variables(
    at: Attrs<'_>,
    list: &Element,
    types: &[SimpleType],
) -> Result<Vec<ScalarVariable>> {
    let elements: Vec<&Element> = list.children_named("ScalarVariable").collect();
    let n = elements.len();
    let mut variables = Vec::with_capacity(n);
    for e in elements {
        let v = scalar_variable(at, e, types)?;
        if let Some(d) = v.real().and_then(|r| r.derivative) {
            if !(1..=n).contains(&d) {
                return Err(at.invalid(
                    e,
                    format!(
                        "variable '{}' has derivative=\"{d}\" outside 1..={n}",
                        v.name
                    ),
                ));
            }
        }
        variables.push(v);
    }
    Ok(variables)
}

fn scalar_variable(at: Attrs<'_>, e: &Element, types: &[SimpleType]) -> Result<ScalarVariable> {
    let name = at.required(e, "name")?;
    let value_reference = at
        .parsed(e, "valueReference")?
        .ok_or_else(|| at.invalid(e, format!("variable '{name}' lacks 'valueReference'")))?;
    let type_elements: Vec<&Element> = e
        .children
        .iter()
        .filter(|c| {
            matches!(
                c.name.as_str(),
                "Real" | "Integer" | "Boolean" | "String" | "Enumeration"
            )
        })
        .collect();
    let [type_element] = type_elements.as_slice() else {
        return Err(at.invalid(
            e,
            format!(
                "variable '{name}' must have exactly one type element (Real, Integer, Boolean, String or Enumeration), found {}",
                type_elements.len()
            ),
        ));
    };
    let kind = variable_kind(at, &name, type_element, types)?;
    let causality = at.choice(e, "causality", CAUSALITIES)?.unwrap_or_default();
    let default_variability = match kind {
        VariableKind::Real(_) => Variability::Continuous,
        // Only Real variables can be continuous (clarified in FMI 2.0.4/2.0.5).
        _ => Variability::Discrete,
    };
    let variability = at
        .choice(e, "variability", VARIABILITIES)?
        .unwrap_or(default_variability);
    if variability == Variability::Continuous && !matches!(kind, VariableKind::Real(_)) {
        return Err(at.invalid(
            e,
            format!("variable '{name}' is continuous but not of type Real"),
        ));
    }
    let Some(case) = initial_case(causality, variability) else {
        return Err(at.invalid(
            e,
            format!(
                "variable '{name}' combines causality {causality:?} with variability {variability:?}, which FMI 2.0 forbids"
            ),
        ));
    };
    let initial = match at.choice(e, "initial", INITIALS)? {
        Some(explicit) if case.allows(explicit) => Some(explicit),
        Some(explicit) => {
            at.quirk(
                "initial",
                e.line,
                format!(
                    "variable '{name}' declares initial={explicit:?}, not allowed for causality \
                     {causality:?} and variability {variability:?}; using the default"
                ),
            );
            case.default_initial()
        }
        None => case.default_initial(),
    };
    let value_type = match kind {
        VariableKind::Real(_) => ValueType::Float64,
        VariableKind::Integer(_) => ValueType::Int32,
        VariableKind::Boolean(_) => ValueType::Boolean,
        VariableKind::String(_) => ValueType::String,
        VariableKind::Enumeration(_) => ValueType::Enumeration,
    };
    Ok(ScalarVariable {
        value_type,
        dimensions: Vec::new(),
        structural_parameter: false,
        intermediate_update: false,
        previous: None,
        clocks: Vec::new(),
        start_values: None,
        value_reference,
        description: at.string(e, "description"),
        causality,
        variability,
        initial,
        can_handle_multiple_set_per_time_instant: at
            .boolean(e, "canHandleMultipleSetPerTimeInstant")?,
        kind,
        line: e.line,
        name,
    })
}

pub(super) fn declared<'t>(
    at: Attrs<'_>,
    e: &Element,
    variable: &str,
    types: &'t [SimpleType],
) -> Result<Option<&'t SimpleType>> {
    let Some(declared) = e.attr("declaredType") else {
        return Ok(None);
    };
    types
        .iter()
        .find(|t| t.name == declared)
        .map(Some)
        .ok_or_else(|| {
            at.invalid(
                e,
                format!("variable '{variable}' has declaredType=\"{declared}\", which TypeDefinitions does not define"),
            )
        })
}

fn mismatch(at: Attrs<'_>, e: &Element, variable: &str) -> crate::error::Error {
    at.invalid(
        e,
        format!(
            "variable '{variable}' is <{}> but its declaredType is of another kind",
            e.name
        ),
    )
}

fn variable_kind(
    at: Attrs<'_>,
    variable: &str,
    e: &Element,
    types: &[SimpleType],
) -> Result<VariableKind> {
    let simple = declared(at, e, variable, types)?;
    let declared_type = at.string(e, "declaredType");
    Ok(match e.name.as_str() {
        "Real" => {
            let base = match simple.map(|t| &t.kind) {
                None => None,
                Some(SimpleTypeKind::Real(r)) => Some(r),
                Some(_) => return Err(mismatch(at, e, variable)),
            };
            VariableKind::Real(RealVariable {
                declared_type,
                attributes: real_type(at, e, base)?,
                start: at.parsed(e, "start")?,
                derivative: at.parsed(e, "derivative")?,
                reinit: at.flag(e, "reinit", false)?,
            })
        }
        "Integer" => {
            let base = match simple.map(|t| &t.kind) {
                None => None,
                Some(SimpleTypeKind::Integer(i)) => Some(i),
                Some(_) => return Err(mismatch(at, e, variable)),
            };
            VariableKind::Integer(IntegerVariable {
                declared_type,
                attributes: integer_type(at, e, base)?,
                start: at.parsed(e, "start")?,
            })
        }
        "Boolean" => {
            if simple.is_some_and(|t| t.kind != SimpleTypeKind::Boolean) {
                return Err(mismatch(at, e, variable));
            }
            VariableKind::Boolean(BooleanVariable {
                declared_type,
                start: at.boolean(e, "start")?,
            })
        }
        "String" => {
            if simple.is_some_and(|t| t.kind != SimpleTypeKind::String) {
                return Err(mismatch(at, e, variable));
            }
            VariableKind::String(StringVariable {
                declared_type,
                start: at.string(e, "start"),
            })
        }
        _ => {
            let quantity = match simple.map(|t| &t.kind) {
                Some(SimpleTypeKind::Enumeration { quantity, .. }) => quantity.clone(),
                Some(_) => return Err(mismatch(at, e, variable)),
                None => {
                    return Err(at.invalid(
                        e,
                        format!(
                            "enumeration variable '{variable}' lacks the required declaredType"
                        ),
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
                start: at.parsed(e, "start")?,
            })
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn initial_defaults_follow_the_standard_table() {
        use Causality as C;
        use Variability as V;
        let d = |c, v| initial_case(c, v).and_then(InitialCase::default_initial);
        assert_eq!(d(C::Parameter, V::Fixed), Some(Initial::Exact));
        assert_eq!(
            d(C::CalculatedParameter, V::Tunable),
            Some(Initial::Calculated)
        );
        assert_eq!(d(C::Output, V::Continuous), Some(Initial::Calculated));
        assert_eq!(d(C::Output, V::Constant), Some(Initial::Exact));
        assert_eq!(d(C::Local, V::Continuous), Some(Initial::Calculated));
        assert_eq!(d(C::Input, V::Continuous), None);
        assert!(initial_case(C::Parameter, V::Continuous).is_none());
        assert!(initial_case(C::Input, V::Constant).is_none());
        assert!(InitialCase::C.allows(Initial::Exact));
        assert!(!InitialCase::B.allows(Initial::Exact));
    }
}
