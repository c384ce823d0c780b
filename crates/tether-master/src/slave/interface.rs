//! Which FMI interface an instance runs (`fmi_type` of an `[[instance]]`):
//! what the system's method needs of it, and the choice of `"auto"` —
//! co-simulation wherever it runs the method, model exchange only where
//! co-simulation would be refused and the FMU offers model exchange.

use tether_fmi::{Capabilities, Interface, ModelDescription};

use crate::spec::{InstanceSpec, InterfaceChoice, SystemSpec};
use crate::MasterError;

/// What the system's method needs of one instance, each with who needs it,
/// and the integrator it gets if it runs model exchange.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Needs {
    /// The instance's `integrator` settings.
    pub integrator: tether_fmi::Integrator,
    /// Rollback (`canGetAndSetFMUstate`).
    pub rollback: Option<String>,
    /// Steps of varying size (adaptive steps).
    pub variable_steps: bool,
    /// Inputs that take polynomials (k > 0 on an instance the constraints
    /// drive).
    pub polynomial_inputs: bool,
}

impl Needs {
    /// What `spec`'s method needs of `instance`; an error for settings of
    /// its `integrator` out of range.
    pub(crate) fn of(spec: &SystemSpec, instance: &InstanceSpec) -> Result<Needs, MasterError> {
        let integrator = instance
            .integrator
            .as_ref()
            .map(|i| i.integrator())
            .transpose()
            .map_err(|reason| MasterError::SystemFile {
                path: spec.source_name(),
                reason: format!("instance '{}': integrator: {reason}", instance.name),
            })?
            .unwrap_or_default();
        let constrained = constrained(spec, &instance.name);
        let rollback = if spec.step_control.is_some() {
            Some("adaptive steps ([step_control])".to_string())
        } else if spec.signals.iterations.is_some() {
            Some("[signals] iterations".to_string())
        } else if constrained && spec.method.needs_rollback() {
            Some(format!(
                "the predictor/corrector method {}",
                spec.method.name()
            ))
        } else {
            None
        };
        Ok(Needs {
            integrator,
            rollback,
            variable_steps: spec.step_control.is_some(),
            polynomial_inputs: constrained && spec.coupling.order > 0,
        })
    }

    /// The first capability of `caps` short of these needs, with who needs
    /// it.
    fn lacking(&self, caps: &Capabilities) -> Option<(&'static str, String)> {
        if let Some(by) = self.rollback.as_ref().filter(|_| !caps.rollback) {
            return Some(("canGetAndSetFMUstate", by.clone()));
        }
        if self.variable_steps && !caps.variable_steps {
            return Some((
                "canHandleVariableCommunicationStepSize",
                "adaptive steps ([step_control])".into(),
            ));
        }
        if self.polynomial_inputs && !caps.polynomial_inputs {
            return Some((
                "inputs that take polynomials",
                "coupling polynomials of degree k > 0".into(),
            ));
        }
        None
    }
}

/// Whether the constraints, joints or coupling variables of `spec` name
/// instance `name` (as `name.` at the start of a word).
fn constrained(spec: &SystemSpec, name: &str) -> bool {
    let prefix = format!("{name}.");
    let names = |text: &str| {
        text.match_indices(&prefix).any(|(at, _)| {
            text[..at]
                .chars()
                .next_back()
                .is_none_or(|c| !(c.is_alphanumeric() || c == '_' || c == '.'))
        })
    };
    spec.constraints.iter().any(|c| {
        [
            Some(&c.position),
            c.velocity.as_ref(),
            c.acceleration.as_ref(),
            Some(&c.drives),
        ]
        .into_iter()
        .flatten()
        .any(|t| names(t))
    }) || spec.joints.iter().any(|j| names(&j.i) || names(&j.j))
        || spec
            .coupling_variables
            .iter()
            .any(|v| names(&v.drives) || names(&v.value))
}

/// The interface `instance` runs, and a note for the user when `"auto"`
/// took model exchange.
pub(crate) fn choose(
    instance: &InstanceSpec,
    md: &ModelDescription,
    needs: &Needs,
) -> (Interface, Option<String>) {
    let model_exchange = Interface::ModelExchange(needs.integrator);
    let name = &instance.name;
    match instance.fmi_type {
        InterfaceChoice::CoSimulation => (Interface::CoSimulation, None),
        InterfaceChoice::ModelExchange => (model_exchange, None),
        InterfaceChoice::Auto => match (&md.co_simulation, &md.model_exchange) {
            (None, Some(_)) => (
                model_exchange,
                Some(format!(
                    "'{name}' runs model exchange: its FMU offers no co-simulation"
                )),
            ),
            (Some(_), Some(_)) => {
                let cs = Capabilities::co_simulation(md);
                let me = Capabilities::model_exchange(md);
                match needs.lacking(&cs) {
                    Some((capability, by)) if needs.lacking(&me).is_none() => (
                        model_exchange,
                        Some(format!(
                            "'{name}' runs model exchange (fmi_type = \"auto\"): its \
                             co-simulation interface lacks {capability}, which {by} needs"
                        )),
                    ),
                    _ => (Interface::CoSimulation, None),
                }
            }
            _ => (Interface::CoSimulation, None),
        },
    }
}
