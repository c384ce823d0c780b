//! Which inputs of an FMU take coupling polynomials (k > 0), and one plain
//! reason when one does not: the same sentence in `tether info`, in the refusal
//! of `tether run` and in the docs.

use tether_fmi::{BaseType, Causality, FmiStandard, ModelDescription, ScalarVariable};

/// The start of every refusal of k > 0.
pub const NEEDS: &str = "k > 0 needs inputs that take polynomials";

/// Why the FMU as a whole passes no polynomials, or `None` when it can
/// (FMI 2.0: `canInterpolateInputs`; FMI 3.0: `providesIntermediateUpdate`).
pub fn fmu_refusal(md: &ModelDescription) -> Option<String> {
    let cs = md.cs();
    if md.standard == FmiStandard::Fmi3 {
        (!cs.provides_intermediate_update).then(|| {
            "the FMU does not provide intermediate update (providesIntermediateUpdate), \
             FMI 3.0's only way to pass them"
                .to_string()
        })
    } else {
        (!cs.can_interpolate_inputs)
            .then(|| "the FMU does not declare canInterpolateInputs".to_string())
    }
}

/// Why input `var` (or an element of it) takes no polynomial, or `None` when
/// it takes one.
pub fn input_refusal(md: &ModelDescription, var: &ScalarVariable) -> Option<String> {
    if let Some(reason) = fmu_refusal(md) {
        return Some(reason);
    }
    if md.standard != FmiStandard::Fmi3 {
        return None;
    }
    if var.is_array() {
        return Some(format!("array elements of '{}' take values only", var.name));
    }
    if !var.intermediate_update {
        return Some(format!(
            "input '{}' is not declared intermediateUpdate=\"true\"",
            var.name
        ));
    }
    None
}

/// What `tether info` says about k > 0: `yes`, `yes, into a, b (…)` or
/// `no: k > 0 needs …; <reason>`.
pub fn summary(md: &ModelDescription) -> String {
    if let Some(reason) = fmu_refusal(md) {
        return format!("no: {NEEDS}; {reason}");
    }
    if md.standard != FmiStandard::Fmi3 {
        return "yes".into();
    }
    let inputs: Vec<&ScalarVariable> = md
        .model_variables
        .iter()
        .filter(|v| v.causality == Causality::Input && v.base_type() == BaseType::Real)
        .collect();
    let (yes, no): (Vec<&ScalarVariable>, Vec<&ScalarVariable>) =
        inputs.iter().partition(|v| input_refusal(md, v).is_none());
    let first_no = no.first().and_then(|v| input_refusal(md, v));
    let more = match no.len() {
        0 | 1 => String::new(),
        n => format!(" (and {} more)", n - 1),
    };
    match (yes.is_empty(), first_no) {
        (true, None) => "yes, through intermediate update (the FMU has no Real inputs)".into(),
        (true, Some(reason)) => format!("no: {NEEDS}; {reason}{more}"),
        (false, none_or_some) => {
            let names: Vec<String> = yes.iter().map(|v| format!("'{}'", v.name)).collect();
            let mut text = format!(
                "yes, through intermediate update, into {}",
                names.join(", ")
            );
            if let Some(reason) = none_or_some {
                text.push_str(&format!("; not others: {reason}{more}"));
            }
            text
        }
    }
}
