//! Applying start values (parameters, input starts) to an instance by name.

use tether_fmi::{
    BaseType, Causality, FmuInstance, ModelDescription, ScalarVariable, Variability, VariableKind,
};

use crate::spec::names::describe;
use crate::spec::StartValue;
use crate::MasterError;

/// Set `name = value` on `instance` before initialization. Refuses outputs,
/// locals, constants and type mismatches with a message naming the variable.
pub fn apply_start_value(
    instance: &mut dyn FmuInstance,
    md: &ModelDescription,
    name: &str,
    value: &StartValue,
) -> Result<(), MasterError> {
    let owner = instance.name().to_string();
    let fail = |reason: String| MasterError::StartValue {
        instance: owner.clone(),
        variable: name.to_string(),
        value: value.to_string(),
        reason,
    };
    let var = crate::spec::names::variable(
        md,
        "parameters",
        &owner,
        || format!("model '{}'", md.model_name),
        name,
    )?;
    if matches!(
        var.causality,
        Causality::Output
            | Causality::Local
            | Causality::Independent
            | Causality::CalculatedParameter
    ) || var.variability == Variability::Constant
    {
        return Err(fail(format!("it is {} and cannot be set", describe(var))));
    }
    set_value(instance, var, value, fail)
}

/// Set `name = value` on `instance` between macro steps, where FMI 2.0 allows
/// it: an input other than those the coupling drives (`coupled`: their value
/// references), or a tunable parameter. Refuses fixed parameters and
/// everything else with a message naming the variable.
pub(crate) fn set_between_steps(
    instance: &mut dyn FmuInstance,
    md: &ModelDescription,
    name: &str,
    value: &StartValue,
    coupled: &[u32],
) -> Result<BaseType, MasterError> {
    let owner = instance.name().to_string();
    let fail = |reason: String| MasterError::StartValue {
        instance: owner.clone(),
        variable: name.to_string(),
        value: value.to_string(),
        reason: format!("{reason} (between steps)"),
    };
    let var = crate::spec::names::variable(
        md,
        "set_parameter",
        &owner,
        || format!("model '{}'", md.model_name),
        name,
    )?;
    let settable = match var.causality {
        Causality::Input => var.variability != Variability::Constant,
        Causality::Parameter => var.variability == Variability::Tunable,
        _ => false,
    };
    if !settable {
        let what = describe(var);
        return Err(fail(match (var.causality, var.variability) {
            (Causality::Parameter, Variability::Fixed) => format!(
                "it is {what} with variability \"fixed\", which FMI 2.0 lets a master set only \
                 before initialization; give it as a start value (parameters, --set)"
            ),
            _ => format!("it is {what}; only inputs and tunable parameters can be set"),
        }));
    }
    if coupled.contains(&var.value_reference) {
        return Err(fail(
            "it is an input the coupling drives; the master sets it at every step".into(),
        ));
    }
    set_value(instance, var, value, fail)?;
    Ok(var.base_type())
}

/// Check `value` against the variable's type and range, then set it.
fn set_value(
    instance: &mut dyn FmuInstance,
    var: &ScalarVariable,
    value: &StartValue,
    fail: impl Fn(String) -> MasterError,
) -> Result<(), MasterError> {
    let vr = [var.value_reference];
    check_range(&var.kind, value).map_err(&fail)?;
    match (var.base_type(), value) {
        (BaseType::Real, StartValue::Real(x)) => instance.set_reals(&vr, &[*x])?,
        (BaseType::Real, StartValue::Integer(i)) => instance.set_reals(&vr, &[*i as f64])?,
        (BaseType::Integer | BaseType::Enumeration, StartValue::Integer(i)) => {
            let i =
                i32::try_from(*i).map_err(|_| fail("out of the 32-bit integer range".into()))?;
            instance.set_integers(&vr, &[i])?
        }
        (BaseType::Boolean, StartValue::Boolean(b)) => instance.set_booleans(&vr, &[*b])?,
        (BaseType::String, StartValue::String(s)) => instance.set_strings(&vr, &[s.as_str()])?,
        _ => return Err(fail(format!("the variable is {}", describe(var)))),
    }
    Ok(())
}

/// Refuses NaN/infinite Reals and values outside the variable's declared `min`/`max`
/// before the FMU sees them (FMUs are not required to check, and many do not).
fn check_range(kind: &VariableKind, value: &StartValue) -> Result<(), String> {
    let (min, max, x) = match (kind, value) {
        (VariableKind::Real(r), StartValue::Real(x)) => (r.attributes.min, r.attributes.max, *x),
        (VariableKind::Real(r), StartValue::Integer(i)) => {
            (r.attributes.min, r.attributes.max, *i as f64)
        }
        (VariableKind::Integer(v) | VariableKind::Enumeration(v), StartValue::Integer(i)) => (
            v.attributes.min.map(f64::from),
            v.attributes.max.map(f64::from),
            *i as f64,
        ),
        _ => return Ok(()),
    };
    if !x.is_finite() {
        return Err("not a finite number".into());
    }
    if let Some(min) = min.filter(|m| x < *m) {
        return Err(format!("below the declared min = {min}"));
    }
    if let Some(max) = max.filter(|m| x > *m) {
        return Err(format!("above the declared max = {max}"));
    }
    Ok(())
}
