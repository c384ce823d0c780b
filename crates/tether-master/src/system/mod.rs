//! The coupled [`System`] every coupling method works on — the instances, the
//! coupling rows and unknowns, the unknowns' history, which instances each
//! unknown drives — and how it is built from a system file: the constraints,
//! joints and coupling variables resolved against the FMUs' variables into
//! rows and unknowns ([`resolve`]), the instances instantiated and
//! initialised, and the consistent initial multipliers from direct
//! feedthrough ([`feedthrough`]). The step a coupling method takes on it is
//! [`crate::algorithm::step`].

pub(crate) mod feedthrough;
pub(crate) mod resolve;

use std::path::Path;

use crate::coupling::touched::{Touched, MAX_INTERFACE_ENTRIES};
use crate::coupling::Coupling;
use crate::polynomial::Taylor;
use crate::runs::Runs;
use crate::slave::interface::Needs;
use crate::slave::{Run, Slave};
use crate::spec::{CheckRollback, InitialMultiplier, SystemSpec};
use crate::{MasterError, Method};

/// The instances and their coupling, as every method sees them.
pub(crate) struct System {
    pub slaves: Vec<Slave>,
    /// How the runs of a step are made: on the main thread or shared with
    /// worker threads (`[coupling] parallel`).
    pub runs: Runs,
    pub coupling: Coupling,
    /// Coupled outputs of each instance at the last accepted point.
    pub outputs: Vec<Vec<f64>>,
    /// Per unknown: `[u_N, u_{N-1}, u_{N-2}]`.
    pub history: Vec<[f64; 3]>,
    /// For each unknown, the instances whose inputs it drives (its owners).
    pub owners: Vec<Vec<usize>>,
    /// Unknowns whose perturbations share one run: no two drive the same instance.
    pub groups: Vec<Vec<usize>>,
    /// Per group, the instances its perturbed run steps (those its unknowns drive).
    pub group_slaves: Vec<Vec<usize>>,
    /// The rows each unknown's perturbation touches (the Jacobian's pattern).
    pub touched: Touched,
    /// Finite-difference increment ε (`coupling.epsilon`).
    pub epsilon: f64,
    /// Largest condition number a linear solve accepts (`coupling.max_condition`).
    pub max_condition: f64,
    /// The rollback check's polynomials (the unknowns held), reused.
    check_polys: Vec<Taylor>,
}

