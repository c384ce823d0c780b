//! One instance of the exported FMU: the system file from `resources/`, the
//! values of the exported parameters and inputs, and the
//! [`Simulation`] built at initialization. Safe code; [`crate::ffi`] calls it.

use std::path::{Path, PathBuf};

use tether_fmi::remote::protocol::{In, Out};
use tether_fmi::remote::{set_host, HostCommand, HOST_NAME};
use tether_fmu_kit::instance::{Failure, Outcome};
use tether_fmu_kit::machine::MachineState;
use tether_fmu_kit::xml::fnv1a64;
use tether_fmu_kit::InputJet;
use tether_master::spec::Isolation;
use tether_master::{
    ExportKind, ExportVariable, Parallel, Simulation, StartValue, SystemSpec, SystemState,
};

use crate::SYSTEM_FILE;

/// A saved state of the exported FMU (`fmi2GetFMUstate`): the whole
/// system's and the exported parameters' and inputs' values.
pub struct Saved {
    system: SystemState,
    values: Vec<f64>,
    inputs: Inputs,
    /// Its bytes, once `fmi2SerializedFMUstateSize` has made them.
    bytes: Vec<u8>,
}

/// The first bytes of a serialized state of an exported FMU, and the
/// format's version (docs/fmu-export.md).
const MAGIC: &[u8; 16] = b"tether-fmu-state";
const VERSION: u32 = 2;
const CHECKSUM_BASIS: u64 = 0xcbf2_9ce4_8422_2325;

/// The highest order of `fmi2SetRealInputDerivatives`: inputs are
/// interpolated by polynomials of degree ≤ 2 (the FMU kit's [`InputJet`]).
pub const MAX_INPUT_ORDER: i32 = 2;

/// The exported inputs between steps: their derivatives for the coming
/// step, and the values the current point was computed with.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Inputs {
    /// Per exported variable, the first and second time derivative given by
    /// `fmi2SetRealInputDerivatives` for the coming step (zero otherwise).
    derivatives: Vec<[f64; 2]>,
    /// Per exported variable, the value it had when the current point was
    /// computed (for an interpolated input: its polynomial at that time).
    at_point: Vec<f64>,
}

/// One `fmi2DoStep`/`fmi3DoStep` under way ([`Exported::begin_step`]).
pub struct Step {
    /// The communication point t the step started at.
    now: f64,
    /// The communication step h.
    h: f64,
    /// On the fixed grid, the inner steps still to make; with step control
    /// `None` (the steps end at t + h).
    remaining: Option<u64>,
    /// The inputs with derivatives: each one's target and its polynomial at t.
    jets: Vec<(String, InputJet)>,
}

pub struct Exported {
    spec: SystemSpec,
    /// The GUID, which a serialized state carries.
    guid: String,
    variables: Vec<ExportVariable>,
    /// The exported parameters' and inputs' values (outputs: unused).
    values: Vec<f64>,
    /// Per exported variable, the exported inputs an output depends on
    /// directly (`Simulation::export_dependencies`).
    dependencies: Vec<Vec<usize>>,
    inputs: Inputs,
    /// The current point's values solved again for the inputs set since it
    /// was computed, and those inputs' values ([`Simulation::consistent_values`]).
    resolved: Option<(Vec<f64>, Vec<f64>)>,
    /// `fmi2SetupExperiment`'s start and stop time.
    start: f64,
    stop: Option<f64>,
    /// Built at initialization, with the parameters and inputs set so far.
    sim: Option<Simulation>,
    pub machine: MachineState,
    /// Whether the state functions may be used (every member can).
    can_save: bool,
    /// A copy of the host program made executable, when the unpacked
    /// FMU's own could not be.
    _host: Option<tempfile::TempDir>,
}

