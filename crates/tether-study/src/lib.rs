//! # tether-study
//!
//! Studies of coupled runs, the way Schweizer & Lu (ZAMM 2015) present their
//! results, for any system file:
//!
//! * [`convergence`]: the global error of chosen columns over the macro-step
//!   size H, against a closed form, a reference CSV or the finest run, with
//!   the fitted order;
//! * [`stability`]: a grid over two quantities (FMU parameters, or H), each
//!   cell run and classified stable / unstable / failed;
//! * [`series`]: time series of several variants side by side;
//! * [`plot`]: SVG and PNG plots of all three, and of any results CSV.
//!
//! Runs are independent and go in parallel over the cores (rayon). A
//! [`Study`] bundles a system file, variants of it and one study; it is read
//! from a TOML study file (`docs/studies.md`) or built in code.
//!
//! ```no_run
//! use tether_study::Study;
//! # fn main() -> Result<(), tether_study::StudyError> {
//! let study = Study::from_file("docs/figures/studies/fig06c.toml".as_ref())?;
//! let report = study.run("target/figures".as_ref(), &|| {})?;
//! println!("{}", report.summary);
//! # Ok(()) }
//! ```

pub mod axis;
pub mod convergence;
mod error;
pub mod output;
pub mod plan;
pub mod plot;
pub mod reference;
pub mod runner;
pub mod series;
pub mod stability;
mod study;
mod table;

pub use axis::{Axis, Scale};
pub use convergence::{convergence, Convergence, ConvergenceCurve, ConvergencePoint};
pub use error::StudyError;
pub use plan::{JobResult, Plan};
pub use reference::{Reference, ReferenceSpec, TwoMassOscillator};
pub use runner::{Outcome, RunResult};
pub use series::{series, Series};
pub use stability::{stability, Cell, Class, Stability, StabilityMap};
pub use study::{Kind, Study, StudyReport, StudyResults, Variant, VariantSpec};
pub use table::Table;
/// The settings a study changes: `[set]` and each `[[variant]]`.
pub use tether_master::Overrides;
