//! The right culprit for a failed step. A coupled output that is finite but
//! far beyond its size at the start (the `quirks` FMU's `huge_after`: 1e300)
//! passes the finiteness check where it is read, reaches the other instances
//! as an input through the multipliers, and the step may then fail there (an
//! instance's solver gives up, a Jacobian turns singular) before the accepted
//! point's divergence check sees the value. So every coupled value is also
//! compared, where it is read, with the divergence limit of its instance's
//! output (`divergence_factor`·max(|initial value|, 1), as the recorded
//! columns are); the first one beyond it is noted on its instance
//! ([`Beyond`]). Noting changes nothing in the run (a value beyond the
//! limit in a perturbed run of a step that then succeeds is harmless); if the
//! step fails, the error names the instance whose output diverged first, and
//! then the failure it led to ([`MasterError::DivergedOutput`]).

use std::sync::atomic::{AtomicU64, Ordering};

use crate::MasterError;

/// Orders the notes of all instances: the earliest read is the culprit.
static SEQUENCE: AtomicU64 = AtomicU64::new(0);

/// A coupled output read beyond its divergence limit.
#[derive(Debug, Clone)]
pub(crate) struct Beyond {
    sequence: u64,
    variable: String,
    value: f64,
    limit: f64,
    call: &'static str,
    /// The instance's time after the call.
    pub(crate) time: f64,
}

impl Beyond {
    pub(crate) fn new(
        variable: String,
        value: f64,
        limit: f64,
        call: &'static str,
        time: f64,
    ) -> Beyond {
        Beyond {
            sequence: SEQUENCE.fetch_add(1, Ordering::Relaxed),
            variable,
            value,
            limit,
            call,
            time,
        }
    }
}

/// Whether `error` may have been caused by a value another instance gave:
/// a failed FMI call, a non-finite output, a singular Jacobian, a step the
/// error control cannot make small enough. (A divergence of the accepted
/// point already names the column, an interruption or a recording error
/// has nothing to do with the values.)
fn may_follow_a_divergence(error: &MasterError) -> bool {
    matches!(
        error,
        MasterError::Fmi(_)
            | MasterError::NonFiniteOutput { .. }
            | MasterError::SingularJacobian { .. }
            | MasterError::StepSizeTooSmall { .. }
    )
}

/// `error`, which stopped the step after the accepted point at `last`, with
/// the instance named whose coupled output went beyond its limit first in
/// that step, if any (`noted`: each instance's name and what was noted).
pub(crate) fn blame<'a>(
    error: MasterError,
    noted: impl Iterator<Item = (&'a str, &'a Beyond)>,
    last: f64,
) -> MasterError {
    if !may_follow_a_divergence(&error) {
        return error;
    }
    let first = noted
        .filter(|(_, b)| b.time > last)
        .min_by_key(|(_, b)| b.sequence);
    let Some((name, beyond)) = first else {
        return error;
    };
    if let MasterError::NonFiniteOutput {
        instance, variable, ..
    } = &error
    {
        if instance == name && *variable == beyond.variable {
            return error;
        }
    }
    MasterError::DivergedOutput {
        instance: name.to_string(),
        variable: beyond.variable.clone(),
        value: beyond.value,
        limit: beyond.limit,
        call: beyond.call,
        time: beyond.time,
        then: error.to_string(),
    }
}