/// For a system with isolated members: the host program the FMU carries
/// (`resources/tether-fmi-host`), made executable (archive tools do not
/// keep the exec bit; a read-only folder gets an executable copy, kept in
/// the returned folder) and set as this library's host, so that isolated
/// members never run a host from elsewhere (`TETHER_FMI_HOST` still comes
/// first, docs/reliability.md).
fn isolated_host(spec: &SystemSpec, resources: &Path) -> Result<Option<tempfile::TempDir>, String> {
    use std::os::unix::fs::PermissionsExt;
    let isolated = spec
        .instances
        .iter()
        .any(|i| i.isolation == Isolation::Process && i.host.is_none());
    if !isolated {
        return Ok(None);
    }
    let host = resources.join(HOST_NAME);
    let mode = std::fs::metadata(&host)
        .map_err(|e| {
            format!(
                "isolated members run in {}, which is missing: {e}",
                host.display()
            )
        })?
        .permissions()
        .mode();
    let executable = std::fs::Permissions::from_mode(mode | 0o555);
    let (program, copy) =
        if mode & 0o111 == 0o111 || std::fs::set_permissions(&host, executable.clone()).is_ok() {
            (host, None)
        } else {
            let dir =
                tempfile::tempdir().map_err(|e| format!("cannot copy {}: {e}", host.display()))?;
            let copy = dir.path().join(HOST_NAME);
            std::fs::copy(&host, &copy)
                .and_then(|_| std::fs::set_permissions(&copy, executable))
                .map_err(|e| format!("cannot make {} executable: {e}", host.display()))?;
            (copy, Some(dir))
        };
    set_host(HostCommand {
        program,
        args: Vec::new(),
    });
    Ok(copy)
}

