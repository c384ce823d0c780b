//! Applying start values (parameters, input starts) to an instance by name:
//! scalars, FMI 3.0 arrays whole (a TOML array, flat in row-major order or
//! nested) or element by element (`A[2,3]`), structural parameters first.

use std::collections::HashMap;

use tether_fmi::{
    BaseType, Causality, FmuInstance, Int, ModelDescription, ScalarVariable, Values, Variability,
    VariableKind,
};

use crate::observer::integer_value;
use crate::spec::names::{describe, ArraySizes, Element};
use crate::spec::StartValue;
use crate::MasterError;

/// What an instance's start values did to its FMI 3.0 arrays: the structural
/// parameters set (the arrays' sizes follow them), and the Real arrays set.
#[derive(Debug, Clone, Default)]
pub struct Arrays {
    /// Structural parameters set, by value reference.
    structural: HashMap<u32, u64>,
    /// Real arrays set, by value reference: all their values.
    reals: HashMap<u32, Vec<f64>>,
    /// Every array set, by value reference: all its values as last set.
    set: HashMap<u32, Vec<StartValue>>,
}

impl ArraySizes for Arrays {
    fn sizes(&self, md: &ModelDescription, v: &ScalarVariable) -> Result<Vec<u64>, MasterError> {
        Ok(md.array_sizes_with(v, &|vr| self.structural.get(&vr).copied())?)
    }
}

impl Arrays {
    /// The sizes of `v`'s dimensions (empty for a scalar).
    pub fn sizes(
        &self,
        md: &ModelDescription,
        v: &ScalarVariable,
    ) -> Result<Vec<u64>, MasterError> {
        ArraySizes::sizes(self, md, v)
    }

    /// The number of values of `v` (1 for a scalar).
    pub fn count(&self, md: &ModelDescription, v: &ScalarVariable) -> Result<usize, MasterError> {
        Ok(self.sizes(md, v)?.iter().product::<u64>() as usize)
    }

    /// The names of `v`'s values: `y[1]`, `A[2,3]`, or the name of a scalar.
    pub fn element_names(
        &self,
        md: &ModelDescription,
        v: &ScalarVariable,
    ) -> Result<Vec<String>, MasterError> {
        Ok(tether_fmi::element_names(&v.name, &self.sizes(md, v)?))
    }

    /// Set element `index` of array `var` to `value`, its other elements at
    /// their values as last set (else their start values): the array is set
    /// whole. The value's type is checked, not its range (as for a scalar a
    /// connection sets).
    pub(crate) fn set_element(
        &mut self,
        instance: &mut dyn FmuInstance,
        md: &ModelDescription,
        var: &ScalarVariable,
        index: usize,
        value: StartValue,
        fail: impl Fn(String) -> MasterError,
    ) -> Result<(), MasterError> {
        let n = self.count(md, var)?;
        let list = self
            .set
            .entry(var.value_reference)
            .or_insert_with(|| start_list(var, n));
        if list.len() != n {
            *list = start_list(var, n);
        }
        if list.len() != n {
            return Err(fail(format!(
                "array '{}' has {n} elements but no start value for each: set it whole first",
                var.name
            )));
        }
        // The record follows the FMU: a refused value leaves both as they were.
        let before = std::mem::replace(&mut list[index], value);
        match write_array(instance, var, list, fail) {
            Ok(Some(reals)) => {
                self.reals.insert(var.value_reference, reals);
            }
            Ok(None) => {}
            Err(e) => {
                list[index] = before;
                return Err(e);
            }
        }
        Ok(())
    }

    /// Set array `var` whole to `list` (row-major), checked as in `parameters`.
    pub(crate) fn set_whole(
        &mut self,
        instance: &mut dyn FmuInstance,
        md: &ModelDescription,
        var: &ScalarVariable,
        value: &StartValue,
        fail: impl Fn(String) -> MasterError,
    ) -> Result<(), MasterError> {
        let list = whole(var, &self.sizes(md, var)?, value).map_err(&fail)?;
        if let Some(reals) = set_array(instance, var, &list, fail)? {
            self.reals.insert(var.value_reference, reals);
        }
        self.set.insert(var.value_reference, list);
        Ok(())
    }

