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

    /// The predictor runs of every instance with the unknowns' polynomials
    /// `polys` (Step 2), their outputs to `predicted[s]`, and with
    /// `perturbed` also the perturbed runs as [`run`](Self::run) makes them.
    /// Unless a strategy hands them over together: the perturbed runs after
    /// the predictor runs.
    fn predict(
        &mut self,
        slaves: &mut [Slave],
        (t, h): (f64, f64),
        polys: &[Taylor],
        predicted: &mut [Vec<f64>],
        perturbed: Option<Perturbed<'_>>,
    ) -> Result<(), MasterError> {
        predictor_runs(slaves, (t, h), polys, predicted)?;
        match perturbed {
            Some((polys, outputs)) => self.run(slaves, t, h, polys, outputs),
            None => Ok(()),
        }
    }

    /// Add the strategy's FMI calls made outside `slaves` and its decisions
    /// to `stats`.
    fn report(&self, _stats: &mut RunStats) {}

    /// `fmi2Terminate` the instances the strategy made itself (the copies on
    /// worker threads), at a normal end of the run.
    fn terminate(&mut self) -> Result<(), MasterError> {
        Ok(())
    }
}

/// The predictor run of every instance, alone.
pub(crate) fn predictor_runs(
    slaves: &mut [Slave],
    (t, h): (f64, f64),
    polys: &[Taylor],
    predicted: &mut [Vec<f64>],
) -> Result<(), MasterError> {
    for (slave, out) in slaves.iter_mut().zip(predicted) {
        slave.predict_and_perturb(polys, (t, h), out, std::iter::empty())?;
    }
    Ok(())
}

/// The perturbed runs' polynomials and outputs, per group (as
/// [`PerturbedRuns::run`] takes them).
pub(crate) type Perturbed<'a> = (&'a [Vec<Taylor>], &'a mut [Vec<Vec<f64>>]);

/// Every run on the calling thread: each instance's perturbed runs handed to
/// it with its predictor run, or group after group.
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

    fn predict(
        &mut self,
        slaves: &mut [Slave],
        (t, h): (f64, f64),
        polys: &[Taylor],
        predicted: &mut [Vec<f64>],
        perturbed: Option<Perturbed<'_>>,
    ) -> Result<(), MasterError> {
        let (perturbed, outputs) = perturbed.unwrap_or((&[], &mut []));
        for (s, (slave, out)) in slaves.iter_mut().zip(predicted).enumerate() {
            // The instance's perturbed runs, in the order of the groups.
            let runs = self
                .group_slaves
                .iter()
                .zip(perturbed)
                .zip(outputs.iter_mut())
                .filter(|((members, _), _)| members.contains(&s))
                .map(|((_, polys), outputs)| (&polys[..], &mut outputs[s][..]));
            slave.predict_and_perturb(polys, (t, h), out, runs)?;
        }
        Ok(())
    }
}
