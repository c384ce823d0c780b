//! SSP 1.0 (System Structure and Parameterization, Modelica Association) for
//! Tether: [`read`] turns an `.ssp` archive, an unpacked SSP folder or a
//! `SystemStructure.ssd` into a [`SystemSpec`]; [`write`] packs a system as an
//! `.ssp`. docs/ssp.md describes the mapping both ways. [`load`] reads a
//! system given by path, a system file or SSP alike.
//!
//! Components become instances, connections become signal connections
//! (`[[connection]]`), parameter bindings (inline and `.ssv`) become start
//! values, nested systems are flattened. What SSP cannot say — constraints,
//! joints, coupling variables, the method and the macro step — travels in an
//! annotation of type [`ANNOTATION_TYPE`] that other tools skip.

mod load;
mod read;
mod write;

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tether_master::{
    ConstraintSpec, CouplingSettings, CouplingVariableSpec, JointSpec, MasterError, Method,
    SignalSettings, StepControl,
};

pub use load::{is_ssp, load, ssd_name};
pub use read::{read, Loaded};
pub use write::{write, write_toml};

/// The SSP 1.0 namespaces and the prefixes the standard's examples use: the reader
/// names elements `ssd:…`, `ssc:…` and so on whatever prefix a file uses.
pub(crate) const NAMESPACES: [(&str, &str); 5] = [
    (
        "ssd",
        "http://ssp-standard.org/SSP1/SystemStructureDescription",
    ),
    ("ssc", "http://ssp-standard.org/SSP1/SystemStructureCommon"),
    (
        "ssv",
        "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    ),
    (
        "ssm",
        "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    ),
    (
        "ssb",
        "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    ),
];

/// The `type` of Tether's `ssc:Annotation` on the root `ssd:System`.
pub const ANNOTATION_TYPE: &str = "org.tether.system";
/// The namespace of the element inside it, which holds TOML text.
pub const ANNOTATION_NAMESPACE: &str = "urn:tether:ssp:1";

/// What Tether's annotation carries: the system file's sections that SSP has
/// no element for, in the system file's own TOML syntax.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Annotation {
    /// Macro-step size H (SSP's DefaultExperiment has none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<f64>,
    /// Tolerance for every FMU's fmi2SetupExperiment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method: Option<Method>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coupling: Option<CouplingSettings>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub signals: Option<SignalSettings>,
    /// Adaptive macro steps (`[step_control]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_control: Option<StepControl>,
    #[serde(rename = "constraint", default, skip_serializing_if = "Vec::is_empty")]
    pub constraints: Vec<ConstraintSpec>,
    #[serde(rename = "joint", default, skip_serializing_if = "Vec::is_empty")]
    pub joints: Vec<JointSpec>,
    #[serde(
        rename = "coupling_variable",
        default,
        skip_serializing_if = "Vec::is_empty"
    )]
    pub coupling_variables: Vec<CouplingVariableSpec>,
}

/// Everything that can go wrong reading or writing SSP: one line each.
#[derive(Debug, thiserror::Error)]
pub enum SspError {
    /// Something at a line of an SSD or SSV file.
    #[error("{file}:{line}: {message}")]
    At {
        /// The file, as named inside the SSP.
        file: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// An SSD or SSV file that is not well-formed XML or is over a limit of the XML
    /// reader (size, nesting depth: [`tether_fmi::xml`]).
    #[error(transparent)]
    Xml(#[from] tether_fmi::xml::XmlError),
    /// An `.ssp` archive that cannot be extracted (every error names the entry).
    #[error(transparent)]
    Archive(#[from] tether_fmi::Error),
    /// A file cannot be read or written.
    #[error("{}: {reason}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// The I/O or archive error.
        reason: String,
    },
    /// Anything else, on one line.
    #[error("{0}")]
    Other(String),
    /// The system itself.
    #[error(transparent)]
    Master(#[from] MasterError),
}

impl SspError {
    pub(crate) fn xml(file: &str, line: usize, message: impl Into<String>) -> SspError {
        SspError::At {
            file: file.to_string(),
            line,
            message: message.into().replace('\n', " "),
        }
    }

    pub(crate) fn file(path: &std::path::Path, reason: impl ToString) -> SspError {
        SspError::File {
            path: path.to_path_buf(),
            reason: reason.to_string().replace('\n', " "),
        }
    }
}
