//! Where an instance runs, and [`instantiate`]: the one place that picks the
//! implementation of [`FmuInstance`] for an FMU's standard and placement.

use std::time::Duration;

use crate::error::Result;
use crate::fmu::{Fmu, InstanceOptions, Interface};
use crate::instance::{LocalInstance, MeInstance};
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

/// Instantiates `fmu` as `name` where `placement` says, for the interface
/// `options.interface` says. A model-exchange instance is a [`MeInstance`]
/// where the FMU is loaded: in this process, or in the host process, which
/// integrates it there (each step one call, as a co-simulation step).
pub fn instantiate(
    fmu: &Fmu,
    name: &str,
    options: InstanceOptions,
    placement: Placement,
) -> Result<Box<dyn FmuInstance>> {
    match options.interface {
        Interface::CoSimulation => fmu.require_co_simulation()?,
        Interface::ModelExchange(integrator) => {
            fmu.require_model_exchange()?;
            // Refused here as in process, before a host is started.
            integrator
                .check()
                .map_err(|message| crate::Error::InvalidArgument {
                    function: "the integrator",
                    instance: name.to_owned(),
                    message,
                })?;
        }
    }
    let fmi3 = fmu.model_description().standard == crate::model_description::FmiStandard::Fmi3;
    Ok(match placement {
        Placement::InProcess => match options.interface {
            Interface::ModelExchange(integrator) => {
                Box::new(MeInstance::new(fmu, name, options, integrator)?)
            }
            Interface::CoSimulation if fmi3 => {
                Box::new(crate::instance::Fmi3Instance::new(fmu, name, options)?)
            }
            Interface::CoSimulation => {
                Box::new(LocalInstance::new(fmu.instantiate(name, options)?))
            }
        },
        // The host makes its instance with this function, in its process.
        Placement::Process { timeout } => Box::new(crate::remote::RemoteInstance::new(
            fmu, name, options, timeout,
        )?),
        Placement::Remote { timeout, host } => Box::new(crate::remote::RemoteInstance::connect(
            fmu, name, options, timeout, &host,
        )?),
    })
}
