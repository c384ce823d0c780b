//! `[export]`: the interface of the system exported as one FMU
//! (`tether fmu export`, docs/fmu-export.md). Here the file's own checks;
//! the names are resolved against the FMUs by
//! [`crate::Simulation::export_interface`].

use serde::{Deserialize, Serialize};

use super::SystemSpec;
use crate::MasterError;

/// `[export]`: the exported FMU's model name and its variables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportSpec {
    /// The exported FMU's `modelName` and `modelIdentifier`.
    pub model_name: String,
    /// `[[export.input]]`: a Real input of the exported FMU setting an
    /// instance input that the coupling does not drive.
    #[serde(rename = "input", default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<ExportLink>,
    /// `[[export.output]]`: a Real output of the exported FMU reading a
    /// column of the system (an instance output, `<constraint>.lambda`, …).
    #[serde(rename = "output", default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<ExportSource>,
    /// `[[export.parameter]]`: a Real parameter of the exported FMU setting
    /// an instance parameter before initialization.
    #[serde(rename = "parameter", default, skip_serializing_if = "Vec::is_empty")]
    pub parameters: Vec<ExportLink>,
}

/// An exported input or parameter: `name` sets `to` (`instance.variable`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportLink {
    pub name: String,
    pub to: String,
}

/// An exported output: `name` reads the column `from`. Without `name` the
/// output is named as the column (`chassis.position`), so that results of
/// the exported FMU compare with those of the system by column name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportSource {
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub name: String,
    pub from: String,
}

impl ExportSource {
    /// The exported output's name: `name`, else the column `from`.
    pub fn name(&self) -> &str {
        if self.name.is_empty() {
            &self.from
        } else {
            &self.name
        }
    }
}

impl ExportSpec {
    /// Every exported variable as (kind, name, target) in value-reference
    /// order: parameters, inputs, outputs.
    pub fn variables(&self) -> impl Iterator<Item = (&'static str, &str, &str)> {
        let parameters = self
            .parameters
            .iter()
            .map(|p| ("parameter", p.name.as_str(), p.to.as_str()));
        let inputs = self
            .inputs
            .iter()
            .map(|i| ("input", i.name.as_str(), i.to.as_str()));
        let outputs = self
            .outputs
            .iter()
            .map(|o| ("output", o.name(), o.from.as_str()));
        parameters.chain(inputs).chain(outputs)
    }
}

fn identifier(name: &str) -> bool {
    name.chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl SystemSpec {
    /// The checks of `[export]` that need no FMU: a model name that is a C
    /// identifier, variable names that are unique, and no instance variable
    /// set by two exported variables.
    pub(crate) fn validate_export(&self) -> Result<(), MasterError> {
        let Some(export) = &self.export else {
            return Ok(());
        };
        let error = |reason: String| MasterError::SystemFile {
            path: self.source_name(),
            reason,
        };
        if !identifier(&export.model_name) {
            return Err(error(format!(
                "[export] model_name '{}' must start with a letter and contain only ASCII letters, digits and '_' (it names the FMU's binary)",
                export.model_name
            )));
        }
        let mut names = std::collections::HashMap::new();
        let mut targets = std::collections::HashMap::new();
        for (kind, name, target) in export.variables() {
            if name.is_empty()
                || name
                    .chars()
                    .any(|c| c.is_control() || c == '"' || c == '<' || c == '>' || c == '&')
            {
                return Err(error(format!(
                    "[[export.{kind}]] name {name:?} must be a non-empty name without control characters, quotes, '<', '>' or '&'"
                )));
            }
            if let Some(first) = names.insert(name, kind) {
                return Err(error(format!(
                    "[[export.{kind}]] name '{name}' is used twice (also an exported {first})"
                )));
            }
            if kind != "output" {
                if let Some(first) = targets.insert(target, name) {
                    return Err(error(format!(
                        "[[export.{kind}]] '{name}' sets '{target}', which '{first}' already sets"
                    )));
                }
            }
        }
        Ok(())
    }
}
