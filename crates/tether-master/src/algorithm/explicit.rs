//! The explicit baseline method (docs/algorithm.md, "The explicit baseline";
//! our reconstruction of the paper's ref. \[16\]): the multipliers are held
//! constant over each macro step, then u_{N+1} is chosen from the states at
//! T_{N+1} so that μ² g̈ + 2μ ġ + g = 0 there. No step is repeated.

use crate::algorithm::step::{MacroStep, StepAt};
use crate::coupling::rows::RowLevel;
use crate::runs::{Outputs, Phase};
use crate::slave::{Run, Slave};
use crate::stats::{Lap, RunStats};
use crate::system::feedthrough::Feedthrough;
use crate::system::System;
use crate::MasterError;

pub(crate) struct Explicit {
    /// Stabilisation time constant μ.
    mu: f64,
    feedthrough: Feedthrough,
}

impl Explicit {
    pub fn new(system: &System, mu: f64) -> Explicit {
        Explicit {
            mu,
            feedthrough: Feedthrough::new(system),
        }
    }
}

impl MacroStep for Explicit {
    fn step(
        &mut self,
        system: &mut System,
        at: StepAt,
        stats: &mut RunStats,
        lap: &mut Lap,
    ) -> Result<Option<f64>, MasterError> {
        // Every instance steps with u_N held as its inputs.
        let phase = Phase::step(at.t, at.h);
        let stepped = |_, s: &Slave| !s.stepped_ahead;
        system
            .runs
            .phase(&mut system.slaves, phase, Outputs::none(), stepped)?;
        lap.split_into(&mut stats.times.predictor);
        for hist in &mut system.history {
            *hist = [hist[0], hist[0], hist[1]];
        }
        let level = RowLevel::Stabilised(self.mu);
        self.feedthrough
            .update_all(system, level, at.t_next, stats)?;
        system.read_accepted(Run::Explicit)?;
        lap.split_into(&mut stats.times.solve);
        Ok(None)
    }
}
