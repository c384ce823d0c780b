//! The study error type: one line naming the culprit.

use std::path::PathBuf;

use tether_master::{MasterError, OverrideError};

/// Everything that keeps a study from running or from writing its results.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The study file cannot be read or has the wrong shape.
    #[error("study file {}: {reason}", path.display())]
    StudyFile {
        /// The file.
        path: PathBuf,
        /// What is wrong, on one line.
        reason: String,
    },
    /// A study setting is out of range or inconsistent.
    #[error("invalid study: {0}")]
    Invalid(String),
    /// A setting (`[set]`, a variant, an axis target) does not fit the system.
    #[error(transparent)]
    Override(#[from] OverrideError),
    /// A column asked for is not among the results.
    #[error("no column '{column}' in {source_name}; columns are: {available}")]
    UnknownColumn {
        /// The name asked for.
        column: String,
        /// Where it was looked up (a file, a run).
        source_name: String,
        /// The columns that exist, comma separated.
        available: String,
    },
    /// A results or reference CSV cannot be read.
    #[error("{}: {reason}", path.display())]
    Csv {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The base system of a study cannot be set up (before any grid point runs).
    #[error(transparent)]
    Master(#[from] MasterError),
    /// Drawing a plot failed.
    #[error("plot {}: {reason}", path.display())]
    Plot {
        /// The output file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The study was stopped before all its runs finished (Ctrl-C).
    #[error("study interrupted after {done} of {total} runs")]
    Interrupted {
        /// Runs finished.
        done: usize,
        /// Runs of the study.
        total: usize,
    },
    /// Writing results failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl StudyError {
    pub(crate) fn unknown_column(column: &str, source_name: &str, available: &[String]) -> Self {
        StudyError::UnknownColumn {
            column: column.to_string(),
            source_name: source_name.to_string(),
            available: available.join(", "),
        }
    }
}
