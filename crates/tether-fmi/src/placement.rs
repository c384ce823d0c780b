//! Where an instance runs, and [`instantiate`]: the one place that picks the
//! implementation of [`FmuInstance`] for an FMU's standard and placement.

use std::time::Duration;

use crate::error::Result;
use crate::fmu::{Fmu, InstanceOptions};
use crate::instance::LocalInstance;
use crate::interface::FmuInstance;

/// Where an instance runs.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Placement {
    /// The FMU's library is loaded in this process.
    #[default]
    InProcess,
    /// A host process of its own; each call waits at most `timeout`.
    Process {
        /// The longest a call may take before the host is killed.
        timeout: Option<Duration>,
    },
    /// A host on another machine (`tether host`), over TCP; each call waits
    /// at most `timeout`.
    Remote {
        /// The longest a call may take before the host is stopped.
        timeout: Option<Duration>,
        /// Where the host is, its token and the FMU on it.
        host: crate::remote::tcp::RemoteHost,
    },
}

/// Instantiates `fmu` as `name` where `placement` says.
pub fn instantiate(
    fmu: &Fmu,
    name: &str,
    options: InstanceOptions,
    placement: Placement,
) -> Result<Box<dyn FmuInstance>> {
    fmu.require_co_simulation()?;
    let fmi3 = fmu.model_description().standard == crate::model_description::FmiStandard::Fmi3;
    Ok(match placement {
        Placement::InProcess if fmi3 => {
            Box::new(crate::instance::Fmi3Instance::new(fmu, name, options)?)
        }
        Placement::InProcess => Box::new(LocalInstance::new(fmu.instantiate(name, options)?)),
        // The host makes its instance with this function, in its process.
        Placement::Process { timeout } => Box::new(crate::remote::RemoteInstance::new(
            fmu, name, options, timeout,
        )?),
        Placement::Remote { timeout, host } => Box::new(crate::remote::RemoteInstance::connect(
            fmu, name, options, timeout, &host,
        )?),
    })
}