    /// The values of Real array `v` as set, else its start values (one start
    /// value stands for every element), else zeros.
    pub(crate) fn real_values(
        &self,
        md: &ModelDescription,
        v: &ScalarVariable,
    ) -> Result<Vec<f64>, MasterError> {
        let n = self.count(md, v)?;
        if let Some(set) = self.reals.get(&v.value_reference).filter(|x| x.len() == n) {
            return Ok(set.clone());
        }
        Ok(match &v.start_values {
            Some(Values::Float(x)) if x.len() == n => x.clone(),
            Some(Values::Float(x)) if x.len() == 1 => vec![x[0]; n],
            _ => vec![0.0; n],
        })
    }
}

/// Set every `name = value` on `instance` before initialization: structural
/// parameters first (in configuration mode, FMI 3.0), then the others in
/// order; an array is set whole, elements given one by one completing the
/// start values. Refuses what [`apply_start_value`] refuses, and arrays of the
/// wrong length, with a message naming the variable.
pub fn apply_start_values<'v>(
    instance: &mut dyn FmuInstance,
    md: &ModelDescription,
    values: impl IntoIterator<Item = (&'v str, &'v StartValue)>,
) -> Result<Arrays, MasterError> {
    let values: Vec<(&str, &StartValue)> = values.into_iter().collect();
    let mut arrays = Arrays::default();
    let structural = |name: &str| md.variable(name).ok().filter(|v| v.structural_parameter);
    for &(name, value) in &values {
        if let Some(var) = structural(name) {
            apply_start_value(instance, md, name, value)?;
            if let StartValue::Integer(n) = value {
                if let Ok(n) = u64::try_from(*n) {
                    arrays.structural.insert(var.value_reference, n);
                }
            }
        }
    }
    // Arrays: all their values, set once after the scalars.
    let mut pending: Vec<(&ScalarVariable, Vec<StartValue>, &str, &StartValue)> = Vec::new();
    for &(name, value) in &values {
        if structural(name).is_some() {
            continue;
        }
        let owner = instance.name().to_string();
        let (var, element) = crate::spec::names::element(
            md,
            &arrays,
            "parameters",
            &owner,
            || format!("model '{}'", md.model_name),
            name,
        )?;
        if !var.is_array() {
            apply_start_value(instance, md, name, value)?;
            continue;
        }
        let fail = |reason: String| MasterError::StartValue {
            instance: owner.clone(),
            variable: name.to_string(),
            value: value.to_string(),
            reason,
        };
        settable(var).map_err(&fail)?;
        let sizes = arrays.sizes(md, var)?;
        let n = sizes.iter().product::<u64>() as usize;
        let slot = match pending.iter().position(|p| std::ptr::eq(p.0, var)) {
            Some(i) => i,
            None => {
                pending.push((var, start_list(var, n), name, value));
                pending.len() - 1
            }
        };
        match element {
            Some(Element { index, .. }) => {
                if matches!(value, StartValue::Array(_)) {
                    return Err(fail("an element takes one value, not an array".into()));
                }
                if pending[slot].1.len() != n {
                    return Err(fail(format!(
                        "array '{}' has {n} elements but {} start values (its sizes changed): set it whole",
                        var.name,
                        pending[slot].1.len()
                    )));
                }
                pending[slot].1[index] = value.clone();
            }
            None => pending[slot].1 = whole(var, &sizes, value).map_err(&fail)?,
        }
        pending[slot].2 = name;
        pending[slot].3 = value;
    }
    for (var, list, name, value) in pending {
        let owner = instance.name().to_string();
        let fail = |reason: String| MasterError::StartValue {
            instance: owner.clone(),
            variable: name.to_string(),
            value: value.to_string(),
            reason,
        };
        let reals = set_array(instance, var, &list, fail)?;
        if let Some(reals) = reals {
            arrays.reals.insert(var.value_reference, reals);
        }
        arrays.set.insert(var.value_reference, list);
    }
    Ok(arrays)
}

