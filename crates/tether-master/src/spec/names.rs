//! Names in error messages: what a variable is ("a Real output"), and which
//! instance a misspelt name probably meant.

use tether_fmi::{BaseType, Causality, ModelDescription, ScalarVariable};

use crate::MasterError;

/// The variable `name` of an instance's model, or an error saying where the
/// name appears (`place`), in which instance and FMU (`fmu`: its file name,
/// or `model '…'`).
pub(crate) fn variable<'a>(
    md: &'a ModelDescription,
    place: &str,
    instance: &str,
    fmu: impl FnOnce() -> String,
    name: &str,
) -> Result<&'a ScalarVariable, MasterError> {
    md.variable(name).map_err(|e| match e {
        tether_fmi::Error::UnknownVariable { suggestions, .. } => {
            MasterError::UnknownVariable(Box::new(crate::UnknownName {
                place: place.to_string(),
                instance: instance.to_string(),
                fmu: fmu(),
                name: name.to_string(),
                suggestions,
            }))
        }
        e => e.into(),
    })
}

/// The sizes of an FMI 3.0 array variable's dimensions as the structural
/// parameters set make them ([`crate::Arrays`] knows them).
pub(crate) trait ArraySizes {
    /// The sizes of `v`'s dimensions (empty for a scalar).
    fn sizes(&self, md: &ModelDescription, v: &ScalarVariable) -> Result<Vec<u64>, MasterError>;
}

/// An element of an FMI 3.0 array variable: its place among the array's
/// values (row-major, 0-based) and their number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Element {
    /// Row-major, 0-based.
    pub index: usize,
    /// The number of values of the array.
    pub count: usize,
}

/// The variable or array element `name` (`y`, `y[2]`, `A[2,3]`, 1-based,
/// row-major) of an instance's model: the name is first looked up exactly
/// (FMI 3.0 structured names such as `pipe[3,4].T[14]` exist), then a
/// trailing subscript is read as an array index. `Some(element)` for an
/// element; the sizes follow the structural parameters set (`arrays`).
/// Errors say where the name appears, as [`variable`]'s.
pub(crate) fn element<'a>(
    md: &'a ModelDescription,
    arrays: &impl ArraySizes,
    place: &str,
    instance: &str,
    fmu: impl FnOnce() -> String,
    name: &str,
) -> Result<(&'a ScalarVariable, Option<Element>), MasterError> {
    if let Ok(var) = md.variable(name) {
        return Ok((var, None));
    }
    let split = name
        .strip_suffix(']')
        .and_then(|head| head.rsplit_once('['))
        .filter(|(base, _)| !base.is_empty());
    let Some((base, subscript)) = split else {
        return variable(md, place, instance, fmu, name).map(|v| (v, None));
    };
    let Ok(var) = md.variable(base) else {
        return variable(md, place, instance, fmu, name).map(|v| (v, None));
    };
    let fail = |reason: String| MasterError::ArrayElement {
        place: place.to_string(),
        instance: instance.to_string(),
        name: name.to_string(),
        reason,
    };
    if !var.is_array() {
        return Err(fail(format!(
            "'{base}' is {}, a scalar: it has no elements",
            describe(var)
        )));
    }
    let sizes = arrays.sizes(md, var)?;
    let shown = sizes
        .iter()
        .map(u64::to_string)
        .collect::<Vec<_>>()
        .join("×");
    let indices: Vec<u64> = subscript
        .split(',')
        .map(|i| i.trim().parse::<u64>().ok().filter(|&i| i >= 1))
        .collect::<Option<_>>()
        .ok_or_else(|| {
            fail(format!(
                "'[{subscript}]' is not a list of 1-based indices (array '{base}' is {shown})"
            ))
        })?;
    if indices.len() != sizes.len() {
        return Err(fail(format!(
            "array '{base}' has {} dimension{} ({shown}): give {} ind{}",
            sizes.len(),
            if sizes.len() == 1 { "" } else { "s" },
            sizes.len(),
            if sizes.len() == 1 { "ex" } else { "ices" },
        )));
    }
    let mut index = 0u64;
    for (k, (&i, &size)) in indices.iter().zip(&sizes).enumerate() {
        if i > size {
            let range = if size == 0 {
                "it is empty".to_string()
            } else {
                format!("valid: 1..={size}")
            };
            return Err(fail(format!(
                "index {i} is out of range in dimension {} of array '{base}' ({shown}; {range})",
                k + 1
            )));
        }
        index = index * size + (i - 1);
    }
    let count: u64 = sizes.iter().product();
    Ok((
        var,
        Some(Element {
            index: index as usize,
            count: count as usize,
        }),
    ))
}

