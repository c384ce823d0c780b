//! The rollback self-check (`[coupling] check_rollback`, docs/reliability.md):
//! an instance saved, stepped, restored and stepped again must give the same
//! outputs, bit for bit.

use super::{Run, Slave, CHECK};
use crate::polynomial::Taylor;
use crate::stats::InstanceCounters;
use crate::{MasterError, Time};

/// The check's settings and buffers.
#[derive(Debug, Default)]
pub(crate) struct RollbackCheck {
    /// `check_rollback = "every_step"`: read the coupled outputs back after
    /// each restore and compare them with those at the save.
    pub verify_restore: bool,
    /// The check's four readings of the coupled outputs.
    pub buf: Vec<f64>,
    /// Coupled outputs at the last save (with `verify_restore`).
    pub at_save: Vec<f64>,
    /// Coupled outputs read back after a restore (with `verify_restore`).
    pub readback: Vec<f64>,
    /// Requests to an isolated instance's host made by the checks, which the
    /// counts leave out as they leave out the checks' calls.
    pub trips: u64,
}

impl Slave {
    /// The rollback self-check (`check_rollback`, docs/reliability.md): save,
    /// step over [t, t + h] with `polys`, read the coupled outputs, restore and
    /// require the outputs of the save, repeat the step and require
    /// bit-identical outputs, restore again. The instance is left as it was
    /// (the state is the saved one); the calls are not counted.
    pub(crate) fn check_rollback(
        &mut self,
        polys: &[Taylor],
        t: f64,
        h: f64,
    ) -> Result<(), MasterError> {
        // The counts as they were (the names are not copied: the periodic
        // check allocates nothing after the first).
        let mut counters = InstanceCounters {
            name: String::new(),
            model: String::new(),
            ..self.counters
        };
        let trips = self.backend.round_trips();
        let n = self.coupled_len();
        let mut buf = std::mem::take(&mut self.check.buf);
        buf.resize(4 * n, 0.0);
        let (at_save, rest) = buf.split_at_mut(n);
        let (first, rest) = rest.split_at_mut(n);
        let (back, second) = rest.split_at_mut(n);
        self.backend.save(CHECK)?;
        self.read_coupled(at_save, Run::Rollback)?;
        self.apply_inputs(polys)?;
        self.do_step(t, h)?;
        self.read_coupled(first, Run::Rollback)?;
        self.backend.restore(CHECK)?;
        self.read_coupled(back, Run::Rollback)?;
        self.compare_restored(at_save, back, t)?;
        self.apply_inputs(polys)?;
        self.do_step(t, h)?;
        self.read_coupled(second, Run::Rollback)?;
        if let Some(i) = first_difference(first, second) {
            let variable = self.coupled_name(i);
            return Err(MasterError::RollbackCheck {
                instance: self.name.clone(),
                reason: format!(
                    "the step from t = {} to {} repeated after fmi2SetFMUstate with the same \
                     inputs gives output '{variable}' = {}, not {} as the first time (not \
                     bit-identical)",
                    Time(t),
                    Time(t + h),
                    second[i],
                    first[i]
                ),
                variable,
                unverified_after: None,
            });
        }
        self.check.buf = buf;
        self.backend.restore(CHECK)?;
        self.backend.free(CHECK)?;
        counters.name = std::mem::take(&mut self.counters.name);
        counters.model = std::mem::take(&mut self.counters.model);
        self.counters = counters;
        self.check.trips += self.backend.round_trips() - trips;
        Ok(())
    }

    /// An error naming the first coupled output whose value read back after a
    /// restore (`back`) differs from the one at the save (`saved`). Before it
    /// blames the restore, the outputs are read once more: an output that
    /// changes between two reads with no step between them is named as such.
    pub(super) fn compare_restored(
        &mut self,
        saved: &[f64],
        back: &[f64],
        time: f64,
    ) -> Result<(), MasterError> {
        let Some(i) = first_difference(saved, back) else {
            return Ok(());
        };
        let mut again = vec![0.0; back.len()];
        self.read_coupled(&mut again, Run::Rollback)?;
        let fail = |variable: String, reason: String| MasterError::RollbackCheck {
            instance: self.name.clone(),
            variable,
            reason,
            unverified_after: None,
        };
        if let Some(j) = first_difference(back, &again) {
            let variable = self.coupled_name(j);
            return Err(fail(
                variable.clone(),
                format!(
                    "output '{variable}' changes without a step: read twice at t = {} with no \
                     fmi2DoStep between, it gives {}, then {} (an output must depend only on \
                     the state and the inputs, or no restore can be checked)",
                    Time(time),
                    back[j],
                    again[j]
                ),
            ));
        }
        let variable = self.coupled_name(i);
        Err(fail(
            variable.clone(),
            format!(
                "after fmi2SetFMUstate back to t = {}, output '{variable}' reads {}, \
                 not {} as at fmi2GetFMUstate (the state was not restored)",
                Time(time),
                back[i],
                saved[i]
            ),
        ))
    }
}

/// The first index where `a` and `b` differ bit for bit.
pub(super) fn first_difference(a: &[f64], b: &[f64]) -> Option<usize> {
    a.iter()
        .zip(b)
        .position(|(x, y)| x.to_bits() != y.to_bits())
}

#[cfg(test)]
mod tests {
    use super::first_difference;

    #[test]
    fn differences_are_bit_for_bit() {
        assert_eq!(first_difference(&[1.0, 2.0], &[1.0, 2.0]), None);
        assert_eq!(first_difference(&[1.0, 2.0], &[1.0, 2.0 + 1e-15]), Some(1));
        // -0 and 0 compare equal as numbers, not as bits; NaN equals itself.
        assert_eq!(first_difference(&[0.0], &[-0.0]), Some(0));
        assert_eq!(first_difference(&[f64::NAN], &[f64::NAN]), None);
    }
}