/// `value` as all the values of array `var` of `sizes`, row-major (a TOML
/// array flat or nested), or why it does not fit.
fn whole(
    var: &ScalarVariable,
    sizes: &[u64],
    value: &StartValue,
) -> Result<Vec<StartValue>, String> {
    let n = sizes.iter().product::<u64>() as usize;
    let mut list = Vec::new();
    value.flatten_into(&mut list);
    if list.len() != n {
        let shown: Vec<String> = sizes.iter().map(u64::to_string).collect();
        return Err(format!(
            "array '{}' is {} = {n} elements (row-major), the value has {}",
            var.name,
            shown.join("×"),
            list.len()
        ));
    }
    Ok(list)
}

/// Whether a start value may be given for `var`, or why not.
fn settable(var: &ScalarVariable) -> Result<(), String> {
    if matches!(
        var.causality,
        Causality::Output
            | Causality::Local
            | Causality::Independent
            | Causality::CalculatedParameter
    ) || var.variability == Variability::Constant
    {
        return Err(format!("it is {} and cannot be set", describe(var)));
    }
    Ok(())
}

/// `var`'s start values as `n` start values (one stands for all; none or
/// another number: `n` of a type's zero, to be overwritten).
fn start_list(var: &ScalarVariable, n: usize) -> Vec<StartValue> {
    let list: Vec<StartValue> = match &var.start_values {
        Some(Values::Float(x)) => x.iter().map(|&x| StartValue::Real(x)).collect(),
        Some(Values::Int(x)) => x.iter().map(|&x| StartValue::Integer(x)).collect(),
        Some(Values::UInt(x)) => x
            .iter()
            .map(|&x| StartValue::Integer(i64::try_from(x).unwrap_or(i64::MAX)))
            .collect(),
        Some(Values::Boolean(x)) => x.iter().map(|&x| StartValue::Boolean(x)).collect(),
        Some(Values::String(x)) => x.iter().map(|x| StartValue::String(x.clone())).collect(),
        Some(Values::Binary(x)) => x
            .iter()
            .map(|x| StartValue::String(x.iter().map(|b| format!("{b:02x}")).collect()))
            .collect(),
        None => Vec::new(),
    };
    match list.len() {
        l if l == n => list,
        1 => vec![list[0].clone(); n],
        _ => Vec::new(),
    }
}

/// Set all values of array `var` (checked against its type and range); the
/// values of a Real array are returned.
fn set_array(
    instance: &mut dyn FmuInstance,
    var: &ScalarVariable,
    list: &[StartValue],
    fail: impl Fn(String) -> MasterError,
) -> Result<Option<Vec<f64>>, MasterError> {
    for (k, x) in list.iter().enumerate() {
        check_range(&var.kind, x)
            .map_err(|r| fail(format!("element {} (row-major): {r}", k + 1)))?;
    }
    write_array(instance, var, list, fail)
}

