//! FMI 2.0 and FMI 3.0 import, co-simulation and model exchange.
//!
//! FMI 3.0 FMUs are opened by the same [`Fmu::open`] (binaries under
//! `binaries/x86_64-linux/`), described by the same [`ModelDescription`] (see
//! [`model_description`] for how FMI 3.0 maps onto it) and instantiated with
//! [`instantiate`] as an [`Fmi3Instance`], an [`FmuInstance`] like the FMI 2.0 ones.
//! A model-exchange FMU of either standard runs as a [`MeInstance`], also an
//! [`FmuInstance`], which integrates it with its built-in [`Integrator`].
//!
//! # Layers
//!
//! - **Files** — [`archive`] unpacks a `.fmu` (or tether-ssp's `.ssp`) safely (no `..`,
//!   absolute paths, duplicates or symlinks; stored/deflate only; a size budget against
//!   decompression bombs) into a temporary directory that lives as long as anything
//!   made from it.
//! - **Description** — [`model_description`] peeks at `fmiVersion`, then parses
//!   `modelDescription.xml` completely for co-simulation, applying the FMI 2.0 defaults;
//!   errors name the file and line. [`xml`] is the XML reader under it (and under
//!   tether-ssp's SSD and SSV files), bounded in size and nesting depth.
//! - **Raw** — [`raw`] mirrors the C API one-to-one (types, `fmi2CallbackFunctions`,
//!   the function table [`raw::Fmi2Functions`]); a crate-private component wrapper calls
//!   the functions under their C names, each through one status check that logs the call
//!   at trace level and turns statuses into [`Error`]s. The variadic logger callback is a
//!   small C shim forwarding to the `log` facade (target `fmu::<instance>`).
//! - **Safe** — [`Fmu`] (open, describe, instantiate), [`Instance`] (the co-simulation
//!   calls, `Send`) and [`FmuState`] (owned states, freed on drop).
//!
//! # Lifetimes
//!
//! An [`Instance`] shares the unpacked directory and the loaded library with its
//! [`Fmu`] through `Arc`s, so dropping the `Fmu` is harmless. An [`FmuState`] may
//! outlive the `Instance` value: the instance owns its component (its calls take no
//! lock), a state dropped while it lives is freed before the instance's next call, and
//! `fmi2FreeInstance` runs when the instance and its last state are gone. After any call returns `fmi2Fatal`, every further
//! call on every instance of that FMU is refused and nothing is freed (the standard
//! forbids further calls).
//!
//! ```no_run
//! use tether_fmi::{Fmu, InstanceOptions};
//!
//! # fn main() -> Result<(), tether_fmi::Error> {
//! let fmu = Fmu::open("oscillator.fmu")?;
//! let md = fmu.model_description();
//! let x = md.value_reference("x")?;
//! let mut a = fmu.instantiate("a", InstanceOptions::default())?;
//! a.setup_experiment(None, 0.0, Some(1.0))?;
//! a.enter_initialization_mode()?;
//! a.exit_initialization_mode()?;
//! let saved = a.get_fmu_state()?;
//! a.do_step(0.0, 1e-3, false)?;
//! a.set_fmu_state(&saved)?;
//! let mut out = [0.0];
//! a.get_real(&[x], &mut out)?;
//! # Ok(())
//! # }
//! ```

pub mod archive;
mod component;
mod current;
mod error;
pub mod exit_hook;
mod fmu;
mod instance;
mod integrator;
mod interface;
mod library;
mod logger;
pub mod model_description;
pub mod paths;
mod placement;
pub mod raw;
pub mod remote;
mod shared;
mod time;
mod uri;
pub mod xml;

pub use archive::{remove_extractions_now, sweep_leftovers, ArchiveKind, ExtractLimits};
pub use current::{calls_in_progress, current_call, CallInProgress, CurrentCall};
pub use error::{Error, FmuMessages, Result};
pub use fmu::{
    set_debug_logging, special_file_kind, Fmu, InstanceOptions, Interface, OpenOptions,
    QUIRKS_TARGET,
};
pub use instance::{
    Fmi3Instance, FmuState, Instance, Integrator, LocalInstance, MeInstance, Method, StatusKind,
    MAX_EVENT_ITERATIONS,
};
pub use interface::{Capabilities, FmuInstance, Inputs, Int, RunRequest, Slot, SLOTS};
pub use library::{PLATFORM, PLATFORM_FMI3};
pub use logger::{parse_rate_limit, rate_limit_from_env, set_rate_limit, RATE_LIMIT};
pub use model_description::{
    element_names, BaseType, BaseUnit, BooleanVariable, Causality, CoSimulation, DefaultExperiment,
    DependencyKind, Dimension, DisplayUnit, EnumerationItem, FmiStandard, Initial, IntegerType,
    IntegerVariable, LogCategory, ModelDescription, ModelExchange, ModelStructure, Quirk, RealType,
    RealVariable, ScalarVariable, SimpleType, SimpleTypeKind, StringVariable, Unit, Unknown,
    ValueReference, ValueType, Values, Variability, VariableKind, VariableNamingConvention,
};
pub use placement::{instantiate, Placement};
pub use raw::Status;
pub use time::Time;
