//! `modelDescription.xml`: a cheap version peek, the full parse (FMI 2.0 or FMI 3.0,
//! co-simulation and model exchange) with the standard's defaults applied, and
//! variable look-up by name.

mod attrs;
mod common;
mod fmi2;
mod fmi3;
mod lookup;
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

    /// The `CoSimulation` flags; all false (and no model identifier) for an
    /// FMU without co-simulation, which the co-simulation paths refuse when
    /// they instantiate it ([`Error::NotCoSimulation`]).
    pub fn cs(&self) -> &CoSimulation {
        self.co_simulation
            .as_ref()
            .unwrap_or(&types::NO_CO_SIMULATION)
    }

    /// The model identifier of the co-simulation interface, else of model
    /// exchange (a model description has one or both).
    pub fn model_identifier(&self) -> &str {
        match (&self.co_simulation, &self.model_exchange) {
            (Some(cs), _) => &cs.model_identifier,
            (None, Some(me)) => &me.model_identifier,
            (None, None) => "",
        }
    }

    /// The value references of the continuous states, in the order of
    /// `ModelStructure`'s derivatives (the order of the FMI state vector),
    /// and of their derivatives.
    pub fn continuous_states(&self) -> Vec<(ValueReference, ValueReference)> {
        self.model_structure
            .derivatives
            .iter()
            .filter_map(|d| {
                let der = self.variable_by_index(d.index)?;
                let state = self.variable_by_index(der.real()?.derivative?)?;
                Some((state.value_reference, der.value_reference))
            })
            .collect()
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

    /// The first variable with value reference `vr` (FMI 3.0 aliases share one).
    pub fn variable_by_vr(&self, vr: ValueReference) -> Option<&ScalarVariable> {
        self.model_variables
            .iter()
            .find(|v| v.value_reference == vr)
    }

    /// The sizes of `v`'s dimensions (empty for a scalar), structural parameters
    /// taken at their start values.
    pub fn array_sizes(&self, v: &ScalarVariable) -> Result<Vec<u64>> {
        self.array_sizes_with(v, &|_| None)
    }

    /// The sizes of `v`'s dimensions, structural parameters taken from `value` where
    /// it knows them and at their start values otherwise.
    pub fn array_sizes_with(
        &self,
        v: &ScalarVariable,
        value: &dyn Fn(ValueReference) -> Option<u64>,
    ) -> Result<Vec<u64>> {
        v.dimensions
            .iter()
            .map(|d| match *d {
                Dimension::Fixed(n) => Ok(n),
                Dimension::Parameter(vr) => value(vr)
                    .or_else(|| {
                        let p = self.variable_by_vr(vr)?;
                        match p.start_values.as_ref()? {
                            Values::UInt(s) => s.first().copied(),
                            Values::Int(s) => s.first().and_then(|&x| u64::try_from(x).ok()),
                            _ => None,
                        }
                    })
                    .ok_or_else(|| Error::InvalidArgument {
                        function: "array dimensions",
                        instance: self.model_name.clone(),
                        message: format!(
                            "the size of array '{}' is the structural parameter with value reference {vr}, which has no start value",
                            v.name
                        ),
                    }),
            })
            .collect()
    }

    /// The number of values of `v` (1 for a scalar), structural parameters at their
    /// start values.
    pub fn element_count(&self, v: &ScalarVariable) -> Result<usize> {
        Ok(self.array_sizes(v)?.iter().product::<u64>() as usize)
    }

    /// The names of `v`'s elements in row-major order: `y[1]`, `A[2,3]` (1-based),
    /// or just the name for a scalar.
    pub fn element_names(&self, v: &ScalarVariable) -> Result<Vec<String>> {
        Ok(element_names(&v.name, &self.array_sizes(v)?))
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

/// The names of the elements of an array called `name` with the given sizes, in
/// row-major order, 1-based: `y[1]`, `A[2,3]`; just `name` for a scalar (no sizes).
pub fn element_names(name: &str, sizes: &[u64]) -> Vec<String> {
    if sizes.is_empty() {
        return vec![name.to_owned()];
    }
    let total: u64 = sizes.iter().product();
    let mut names = Vec::with_capacity(total as usize);
    let mut index = vec![1u64; sizes.len()];
    for _ in 0..total {
        let subscript: Vec<String> = index.iter().map(u64::to_string).collect();
        names.push(format!("{name}[{}]", subscript.join(",")));
        for d in (0..sizes.len()).rev() {
            index[d] += 1;
            if index[d] <= sizes[d] {
                break;
            }
            index[d] = 1;
        }
    }
    names
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
    let standard = match version.as_deref() {
        Some(v) if v.trim().starts_with("2.") || v.trim() == "2" => FmiStandard::Fmi2,
        Some(v) if v.trim().starts_with("3.") || v.trim() == "3" => FmiStandard::Fmi3,
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
    };
    let root = xml::parse(text, file, xml::Names::AsWritten)?;
    if standard == FmiStandard::Fmi3
        && root.child("CoSimulation").is_none()
        && root.child("ModelExchange").is_none()
        && root.child("ScheduledExecution").is_some()
    {
        return Err(Error::NotCoSimulationFmi3 {
            path: origin.to_owned(),
            model: root.attr("modelName").unwrap_or("?").to_owned(),
            offers: "scheduled execution",
        });
    }
    let quirks = std::cell::RefCell::new(Vec::new());
    let at = attrs::Attrs {
        file,
        quirks: &quirks,
    };
    let mut md = match standard {
        FmiStandard::Fmi2 => fmi2::model_description(at, &root),
        FmiStandard::Fmi3 => fmi3::model_description(at, &root),
    }?;
    md.quirks = quirks.into_inner();
    Ok(md)
}

pub(crate) use fmi3::{hex_decode, hex_encode};

#[cfg(test)]
mod tests;