/// An FMU's file name for messages: `oscillator.fmu`.
pub(crate) fn fmu_file(path: &std::path::Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// "a Real output", "an Integer parameter", … for error messages.
pub(crate) fn describe(var: &ScalarVariable) -> String {
    let ty = match var.base_type() {
        BaseType::Real => "Real",
        BaseType::Integer => "Integer",
        BaseType::Boolean => "Boolean",
        BaseType::String => "String",
        BaseType::Enumeration => "Enumeration",
    };
    let causality = match var.causality {
        Causality::Parameter => "parameter",
        Causality::CalculatedParameter => "calculated parameter",
        Causality::Input => "input",
        Causality::Output => "output",
        Causality::Local => "local variable",
        Causality::Independent => "independent variable",
    };
    let article = if matches!(var.base_type(), BaseType::Integer | BaseType::Enumeration) {
        "an"
    } else {
        "a"
    };
    format!("{article} {ty} {causality}")
}

/// The index of `instance` among `names`, or an error naming `owner` with the
/// close names ("did you mean …?") or, without any, all of them.
pub(crate) fn find_instance<'a>(
    owner: &str,
    instance: &str,
    names: impl Iterator<Item = &'a str> + Clone,
) -> Result<usize, MasterError> {
    if let Some(i) = names.clone().position(|n| n == instance) {
        return Ok(i);
    }
    let close: Vec<&str> = names.clone().filter(|n| similar(n, instance)).collect();
    let hint = if close.is_empty() {
        let all: Vec<&str> = names.collect();
        format!("; instances are: {}", all.join(", "))
    } else {
        format!("; did you mean '{}'?", close.join("', '"))
    };
    Err(MasterError::UnknownInstance {
        owner: owner.to_string(),
        instance: instance.to_string(),
        hint,
    })
}

/// `; did you mean 'a', 'b'?` with the close `names`, or `; columns are: …`
/// (the first twelve of them), for a name or pattern that matched nothing.
pub(crate) fn suggest<'a>(name: &str, names: impl Iterator<Item = &'a str> + Clone) -> String {
    let close: Vec<&str> = names.clone().filter(|n| similar(n, name)).take(6).collect();
    if !close.is_empty() {
        return format!("; did you mean '{}'?", close.join("', '"));
    }
    let all: Vec<&str> = names.collect();
    let shown: Vec<&str> = all.iter().take(12).copied().collect();
    let more = if all.len() > shown.len() {
        format!(" … ({} in all)", all.len())
    } else {
        String::new()
    };
    format!("; columns are: {}{more}", shown.join(", "))
}

/// Names within edit distance 2 or sharing a prefix of 3 characters.
fn similar(a: &str, b: &str) -> bool {
    let prefix = a.chars().zip(b.chars()).take_while(|(x, y)| x == y).count();
    prefix >= 3 || edit_distance(a, b) <= 2
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_names_are_suggested() {
        assert!(similar("mass1", "mas1"));
        assert!(similar("pendulum", "pendulum_b"));
        assert!(!similar("mass1", "crank"));
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        let names = ["mass1", "mass2", "crank"];
        assert_eq!(
            find_instance("x", "crank", names.iter().copied()).unwrap(),
            2
        );
        let err = find_instance("constraint 'c'", "mas1", names.iter().copied()).unwrap_err();
        assert!(
            err.to_string().contains("did you mean 'mass1', 'mass2'?"),
            "{err}"
        );
        let err = find_instance("constraint 'c'", "zzz", names.iter().copied()).unwrap_err();
        assert!(
            err.to_string()
                .contains("instances are: mass1, mass2, crank"),
            "{err}"
        );
    }
}