impl System {
    /// Instantiate the FMUs with their start values, resolve the coupling
    /// against them and initialise them for `[start, stop]`.
    pub fn new(spec: &SystemSpec, method: &Method, stop: f64) -> Result<System, MasterError> {
        let order = spec.coupling.order;
        let mut opened = Vec::new();
        let mut slaves = spec
            .instances
            .iter()
            .map(|instance| {
                let experiment = (spec.experiment.start, stop, spec.experiment.tolerance);
                let needs = Needs::of(spec, instance)?;
                Slave::instantiate(instance, &mut opened, order, experiment, &needs)
                    .map_err(|e| against_system_folder(e, spec, &instance.fmu))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let coupling = Coupling::build(spec, &mut slaves, method, order)?;
        let mut owners: Vec<Vec<usize>> = vec![Vec::new(); coupling.len()];
        for (s, slave) in slaves.iter().enumerate() {
            for input in &slave.coupled.inputs {
                for &(m, _) in &input.terms {
                    // Instances come in order: a repeat is the last one.
                    if owners[m].last() != Some(&s) {
                        owners[m].push(s);
                    }
                }
            }
        }
        // The interface system's size first: what follows grows with it.
        let touched = Touched::new(&coupling, &owners, slaves.len()).ok_or_else(|| {
            MasterError::SystemFile {
                path: spec.source_name(),
                reason: format!(
                    "its {n} coupling unknowns make an interface Jacobian with more than \
                     {MAX_INTERFACE_ENTRIES} entries that can be non-zero, above the limit (docs/system-file.md, \"Limits\")",
                    n = coupling.len()
                ),
            }
        })?;
        let groups = perturbation_groups(&owners, slaves.len());
        let group_slaves: Vec<Vec<usize>> = groups
            .iter()
            .map(|group| {
                let mut members: Vec<usize> = group
                    .iter()
                    .flat_map(|&m| owners[m].iter().copied())
                    .collect();
                members.sort_unstable();
                members.dedup();
                members
            })
            .collect();
        let runs = Runs::new(
            spec.coupling.parallel,
            spec.coupling.threads,
            &slaves,
            &spec.instances,
            &group_slaves,
            coupling.len(),
        )?;
        let every_step = spec.coupling.check_rollback == CheckRollback::EveryStep;
        for slave in &mut slaves {
            slave.enter_initialization()?;
            slave.check.verify_restore =
                every_step && method.needs_rollback() && slave.is_coupled();
        }
        let history = coupling
            .unknowns
            .iter()
            .map(|c| match c.initial {
                InitialMultiplier::Value(v) => [v; 3],
                InitialMultiplier::Consistent => [0.0; 3],
            })
            .collect();
        Ok(System {
            outputs: slaves.iter().map(|s| vec![0.0; s.coupled_len()]).collect(),
            slaves,
            runs,
            coupling,
            history,
            owners,
            groups,
            group_slaves,
            touched,
            epsilon: spec.coupling.epsilon,
            max_condition: spec.coupling.max_condition,
            check_polys: Vec::new(),
        })
    }

    /// Every instance leaves initialization mode ([`System::new`] leaves
    /// them in it, for the loops' values at T_0).
    pub fn exit_initialization(&mut self) -> Result<(), MasterError> {
        for slave in &mut self.slaves {
            slave.exit_initialization()?;
        }
        Ok(())
    }

    /// The finite-difference increment of unknown `m`: `ε·max(1, |u_{m,N}|)`.
    pub fn delta(&self, m: usize) -> f64 {
        self.epsilon * self.history[m][0].abs().max(1.0)
    }

    /// Set every instance's coupled inputs from the unknowns' polynomials.
    pub fn apply_inputs(&mut self, polys: &[Taylor]) -> Result<(), MasterError> {
        for slave in &mut self.slaves {
            slave.apply_inputs(polys)?;
        }
        Ok(())
    }

    /// The rollback self-check of every instance the method rolls back (those
    /// an unknown drives), from the current state with the unknowns u_N held
    /// constant over [t, t + h]; each is left in its current state.
    pub fn check_rollback(&mut self, t: f64, h: f64) -> Result<(), MasterError> {
        // The unknowns held at their values (buffer kept between checks).
        let mut polys = std::mem::take(&mut self.check_polys);
        polys.clear();
        polys.extend(self.history.iter().map(|u| Taylor {
            value: u[0],
            ..Taylor::default()
        }));
        for slave in self.slaves.iter_mut().filter(|s| s.is_coupled()) {
            slave.check_rollback(&polys, t, h)?;
        }
        self.check_polys = polys;
        Ok(())
    }

    /// `fmi2Terminate` every instance, at a normal end of the run.
    pub fn terminate(&mut self) -> Result<(), MasterError> {
        for slave in &mut self.slaves {
            slave.terminate()?;
        }
        Ok(())
    }

    /// Read the coupled outputs (into `outputs`) and the recorded outputs of
    /// every instance at an accepted point.
    /// `run` names the call they come after, for a non-finite value.
    pub fn read_accepted(&mut self, run: Run) -> Result<(), MasterError> {
        for (slave, out) in self.slaves.iter_mut().zip(&mut self.outputs) {
            slave.read_accepted(out, run)?;
        }
        Ok(())
    }
}

/// Group unknowns so that no two in a group drive the same instance: one
/// perturbed run per group serves every unknown in it (greedy colouring:
/// each unknown joins the first group none of its instances is in). Linear
/// in the number of (unknown, instance) pairs times the groups an instance
/// is in, which is bounded by the unknowns driving it.
pub(crate) fn perturbation_groups(owners: &[Vec<usize>], instances: usize) -> Vec<Vec<usize>> {
    let mut groups: Vec<Vec<usize>> = Vec::new();
    // Per instance: the groups it is already in.
    let mut used: Vec<Vec<usize>> = vec![Vec::new(); instances];
    let mut taken: Vec<usize> = Vec::new();
    for (m, own) in owners.iter().enumerate() {
        taken.clear();
        taken.extend(own.iter().flat_map(|&s| used[s].iter().copied()));
        taken.sort_unstable();
        taken.dedup();
        // The first group index not taken.
        let g = taken
            .iter()
            .enumerate()
            .find(|&(i, &t)| i != t)
            .map_or(taken.len(), |(i, _)| i);
        if g == groups.len() {
            groups.push(Vec::new());
        }
        groups[g].push(m);
        for &s in own {
            used[s].push(g);
        }
    }
    groups
}

/// An FMU that is not there, said as the system file has it: the path as
/// written, resolved against the system file's folder (`from_file` joined
/// them; a path the file gives absolute stays as it is).
fn against_system_folder(e: MasterError, spec: &SystemSpec, fmu: &Path) -> MasterError {
    let MasterError::InstanceFmu {
        instance,
        error: tether_fmi::Error::Missing { place, source },
    } = e
    else {
        return e;
    };
    let folder = spec
        .source
        .as_deref()
        .map(|file| file.parent().unwrap_or(Path::new("")));
    let place = match folder {
        Some(folder) if !fmu.is_absolute() || fmu.starts_with(folder) => {
            let written = fmu.strip_prefix(folder).unwrap_or(fmu);
            Box::new(tether_fmi::paths::Missing::new(
                written,
                Some((folder, "the system file's folder")),
            ))
        }
        _ => place,
    };
    MasterError::InstanceFmu {
        instance,
        error: tether_fmi::Error::Missing { place, source },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknowns_on_different_instances_share_a_perturbed_run() {
        // λ0 drives A and B, λ1 drives only A, λ2 only C, λ3 only B.
        let owners = vec![vec![0, 1], vec![0], vec![2], vec![1]];
        let groups = perturbation_groups(&owners, 3);
        assert_eq!(groups, vec![vec![0, 2], vec![1, 3]]);
    }
}