/// Set all values of array `var`, checked against its type only.
fn write_array(
    instance: &mut dyn FmuInstance,
    var: &ScalarVariable,
    list: &[StartValue],
    fail: impl Fn(String) -> MasterError,
) -> Result<Option<Vec<f64>>, MasterError> {
    let vr = [var.value_reference];
    let at = |k: usize, reason: String| fail(format!("element {} (row-major): {reason}", k + 1));
    let wrong = |k: usize| at(k, format!("the variable is {}", describe(var)));
    match var.base_type() {
        BaseType::Real => {
            let mut reals = Vec::with_capacity(list.len());
            for (k, x) in list.iter().enumerate() {
                reals.push(match x {
                    StartValue::Real(x) => *x,
                    StartValue::Integer(i) => as_real(*i).map_err(|r| at(k, r))?,
                    _ => return Err(wrong(k)),
                });
            }
            instance.set_reals(&vr, &reals)?;
            return Ok(Some(reals));
        }
        BaseType::Integer | BaseType::Enumeration => {
            let mut ints = Vec::with_capacity(list.len());
            for (k, x) in list.iter().enumerate() {
                let StartValue::Integer(i) = x else {
                    return Err(wrong(k));
                };
                ints.push(Int::from(*i));
            }
            instance.set_integers(&vr, &ints)?;
        }
        BaseType::Boolean => {
            let mut bools = Vec::with_capacity(list.len());
            for (k, x) in list.iter().enumerate() {
                let StartValue::Boolean(b) = x else {
                    return Err(wrong(k));
                };
                bools.push(*b);
            }
            instance.set_booleans(&vr, &bools)?;
        }
        BaseType::String => {
            let mut texts = Vec::with_capacity(list.len());
            for (k, x) in list.iter().enumerate() {
                let StartValue::String(s) = x else {
                    return Err(wrong(k));
                };
                texts.push(s.as_str());
            }
            instance.set_strings(&vr, &texts)?;
        }
    }
    Ok(None)
}

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
    settable(var).map_err(&fail)?;
    if var.is_array() {
        return apply_start_values(instance, md, [(name, value)]).map(|_| ());
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
    arrays: &mut Arrays,
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
    let (var, element) = crate::spec::names::element(
        md,
        arrays,
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
    match element {
        Some(Element { index, .. }) if !matches!(value, StartValue::Array(_)) => {
            check_range(&var.kind, value).map_err(&fail)?;
            arrays.set_element(instance, md, var, index, value.clone(), fail)?
        }
        Some(_) => return Err(fail("an element takes one value, not an array".into())),
        None if var.is_array() => arrays.set_whole(instance, md, var, value, fail)?,
        None => set_value(instance, var, value, fail)?,
    }
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
        (BaseType::Real, StartValue::Integer(i)) => {
            instance.set_reals(&vr, &[as_real(*i).map_err(&fail)?])?
        }
        (BaseType::Integer | BaseType::Enumeration, StartValue::Integer(i)) => {
            instance.set_integers(&vr, &[Int::from(*i)])?
        }
        (BaseType::Boolean, StartValue::Boolean(b)) => instance.set_booleans(&vr, &[*b])?,
        (BaseType::String, StartValue::String(s)) => instance.set_strings(&vr, &[s.as_str()])?,
        _ => return Err(fail(format!("the variable is {}", describe(var)))),
    }
    Ok(())
}

/// Refuses NaN/infinite Reals and values outside the variable's declared `min`/`max`
/// before the FMU sees them (FMUs are not required to check, and many do not).
/// An integer literal given for a Real variable, refused where the float
/// would round it.
fn as_real(i: i64) -> Result<f64, String> {
    match integer_value(Int::from(i)) {
        (x, true) => Ok(x),
        (x, false) => Err(format!(
            "the integer {i} has no exact Real value (the nearest is {x}); write it as a float"
        )),
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    /// The Reference FMU `StateSpace` (tests/fixtures/reference-fmus): `y` has `r`
    /// elements, `C` is `r`×`n`.
    fn state_space() -> tether_fmi::Fmu {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/fixtures/reference-fmus/fmi3/StateSpace.fmu");
        tether_fmi::Fmu::open_unloaded(&path, &Default::default()).unwrap()
    }

    #[test]
    fn sizes_names_and_elements_follow_the_structural_parameters_set() {
        let fmu = state_space();
        let md = fmu.model_description();
        let vr = |name: &str| md.variable(name).unwrap().value_reference;
        let y = md.variable("y").unwrap();
        let c = md.variable("C").unwrap();
        let start = Arrays::default();
        assert_eq!(start.sizes(md, y).unwrap(), [3]);
        let mut set = Arrays::default();
        set.structural.insert(vr("r"), 2);
        set.structural.insert(vr("n"), 1);
        assert_eq!(set.sizes(md, y).unwrap(), [2]);
        assert_eq!(set.element_names(md, c).unwrap(), ["C[1,1]", "C[2,1]"]);
        let find = |arrays: &Arrays, name: &str| {
            crate::spec::names::element(md, arrays, "here", "ss", String::new, name)
                .map(|(v, e)| (v.name.clone(), e))
        };
        assert_eq!(
            find(&set, "y[2]").unwrap(),
            ("y".into(), Some(Element { index: 1, count: 2 }))
        );
        assert_eq!(
            find(&start, "C[3,2]").unwrap().1,
            Some(Element { index: 7, count: 9 })
        );
        let err = find(&set, "y[3]").unwrap_err().to_string();
        assert!(err.contains("valid: 1..=2"), "{err}");
        let err = find(&set, "C[1,2]").unwrap_err().to_string();
        assert!(err.contains("dimension 2") && err.contains("2×1"), "{err}");
        // A Real array set whole keeps its values for the elements nobody drives.
        set.reals.insert(vr("y"), vec![4.0, 5.0]);
        assert_eq!(set.real_values(md, y).unwrap(), [4.0, 5.0]);
        let u = md.variable("u").unwrap();
        assert_eq!(start.real_values(md, u).unwrap(), [1.0, 2.0, 3.0]);
    }
}

/// A value the user set on a scalar parameter declared `initial="exact"`:
/// read back after initialization, where an FMU that resets its parameters
/// (in `fmi2SetupExperiment` or its initialization) shows the change.
#[derive(Debug, Clone)]
pub(crate) struct ExactParameter {
    name: String,
    vr: u32,
    base: BaseType,
    float32: bool,
    value: StartValue,
}

/// The values of `values` set on scalar parameters with `initial="exact"`
/// (the last one of each variable).
pub(crate) fn exact_parameters<'v>(
    md: &ModelDescription,
    values: impl IntoIterator<Item = (&'v str, &'v StartValue)>,
) -> Vec<ExactParameter> {
    let mut out: Vec<ExactParameter> = Vec::new();
    for (name, value) in values {
        let Ok(var) = md.variable(name) else { continue };
        if var.causality != Causality::Parameter
            || var.initial != Some(tether_fmi::Initial::Exact)
            || var.is_array()
        {
            continue;
        }
        if matches!(
            var.value_type,
            tether_fmi::ValueType::Binary | tether_fmi::ValueType::Clock
        ) {
            continue;
        }
        let base = match var.base_type() {
            BaseType::Enumeration => BaseType::Integer,
            b => b,
        };
        out.retain(|p| p.vr != var.value_reference || p.base != base);
        out.push(ExactParameter {
            name: var.name.clone(),
            vr: var.value_reference,
            base,
            float32: var.value_type == tether_fmi::ValueType::Float32,
            value: value.clone(),
        });
    }
    out
}

