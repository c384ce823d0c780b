//! `modelDescription.xml`: a cheap version peek, the full co-simulation parse with the
//! FMI 2.0 defaults applied, and variable look-up by name.

mod attrs;
mod lookup;
mod parse;
mod type_attrs;
mod types;
mod variables;

use std::path::Path;

pub use types::*;

use crate::error::{Error, Result};
use crate::xml;

impl ModelDescription {
    /// Reads and parses a `modelDescription.xml` file (at most [`xml::MAX_BYTES`] bytes).
    pub fn from_file(path: &Path) -> Result<ModelDescription> {
        let bytes = xml::read(path).map_err(|source| Error::Io {
            path: path.to_owned(),
            source,
        })?;
        let origin = path.parent().unwrap_or(path);
        parse_bytes(&bytes, path, origin)
    }

    /// Parses modelDescription.xml text; errors name the file `modelDescription.xml`.
    pub fn from_xml(text: &str) -> Result<ModelDescription> {
        let file = Path::new("modelDescription.xml");
        parse_bytes(text.as_bytes(), file, file)
    }

    /// Parses modelDescription.xml bytes (any encoding the importer accepts); errors
    /// name the file `modelDescription.xml`.
    pub fn from_bytes(bytes: &[u8]) -> Result<ModelDescription> {
        let file = Path::new("modelDescription.xml");
        parse_bytes(bytes, file, file)
    }

    /// The variable called `name`, or [`Error::UnknownVariable`] with close matches.
    pub fn variable(&self, name: &str) -> Result<&ScalarVariable> {
        match self.by_name.get(name) {
            Some(&i) => Ok(&self.model_variables[i]),
            None => Err(Error::UnknownVariable {
                model: self.model_name.clone(),
                name: name.to_owned(),
                suggestions: lookup::suggestions(
                    name,
                    self.model_variables.iter().map(|v| v.name.as_str()),
                ),
            }),
        }
    }

    /// The value reference of the variable called `name`.
    pub fn value_reference(&self, name: &str) -> Result<ValueReference> {
        self.variable(name).map(|v| v.value_reference)
    }

    /// The variable with FMI's 1-based `index` (as used in `ModelStructure`).
    pub fn variable_by_index(&self, index: usize) -> Option<&ScalarVariable> {
        index
            .checked_sub(1)
            .and_then(|i| self.model_variables.get(i))
    }

    /// Variables with the given causality, in file order.
    pub fn variables_with_causality(
        &self,
        causality: Causality,
    ) -> impl Iterator<Item = &ScalarVariable> {
        self.model_variables
            .iter()
            .filter(move |v| v.causality == causality)
    }
}

/// Reads only the root start tag and returns its `fmiVersion` attribute.
pub fn peek_fmi_version(text: &str, file: &Path) -> Result<Option<String>> {
    let root = xml::parse_root(text, file)?;
    Ok(root.attr("fmiVersion").map(str::to_owned))
}

/// Parses modelDescription.xml bytes. `file` names the XML in line-level errors,
/// `origin` names the FMU in FMU-level errors (version, kind).
pub(crate) fn parse_bytes(bytes: &[u8], file: &Path, origin: &Path) -> Result<ModelDescription> {
    let text = xml::decode(bytes, file)?;
    // Cheap peek first: an FMI 1.0 or 3.0 file is refused before its (different) schema
    // can produce confusing errors.
    let version = peek_fmi_version(text, file)?;
    match version.as_deref() {
        Some(v) if v.trim().starts_with("2.") || v.trim() == "2" => {}
        Some(v) => {
            return Err(Error::UnsupportedFmiVersion {
                path: origin.to_owned(),
                version: v.trim().to_owned(),
            })
        }
        None => {
            return Err(Error::UnsupportedFmiVersion {
                path: origin.to_owned(),
                version: "(unknown: no fmiVersion attribute)".into(),
            })
        }
    }
    let root = xml::parse(text, file, xml::Names::AsWritten)?;
    if root.child("CoSimulation").is_none() && root.child("ModelExchange").is_some() {
        return Err(Error::NotCoSimulation {
            path: origin.to_owned(),
            model: root.attr("modelName").unwrap_or("?").to_owned(),
        });
    }
    parse::model_description(attrs::Attrs { file }, &root)
}

#[cfg(test)]
mod tests;
