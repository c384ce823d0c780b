//! # tether-master
//!
//! The constraint-coupling co-simulation master of Tether: the semi-implicit
//! predictor/corrector methods of Schweizer & Lu (ZAMM 2015) — Method 1
//! (Baumgarte stabilisation) and Method 2 (weighted multipliers) on index 1, 2
//! or 3 level — plus an explicit baseline, coupling FMI 2.0 and FMI 3.0
//! co-simulation FMUs through algebraic constraints between their outputs, and
//! through signal connections.
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

mod algorithm;
mod coupling;
mod culprit;
mod error;
pub mod expr;
mod linalg;
mod method;
mod observer;
pub mod polynomial;
pub mod polynomial_inputs;
mod runs;
mod signals;
mod simulation;
mod single;
mod slave;
pub mod spec;
mod start;
mod state_bytes;
mod stats;
mod step_control;
mod system;
pub mod units;

pub use error::{error_line, MasterError, UnknownName};
pub use method::{IndexConflict, IndexedKind, Method};
pub use observer::{
    CsvRecorder, Emergency, MemoryRecorder, Observer, Results, Sample, FLUSH_INTERVAL,
};
pub use simulation::{
    ExportKind, ExportVariable, MasterState, Simulation, SystemState, RECHECK_EVERY,
};
pub use single::{FmiType, SingleEnd, SingleExperiment, SingleFmu, SingleOutputs, SingleRun};
pub use spec::overrides::{MethodChange, MethodKind, OverrideError, Overrides};
pub use spec::Parallel;
pub use spec::{
    CheckRollback, ConnectionSpec, ConstraintSpec, CouplingSettings, CouplingVariableSpec,
    Experiment, ExportLink, ExportSource, ExportSpec, InitialMultiplier, InstanceSpec,
    IntegratorSpec, InterfaceChoice, JacobianMode, JointInitial, JointSpec, OutputSpec,
    ResidualLimit, SignalScheme, SignalSettings, SignalSolver, StartValue, SystemSpec,
};
pub use start::{apply_start_value, apply_start_values, Arrays};
pub use stats::{
    wrap, AdaptiveStats, CallNames, Failure, InstanceCounters, ParallelInfo, PhaseTimes, RunStats,
    SignalStats, Termination, SUMMARY_SCHEMA, SUMMARY_WIDTH,
};
pub use step_control::StepControl;
pub use tether_fmi::Time;

/// Timings for the benchmarks (not a stable interface).
#[doc(hidden)]
pub mod bench_hooks {
    pub use crate::linalg::solve::solve_times;
}