/// Read `parameters` back (calls the caller does not count) and say, one
/// line each, which the FMU changed: compared as the variable's type (a
/// Float32 after rounding the value set to f32). `receivers` are the value
/// references signal connections set, left out.
pub(crate) fn changed_parameters(
    instance: &mut dyn FmuInstance,
    parameters: &[ExactParameter],
    receivers: &[u32],
) -> Result<Vec<String>, MasterError> {
    let mut lines = Vec::new();
    for p in parameters.iter().filter(|p| !receivers.contains(&p.vr)) {
        let vr = [p.vr];
        let read = match (p.base, &p.value) {
            (BaseType::Real, set) => {
                let set = match set {
                    StartValue::Real(x) => *x,
                    StartValue::Integer(i) => *i as f64,
                    _ => continue,
                };
                let mut out = [0.0];
                instance.get_reals(&vr, &mut out)?;
                let expected = if p.float32 {
                    f64::from(set as f32)
                } else {
                    set
                };
                let same = out[0] == expected || (out[0].is_nan() && expected.is_nan());
                (!same).then(|| out[0].to_string())
            }
            (BaseType::Integer, StartValue::Integer(i)) => {
                let mut out = [Int::from(0i32)];
                instance.get_integers(&vr, &mut out)?;
                (out[0] != Int::from(*i)).then(|| out[0].to_string())
            }
            (BaseType::Boolean, StartValue::Boolean(b)) => {
                let mut out = [false];
                instance.get_booleans(&vr, &mut out)?;
                (out[0] != *b).then(|| out[0].to_string())
            }
            (BaseType::String, StartValue::String(s)) => {
                let mut out = [String::new()];
                instance.get_strings(&vr, &mut out)?;
                (out[0] != *s).then(|| format!("{:?}", out[0]))
            }
            _ => None,
        };
        if let Some(read) = read {
            lines.push(format!(
                "instance '{}': the FMU changed parameter '{}' in its initialization: set to {}, reads {read}",
                instance.name(),
                p.name,
                p.value
            ));
        }
    }
    Ok(lines)
}
