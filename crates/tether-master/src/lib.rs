//! # tether-master
//!
//! The constraint-coupling co-simulation master of Tether: the semi-implicit
//! predictor/corrector methods of Schweizer & Lu (ZAMM 2015) — Method 1
//! (Baumgarte stabilisation) and Method 2 (weighted multipliers) on index 1, 2
//! or 3 level — plus an explicit baseline, coupling FMI 2.0 co-simulation FMUs
//! through algebraic constraints between their outputs.
//!
//! ```no_run
//! use tether_master::{MemoryRecorder, Simulation, SystemSpec};
//! # fn main() -> Result<(), tether_master::MasterError> {
//! let spec = SystemSpec::from_file("examples/oscillator.toml".as_ref())?;
//! let mut sim = Simulation::new(&spec)?;
//! let mut results = MemoryRecorder::default();
//! let stats = sim.run(&mut [&mut results], &mut |_, _| {})?;
//! println!("{stats}");
//! # Ok(()) }
//! ```
//!
//! The algorithm as implemented is described in `docs/algorithm.md`.

mod arrays;
mod coupling;
mod culprit;
mod error;
mod error_estimate;
mod explicit;
pub mod expr;
mod feedthrough;
mod jacobian_reuse;
mod joints;
mod method;
mod names;
mod observer;
mod overrides;
pub mod polynomial;
mod predictor_corrector;
mod resolve;
mod rows;
mod runs;
mod signals;
mod simulation;
mod slave;
mod solve;
mod sparse_lu;
pub mod spec;
mod start;
mod stats;
mod step_control;
mod system;
mod threads;
mod touched;

pub use error::MasterError;
pub use method::Method;
pub use observer::{CsvRecorder, Emergency, MemoryRecorder, Observer, Sample, FLUSH_INTERVAL};
pub use overrides::{MethodChange, MethodKind, OverrideError, Overrides};
pub use simulation::{MasterState, Simulation, SystemState};
pub use spec::{
    CheckRollback, ConnectionSpec, ConstraintSpec, CouplingSettings, CouplingVariableSpec,
    Experiment, InitialMultiplier, InstanceSpec, JacobianMode, JointInitial, JointSpec, OutputSpec,
    SignalScheme, SignalSettings, StartValue, SystemSpec,
};
pub use start::apply_start_value;
pub use stats::{
    AdaptiveStats, InstanceCounters, PhaseTimes, RunStats, Termination, SUMMARY_SCHEMA,
};
pub use step_control::StepControl;
pub use threads::{Parallel, ParallelInfo};

/// Timings for the benchmarks (not a stable interface).
#[doc(hidden)]
pub mod bench_hooks {
    pub use crate::solve::solve_times;
}