/// `file:///a/b%20c/` → `/a/b c/`.
pub fn uri_path(uri: &str) -> Result<PathBuf, String> {
    let rest = uri
        .strip_prefix("file://")
        .map(|r| r.strip_prefix("localhost").unwrap_or(r))
        .or_else(|| uri.strip_prefix("file:"))
        .ok_or_else(|| format!("fmuResourceLocation '{uri}' is not a file:// URI"))?;
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let (Some(h), Some(l)) = (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    let path =
        String::from_utf8(out).map_err(|_| format!("fmuResourceLocation '{uri}' is not UTF-8"))?;
    Ok(PathBuf::from(path))
}

impl Exported {
    /// Reads `resources/system.toml`, checks the GUID against it and resolves
    /// the exported interface (the members are loaded once for that).
    pub fn new(resources: &Path, guid: &str) -> Result<Exported, String> {
        let file = resources.join(SYSTEM_FILE);
        let text = std::fs::read_to_string(&file)
            .map_err(|e| format!("cannot read {}: {e}", file.display()))?;
        let expected = crate::description::guid(&text);
        if guid != expected {
            return Err(format!(
                "GUID {guid} does not match the system file's {expected} ({})",
                file.display()
            ));
        }
        let mut spec = SystemSpec::from_file(&file).map_err(|e| e.to_string())?;
        // Inner perturbed runs stay on the importer's thread unless the
        // system file asks for threads.
        if spec.coupling.parallel == Parallel::Auto {
            spec.coupling.parallel = Parallel::Off;
        }
        let host = isolated_host(&spec, resources)?;
        let sim = Simulation::new(&spec).map_err(|e| e.to_string())?;
        let variables = sim.export_interface(&spec).map_err(|e| e.to_string())?;
        let can_save = sim.can_save_state();
        let dependencies = sim.export_dependencies(&variables);
        drop(sim);
        let values: Vec<f64> = variables.iter().map(|v| v.start.unwrap_or(0.0)).collect();
        let inputs = Inputs {
            derivatives: vec![[0.0; 2]; values.len()],
            at_point: values.clone(),
        };
        let start = spec.experiment.start;
        Ok(Exported {
            spec,
            guid: guid.to_string(),
            variables,
            values,
            dependencies,
            inputs,
            resolved: None,
            start,
            stop: None,
            sim: None,
            machine: MachineState::Instantiated,
            can_save,
            _host: host,
        })
    }

    pub fn setup_experiment(&mut self, start: f64, stop: Option<f64>) -> Outcome {
        if !start.is_finite() || stop.is_some_and(|s| !(s.is_finite() && s > start)) {
            return Err(Failure::usage(format!(
                "start time {start} and stop time {stop:?}: expected finite times, stop after start"
            )));
        }
        self.start = start;
        self.stop = stop;
        self.sim = None;
        Ok(())
    }

    /// The simulation, built with the values set so far if it is not yet.
    fn simulation(&mut self) -> Outcome<&mut Simulation> {
        if self.sim.is_none() {
            let mut spec = self.spec.clone();
            let step = spec.experiment.step;
            spec.experiment.stop = match self.stop {
                Some(stop) => stop,
                None => self.start + (spec.end_time() - spec.experiment.start),
            };
            spec.experiment.start = self.start;
            if spec.experiment.stop - spec.experiment.start < step * (1.0 - 1e-9) {
                return Err(Failure::usage(format!(
                    "stop time {} is less than one macro step ({step}) after the start time {}",
                    spec.experiment.stop, spec.experiment.start
                )));
            }
            for (v, &value) in self.variables.iter().zip(&self.values) {
                if v.kind == ExportKind::Output {
                    continue;
                }
                let (instance, variable) = v.target.split_once('.').unwrap_or_default();
                if let Some(i) = spec.instances.iter_mut().find(|i| i.name == instance) {
                    i.parameters
                        .insert(variable.to_string(), StartValue::Real(value));
                }
            }
            let sim = Simulation::new(&spec).map_err(|e| Failure::model(e.to_string()))?;
            for warning in sim.warnings() {
                log::warn!("{warning}");
            }
            self.sim = Some(sim);
            self.inputs.at_point.clone_from(&self.values);
            self.resolved = None;
        }
        Ok(self.sim.as_mut().expect("built above"))
    }

    pub fn exit_initialization_mode(&mut self) -> Outcome {
        self.simulation().map(|_| ())
    }

    pub fn reset(&mut self) {
        self.sim = None;
        self.resolved = None;
        self.inputs.derivatives.fill([0.0; 2]);
        self.values = self
            .variables
            .iter()
            .map(|v| v.start.unwrap_or(0.0))
            .collect();
        self.stop = None;
        self.start = self.spec.experiment.start;
    }

    fn variable(&self, vr: u32) -> Outcome<&ExportVariable> {
        self.variables.get(vr as usize).ok_or_else(|| {
            Failure::usage(format!(
                "value reference {vr} is not a variable (0 to {})",
                self.variables.len().saturating_sub(1)
            ))
        })
    }

    pub fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Outcome {
        for (&vr, value) in vrs.iter().zip(values.iter_mut()) {
            let v = self.variable(vr)?;
            *value = match v.column {
                Some(column) if self.changed_input(vr as usize) => self.resolved()?[column],
                Some(column) => self.simulation()?.values()[column],
                None => self.values[vr as usize],
            };
        }
        Ok(())
    }

    /// Whether an input that output `vr` depends on directly has been set
    /// to another value than the current point was computed with.
    fn changed_input(&self, vr: usize) -> bool {
        let at_point = &self.inputs.at_point;
        self.dependencies[vr]
            .iter()
            .any(|&i| self.values[i].to_bits() != at_point[i].to_bits())
    }

    /// The current point's values with the multipliers solved again for the
    /// inputs as they are set now (once per set of input values): no step,
    /// and the next step starts from the same point.
    fn resolved(&mut self) -> Outcome<&[f64]> {
        let fresh = matches!(&self.resolved, Some((values, _)) if *values == self.values);
        if !fresh {
            let row = self
                .simulation()?
                .consistent_values()
                .map_err(|e| Failure::model(e.to_string()))?;
            self.resolved = Some((self.values.clone(), row));
        }
        Ok(&self.resolved.as_ref().expect("solved above").1)
    }

    /// `fmi2SetRealInputDerivatives`: the derivatives of order 1 or 2 of
    /// inputs at the current time, for the coming `fmi2DoStep` (FMI 2.0:
    /// the input is then u(t) + u'(t)·(τ − t) + u''(t)·(τ − t)²/2 over the
    /// step). They hold for one step.
    pub fn set_input_derivatives(
        &mut self,
        vrs: &[u32],
        orders: &[i32],
        values: &[f64],
    ) -> Outcome {
        for ((&vr, &order), &value) in vrs.iter().zip(orders).zip(values) {
            let v = self.variable(vr)?;
            if v.kind != ExportKind::Input {
                return Err(Failure::usage(format!(
                    "{} is not an input: only inputs take derivatives",
                    v.name
                )));
            }
            if !(1..=MAX_INPUT_ORDER).contains(&order) {
                return Err(Failure::usage(format!(
                    "{}: derivative of order {order}; inputs are interpolated with derivatives \
                     of order 1 to {MAX_INPUT_ORDER}",
                    v.name
                )));
            }
            if !value.is_finite() {
                return Err(Failure::usage(format!(
                    "{}: derivative of order {order} = {value}: not a finite number",
                    v.name
                )));
            }
            self.inputs.derivatives[vr as usize][order as usize - 1] = value;
        }
        Ok(())
    }

    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Outcome {
        let stepping = self.machine == MachineState::StepComplete;
        for (&vr, &value) in vrs.iter().zip(values) {
            let v = self.variable(vr)?.clone();
            if !value.is_finite() {
                return Err(Failure::usage(format!(
                    "{} = {value}: not a finite number",
                    v.name
                )));
            }
            match (v.kind, stepping) {
                (ExportKind::Output, _) => {
                    return Err(Failure::usage(format!(
                        "{} is an output: it cannot be set",
                        v.name
                    )))
                }
                (ExportKind::Parameter, true) => {
                    return Err(Failure::usage(format!(
                        "{} is a fixed parameter: set it before fmi2ExitInitializationMode",
                        v.name
                    )))
                }
                // An input sets the member's input at once: a dependent
                // output read now is solved again with it. Before the first
                // step it is also a start value of the run: the first
                // fmi2DoStep builds the system again with it, so the run is
                // `tether run`'s with that value (consistent multipliers
                // included).
                (ExportKind::Input, _) => {
                    if let Some(sim) = self.sim.as_mut() {
                        sim.set_parameter(&v.target, &StartValue::Real(value))
                            .map_err(|e| Failure::usage(e.to_string()))?;
                    }
                }
                // Before the run: taken when the simulation is built.
                (ExportKind::Parameter, false) => self.sim = None,
            }
            self.values[vr as usize] = value;
        }
        Ok(())
    }

    /// `fmi2DoStep(t, h)`: the macro steps over [t, t + h], t the current
    /// time. On the fixed grid h must be a whole multiple of the system's
    /// step H (within 1e-9·H); with `[step_control]` any h > 0, the last
    /// inner step ending at t + h. Inputs with derivatives are set at each
    /// inner step's start τ to their polynomial there (with its derivatives,
    /// for a member that interpolates); other inputs are held.
    pub fn do_step(&mut self, t: f64, h: f64) -> Outcome {
        let mut step = self.begin_step(t, h)?;
        while self.next_inner_step(&step)?.is_some() {
            self.inner_step(&mut step)?;
        }
        self.end_step(&step)
    }

    /// The checks of [`do_step`](Self::do_step) and what its inner steps
    /// need. `fmi3DoStep` with an intermediate update callback runs the
    /// inner steps itself, calling back before each one
    /// ([`next_inner_step`](Self::next_inner_step)), so that the importer
    /// sets the inputs for that time.
    pub fn begin_step(&mut self, t: f64, h: f64) -> Outcome<Step> {
        let step = self.spec.experiment.step;
        let adaptive = self.spec.step_control.is_some();
        let jets = self.jets();
        self.restart_with_new_inputs();
        let now = self.simulation()?.time();
        if (t - now).abs() > 1e-9 * step.max(h.abs()) {
            return Err(Failure::usage(format!(
                "communication point {t} is not the FMU's time {now}"
            )));
        }
        let remaining = if adaptive {
            if !(h.is_finite() && h > 0.0) {
                return Err(Failure::usage(format!(
                    "communication step {h}: expected a positive step"
                )));
            }
            None
        } else {
            let n = (h / step).round();
            if !(n >= 1.0 && (h - n * step).abs() <= 1e-9 * step) {
                return Err(Failure::usage(format!(
                    "communication step {h} is not a whole multiple of the system's macro step {step} \
                     (within 1e-9 of a step)"
                )));
            }
            Some(n as u64)
        };
        Ok(Step {
            now,
            h,
            remaining,
            jets,
        })
    }

    /// Before the first step an input set since the run was built is a
    /// start value of the run: the run is built again with it, so that it
    /// is `tether run`'s with that value (consistent multipliers included).
    fn restart_with_new_inputs(&mut self) {
        if self.time() == Some(self.start) && self.inputs.at_point != self.values {
            self.sim = None;
        }
    }

    /// The start time of the step's next inner step, `None` when the step
    /// has reached its end.
    pub fn next_inner_step(&mut self, step: &Step) -> Outcome<Option<f64>> {
        let sim = self.simulation()?;
        let more = match step.remaining {
            Some(n) => n > 0,
            None => step.now + step.h - sim.time() > 1e-9 * step.h,
        };
        if !more {
            return Ok(None);
        }
        if sim.finished() {
            return Err(Failure::usage(format!(
                "step to {} goes beyond the stop time (the run ends at {})",
                step.now + step.h,
                sim.time()
            )));
        }
        Ok(Some(sim.time()))
    }

    /// One inner step, its inputs with derivatives set to their polynomial
    /// at its start; the others as they are set.
    pub fn inner_step(&mut self, step: &mut Step) -> Outcome {
        self.restart_with_new_inputs();
        let sim = self.simulation()?;
        for (target, jet) in &step.jets {
            let at = jet.shifted(sim.time() - step.now);
            let derivatives = [at.d1, at.d2];
            let order = if at.d2 == 0.0 { 1 } else { 2 };
            sim.set_input(target, at.value, &derivatives[..order])
                .map_err(|e| Failure::usage(e.to_string()))?;
        }
        let model = |e: tether_master::MasterError| Failure::model(e.to_string());
        match &mut step.remaining {
            Some(n) => {
                sim.step().map_err(model)?;
                *n -= 1;
            }
            None => sim.step_until(step.now + step.h).map_err(model)?,
        }
        Ok(())
    }

    /// The end of a step: each interpolated input is now its polynomial's
    /// value at the point reached, which the outputs there were computed
    /// with; it is held from here on (until the importer sets it), its
    /// derivatives cleared.
    pub fn end_step(&mut self, step: &Step) -> Outcome {
        let now = step.now;
        let sim = self.simulation()?;
        let end = sim.time();
        for (target, jet) in &step.jets {
            sim.set_input(target, jet.eval(end - now), &[])
                .map_err(|e| Failure::usage(e.to_string()))?;
        }
        for (i, d) in self.inputs.derivatives.iter_mut().enumerate() {
            if *d != [0.0; 2] {
                let jet = InputJet {
                    value: self.values[i],
                    d1: d[0],
                    d2: d[1],
                };
                self.values[i] = jet.eval(end - now);
                *d = [0.0; 2];
            }
        }
        self.inputs.at_point.clone_from(&self.values);
        self.resolved = None;
        Ok(())
    }

    /// The inputs with derivatives for the coming step: each one's target and
    /// polynomial at the current time. Empty when no input has any (held).
    fn jets(&self) -> Vec<(String, InputJet)> {
        (self
            .variables
            .iter()
            .zip(&self.values)
            .zip(&self.inputs.derivatives))
        .filter(|((v, _), d)| v.kind == ExportKind::Input && **d != [0.0; 2])
        .map(|((v, &value), d)| {
            let jet = InputJet {
                value,
                d1: d[0],
                d2: d[1],
            };
            (v.target.clone(), jet)
        })
        .collect()
    }

    pub fn time(&self) -> Option<f64> {
        self.sim.as_ref().map(Simulation::time)
    }

    /// The start time (the system's, or as the importer set it).
    pub fn start_time(&self) -> f64 {
        self.start
    }

    /// The number of exported variables (value references 0 to n − 1).
    pub fn variable_count(&self) -> usize {
        self.variables.len()
    }

    fn require_state(&self) -> Outcome {
        if self.can_save {
            Ok(())
        } else {
            Err(Failure::usage(
                "a member FMU cannot save its state (canGetAndSetFMUstate and canSerializeFMUstate), so neither can the system",
            ))
        }
    }

    pub fn get_state(&mut self) -> Outcome<Saved> {
        self.require_state()?;
        let values = self.values.clone();
        let inputs = self.inputs.clone();
        let system = self
            .simulation()?
            .save_state()
            .map_err(|e| Failure::model(e.to_string()))?;
        Ok(Saved {
            system,
            values,
            inputs,
            bytes: Vec::new(),
        })
    }

    pub fn set_state(&mut self, saved: &Saved) -> Outcome {
        self.require_state()?;
        self.simulation()?
            .restore_state(&saved.system)
            .map_err(|e| Failure::model(e.to_string()))?;
        self.values.clone_from(&saved.values);
        self.inputs.clone_from(&saved.inputs);
        self.resolved = None;
        Ok(())
    }

    /// `saved` as bytes (`fmi2SerializeFMUstate`): the magic and format
    /// version, the GUID, the exported parameters' and inputs' values, the
    /// whole system's state ([`SystemState::write`]) and an FNV-1a checksum
    /// of all that. Made once per saved state.
    pub fn serialize<'s>(&self, saved: &'s mut Saved) -> Outcome<&'s [u8]> {
        self.require_state()?;
        if saved.bytes.is_empty() {
            let mut out = Out(MAGIC.to_vec());
            out.u32(VERSION).str(&self.guid).f64s(&saved.values);
            out.f64s(saved.inputs.derivatives.as_flattened())
                .f64s(&saved.inputs.at_point);
            saved.system.write(&mut out).map_err(Failure::usage)?;
            let checksum = fnv1a64(&out.0, CHECKSUM_BASIS);
            out.u64(checksum);
            saved.bytes = out.0;
        }
        Ok(&saved.bytes)
    }

    /// A state from bytes of [`serialize`](Self::serialize) of this FMU
    /// (`fmi2DeSerializeFMUstate`): bytes that are cut short, changed, of
    /// another format version or of another exported system are refused
    /// with the reason.
    pub fn deserialize(&mut self, bytes: &[u8]) -> Outcome<Saved> {
        self.require_state()?;
        let refuse = |why: String| Failure::usage(format!("not a state of this FMU: {why}"));
        let n = bytes.len();
        if n < MAGIC.len() + 8 || !bytes.starts_with(MAGIC) {
            return Err(refuse(format!(
                "{n} bytes that do not begin with '{}'",
                String::from_utf8_lossy(MAGIC)
            )));
        }
        let (body, sum) = bytes.split_at(n - 8);
        let sum = u64::from_le_bytes(sum.try_into().expect("8 bytes"));
        if fnv1a64(body, CHECKSUM_BASIS) != sum {
            return Err(refuse(format!(
                "the checksum of its {n} bytes does not match (cut short or changed)"
            )));
        }
        let mut input = In::new(&body[MAGIC.len()..]);
        let short = |_| refuse("the bytes end early".into());
        let version = input.u32().map_err(short)?;
        if version != VERSION {
            return Err(refuse(format!(
                "format version {version}, this FMU reads version {VERSION}"
            )));
        }
        let guid = input.str().map_err(short)?;
        if guid != self.guid {
            return Err(refuse(format!(
                "it was saved by the FMU with GUID {guid}, this one is {}",
                self.guid
            )));
        }
        let mut values = Vec::new();
        input.f64s(&mut values).map_err(short)?;
        if values.len() != self.values.len() {
            return Err(refuse(format!(
                "{} exported values, this FMU has {}",
                values.len(),
                self.values.len()
            )));
        }
        let mut derivatives = Vec::new();
        input.f64s(&mut derivatives).map_err(short)?;
        let mut at_point = Vec::new();
        input.f64s(&mut at_point).map_err(short)?;
        if derivatives.len() != 2 * values.len() || at_point.len() != values.len() {
            return Err(refuse("the exported inputs' sizes differ".into()));
        }
        let inputs = Inputs {
            derivatives: derivatives.chunks(2).map(|d| [d[0], d[1]]).collect(),
            at_point,
        };
        let system = self.simulation()?.read_state(&mut input).map_err(refuse)?;
        if !input.is_empty() {
            return Err(refuse("bytes are left after the state".into()));
        }
        Ok(Saved {
            system,
            values,
            inputs,
            bytes: Vec::new(),
        })
    }
}
