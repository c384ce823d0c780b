//! How the perturbed runs of a macro step are executed (Step 3 of
//! docs/algorithm.md): one strategy behind [`PerturbedRuns`], chosen at setup
//! from `[coupling] parallel` — all on the calling thread ([`Sequential`]), or
//! shared with worker threads ([`crate::algorithm::threads::Threads`]).

use crate::polynomial::Taylor;
use crate::slave::Slave;
use crate::stats::RunStats;
use crate::MasterError;

/// The perturbed runs of one macro step. For each group `g` of unknowns,
/// every instance of `group_slaves[g]` restarts from its saved state at T_N
/// with the inputs `polys[g]`, steps to T_{N+1}, and its coupled outputs go
/// to `outputs[g][s]`. Every strategy computes the same values bit for bit.
pub(crate) trait PerturbedRuns: Send {
    fn run(
        &mut self,
        slaves: &mut [Slave],
        t: f64,
        h: f64,
        polys: &[Vec<Taylor>],
        outputs: &mut [Vec<Vec<f64>>],
    ) -> Result<(), MasterError>;

    /// Add the strategy's FMI calls made outside `slaves` and its decisions
    /// to `stats`.
    fn report(&self, _stats: &mut RunStats) {}

    /// `fmi2Terminate` the instances the strategy made itself (the copies on
    /// worker threads), at a normal end of the run.
    fn terminate(&mut self) -> Result<(), MasterError> {
        Ok(())
    }
}

/// Every run on the calling thread, group after group.
pub(crate) struct Sequential {
    /// Per group, the instances its run steps.
    pub group_slaves: Vec<Vec<usize>>,
}

impl PerturbedRuns for Sequential {
    fn run(
        &mut self,
        slaves: &mut [Slave],
        t: f64,
        h: f64,
        polys: &[Vec<Taylor>],
        outputs: &mut [Vec<Vec<f64>>],
    ) -> Result<(), MasterError> {
        for (g, members) in self.group_slaves.iter().enumerate() {
            for &s in members {
                slaves[s].rerun(&polys[g], t, h, Some(&mut outputs[g][s]))?;
            }
        }
        Ok(())
    }
}
