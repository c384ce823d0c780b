//! Saved states of an instance: the state saved at the start of each macro
//! step (and restored for each repeated run) and the whole system's saved
//! state.

use super::{Run, Slave, SAVED, SNAPSHOT};
use crate::MasterError;

impl Slave {
    /// Save the current state (`fmi2GetFMUstate`, reusing the previous handle).
    pub(crate) fn save_state(&mut self) -> Result<(), MasterError> {
        self.backend.save(SAVED)?;
        self.saved = true;
        self.counters.state_gets += 1;
        if self.check.verify_restore {
            let mut at_save = std::mem::take(&mut self.check.at_save);
            let read = self.read_coupled(&mut at_save, Run::Rollback);
            self.check.at_save = at_save;
            read?;
        }
        Ok(())
    }

    /// Roll back to the saved state (`fmi2SetFMUstate`); with
    /// `verify_restore`, read the coupled outputs back and require those of
    /// the save.
    pub(crate) fn restore_state(&mut self) -> Result<(), MasterError> {
        assert!(self.saved, "restore_state is only called after save_state");
        self.backend.restore(SAVED)?;
        self.counters.state_sets += 1;
        if self.check.verify_restore {
            let mut readback = std::mem::take(&mut self.check.readback);
            let at_save = std::mem::take(&mut self.check.at_save);
            let read = self.read_coupled(&mut readback, Run::Rollback);
            let compared = read.and_then(|()| {
                let time = self.backend.time();
                self.compare_restored(&at_save, &readback, time)
            });
            self.check.readback = readback;
            self.check.at_save = at_save;
            compared?;
        }
        Ok(())
    }

    /// Save the current state as bytes into `out`, for the whole system's
    /// saved state (needs `canGetAndSetFMUstate` and `canSerializeFMUstate`).
    pub(crate) fn snapshot(&mut self, out: &mut Vec<u8>) -> Result<(), MasterError> {
        let lacking = if !self.caps.rollback {
            Some("canGetAndSetFMUstate")
        } else if !self.caps.serialization {
            Some("canSerializeFMUstate")
        } else {
            None
        };
        if let Some(capability) = lacking {
            return Err(MasterError::MissingCapability {
                instance: self.name.clone(),
                model: self.model_name.clone(),
                capability,
                needed_by: "the system's saved state".into(),
            });
        }
        self.backend.save(SNAPSHOT)?;
        self.backend.serialize(SNAPSHOT, out)?;
        self.backend.free(SNAPSHOT)?;
        Ok(())
    }

    /// Back to a state of [`snapshot`](Self::snapshot), with the recorded
    /// outputs read then.
    pub(crate) fn load_snapshot(
        &mut self,
        bytes: &[u8],
        recorded: &[f64],
    ) -> Result<(), MasterError> {
        self.backend.deserialize(SNAPSHOT, bytes)?;
        self.backend.restore(SNAPSHOT)?;
        self.backend.free(SNAPSHOT)?;
        self.recorded.values.copy_from_slice(recorded);
        self.recorded.exact.clear();
        Ok(())
    }
}
