//! [`Fmi3Instance`]: an FMI 3.0 co-simulation instance in this process, as a master
//! drives it ([`FmuInstance`]).
//!
//! The instance is made with `fmi3InstantiateCoSimulation`, `eventModeUsed` and
//! `earlyReturnAllowed` false: an FMU that declares `hasEventMode` or
//! `canReturnEarlyAfterIntermediateUpdate` runs without them, as the standard allows.
//! FMUs with clocks are refused (clocks need event mode).
//!
//! An FMU that declares `providesIntermediateUpdate`, instantiated for polynomial
//! inputs ([`InstanceOptions::polynomial_inputs`], the master's k > 0), gets the
//! intermediate update callback, and its Float64 inputs declared
//! `intermediateUpdate="true"` as the required intermediate variables; otherwise
//! no callback (the FMU makes none). Such an input takes a polynomial over a step
//! ([`FmuInstance::set_inputs`] with derivatives), set to the polynomial's value at
//! every intermediate time at which the FMU asks for inputs
//! (`component::fmi3`'s intermediate update). Other inputs take values only (k = 0).
//!
//! Values go through the [`FmuInstance`] methods by kind: `get_reals`/`set_reals` for
//! `Float64` and `Float32`, `get_integers`/`set_integers` for every integer type and
//! enumerations (exactly, as [`Int`]; a value set outside the variable's type is an
//! error, never wrapped),
//! `get_booleans`/`set_booleans` for `Boolean`, `get_strings`/`set_strings` for `String`
//! and `Binary` (as hexadecimal text). An array variable takes as many values as it has
//! elements, row-major, its sizes following the structural parameters set so far. A
//! structural parameter set before initialization is set in configuration mode.

use std::collections::HashMap;
use std::sync::Arc;

use crate::component::fmi3::{InstantiateArgs3, RawInstance3, RawState3, StepAnswers};
use crate::error::{Error, Result};
use crate::fmu::{Fmu, InstanceOptions};
use crate::interface::{FmuInstance, Inputs, Int, Slot, SLOTS};
use crate::model_description::{
    hex_decode, hex_encode, Causality, ModelDescription, ScalarVariable, ValueReference, ValueType,
};
use crate::shared::{FmuShared, OnceGuard};

/// Where an instance is in the FMI 3.0 life cycle (as far as the safe layer cares).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Instantiated: structural parameters are set in configuration mode.
    Instantiated,
    /// Initialization mode, step mode, terminated.
    Initialized,
}

/// Consecutive requested variables of one type, and where their values go.
#[derive(Debug, Clone)]
struct Group {
    ty: ValueType,
    vrs: std::ops::Range<usize>,
    values: std::ops::Range<usize>,
}

/// An FMI 3.0 co-simulation instance in this process, with its saved states.
#[derive(Debug)]
pub struct Fmi3Instance {
    raw: RawInstance3,
    fmu: Arc<FmuShared>,
    states: [Option<(RawState3, f64)>; SLOTS],
    experiment: (Option<f64>, f64, Option<f64>),
    phase: Phase,
    /// Value reference → index into the model variables (the first with it).
    index: HashMap<ValueReference, usize>,
    /// Structural parameters set on this instance, by value reference.
    structural: HashMap<ValueReference, u64>,
    /// No `Float32` and no floating-point array: Real values go straight to
    /// `fmi3GetFloat64`/`fmi3SetFloat64`.
    plain_reals: bool,
    /// The inputs that take a polynomial over a step (intermediate update).
    polynomial_inputs: Vec<ValueReference>,
    /// Made for model exchange: the `ModelExchange` flags say what it can do.
    model_exchange: bool,
}

impl Fmi3Instance {
    /// `fmi3SetFloat64` (and `fmi3SetFloat32`) of Real values, with no effect on
    /// the inputs' polynomials.
    fn write_reals(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        const F: &str = "fmi3SetFloat64";
        if self.plain_reals && vrs.len() == values.len() {
            return self.raw.fmi3SetFloat64(vrs, values);
        }
        for g in self.groups(F, "Float64 or Float32", vrs, values.len(), is_float)? {
            if g.ty == ValueType::Float64 {
                self.raw
                    .fmi3SetFloat64(&vrs[g.vrs.clone()], &values[g.values.clone()])?;
            } else {
                // Rounded to the nearest Float32, as the FMU would store it.
                let narrow: Vec<f32> = values[g.values].iter().map(|&x| x as f32).collect();
                self.raw.fmi3SetFloat32(&vrs[g.vrs.clone()], &narrow)?;
            }
        }
        Ok(())
    }

    /// The outcome of an `fmi3DoStep` to `end` that failed or reported
    /// something besides its status (termination, an early return, an event).
    #[cold]
    #[inline(never)]
    fn step_answered(&mut self, end: f64, result: Result<()>, answers: StepAnswers) -> Result<()> {
        let terminated = |time: f64, this: &mut Self| {
            this.raw.time = time;
            Error::TerminationRequested {
                instance: this.raw.name().to_owned(),
                time,
                how: Some("fmi3DoStep returned terminateSimulation = true".into()),
            }
        };
        match result {
            Ok(()) => {
                if answers.terminate_simulation {
                    let time = if answers.early_return {
                        answers.last_successful_time
                    } else {
                        end
                    };
                    return Err(terminated(time, self));
                }
                if answers.early_return && answers.last_successful_time < end {
                    return Err(self.invalid(
                        "fmi3DoStep",
                        format!(
                            "the FMU returned early at t = {} (the step was to end at t = {}), which earlyReturnAllowed = false forbids",
                            crate::Time(answers.last_successful_time),
                            crate::Time(end)
                        ),
                    ));
                }
                // Without event mode the FMU handles its events itself: the standard
                // has the importer ignore eventHandlingNeeded.
                if answers.event_handling_needed {
                    log::trace!(
                        target: "tether_fmi::call",
                        "fmi3DoStep({}): eventHandlingNeeded ignored (no event mode) at t={end}",
                        self.raw.name()
                    );
                }
                self.raw.time = end;
                Ok(())
            }
            Err(Error::Discard { .. }) if answers.terminate_simulation => {
                Err(terminated(answers.last_successful_time, self))
            }
            Err(e) => Err(e),
        }
    }

    /// Instantiates `fmu` (an FMI 3.0 co-simulation FMU) as `name`.
    pub fn new(fmu: &Fmu, name: &str, options: InstanceOptions) -> Result<Fmi3Instance> {
        Fmi3Instance::new_as(fmu, name, options, false)
    }

    /// Instantiates `fmu` for model exchange (`fmi3InstantiateModelExchange`), for
    /// [`MeInstance`](crate::MeInstance), which drives it.
    pub(crate) fn new_model_exchange(
        fmu: &Fmu,
        name: &str,
        options: InstanceOptions,
    ) -> Result<Fmi3Instance> {
        Fmi3Instance::new_as(fmu, name, options, true)
    }

    fn new_as(
        fmu: &Fmu,
        name: &str,
        options: InstanceOptions,
        model_exchange: bool,
    ) -> Result<Fmi3Instance> {
        let shared = Arc::clone(fmu.shared());
        let md = &shared.model_description;
        let clocks: Vec<&str> = md
            .model_variables
            .iter()
            .filter(|v| v.value_type == ValueType::Clock)
            .map(|v| v.name.as_str())
            .collect();
        if !clocks.is_empty() {
            return Err(Error::Unsupported {
                model: md.model_name.clone(),
                reason: if model_exchange {
                    format!(
                        "it has clocks ({}); Tether runs FMI 3.0 model exchange without clocks",
                        clocks.join(", ")
                    )
                } else {
                    format!(
                        "it has clocks ({}), which need event mode; Tether runs FMI 3.0 co-simulation without event mode",
                        clocks.join(", ")
                    )
                },
            });
        }
        let cs = md.cs();
        let once_per_process = if model_exchange {
            let Some(me) = &md.model_exchange else {
                return Err(Error::Unsupported {
                    model: md.model_name.clone(),
                    reason: "it has no model-exchange interface (no <ModelExchange> element)"
                        .into(),
                });
            };
            me.can_be_instantiated_only_once_per_process
        } else {
            fmu.require_co_simulation()?;
            if cs.has_event_mode || cs.can_return_early_after_intermediate_update {
                log::debug!(
                    "model '{}' offers event mode or early return; instance '{name}' runs without them",
                    md.model_name
                );
            }
            cs.can_be_instantiated_only_once_per_process
        };
        let once = if once_per_process {
            Some(OnceGuard::acquire(&md.guid, &md.model_name, name)?)
        } else {
            None
        };
        let debug = crate::fmu::debug_logging();
        let intermediate_update =
            !model_exchange && cs.provides_intermediate_update && options.polynomial_inputs;
        let polynomial_inputs: Vec<ValueReference> = if intermediate_update {
            md.model_variables
                .iter()
                .filter(|v| {
                    v.causality == Causality::Input
                        && v.intermediate_update
                        && v.value_type == ValueType::Float64
                        && !v.is_array()
                })
                .map(|v| v.value_reference)
                .collect()
        } else {
            Vec::new()
        };
        let mut resources = shared.dir.resources().to_string_lossy().into_owned();
        if !resources.ends_with('/') {
            resources.push('/');
        }
        let mut raw = RawInstance3::fmi3InstantiateCoSimulation(
            shared.library3()?,
            Arc::clone(&shared.dir),
            &InstantiateArgs3 {
                model: &md.model_name,
                instance_name: name,
                instantiation_token: &md.guid,
                resource_path: &resources,
                visible: options.visible,
                logging_on: options.logging_on || debug.is_some(),
                event_mode_used: false,
                early_return_allowed: false,
                required_intermediate_variables: &polynomial_inputs,
                intermediate_update,
                model_exchange,
            },
        )?;
        raw.once = once;
        let mut index = HashMap::with_capacity(md.model_variables.len());
        for (i, v) in md.model_variables.iter().enumerate() {
            index.entry(v.value_reference).or_insert(i);
        }
        let plain_reals = !md.model_variables.iter().any(|v| {
            v.value_type == ValueType::Float32
                || (v.value_type == ValueType::Float64 && v.is_array())
        });
        let start = md
            .default_experiment
            .and_then(|d| d.start_time)
            .unwrap_or(0.0);
        let mut instance = Fmi3Instance {
            raw,
            fmu: Arc::clone(&shared),
            states: Default::default(),
            experiment: (None, start, None),
            phase: Phase::Instantiated,
            index,
            structural: HashMap::new(),
            plain_reals,
            polynomial_inputs,
            model_exchange,
        };
        if let Some(wanted) = debug.filter(|c| !c.is_empty()) {
            let declared = &md.log_categories;
            let categories: Vec<&str> = wanted
                .iter()
                .filter(|c| declared.is_empty() || declared.iter().any(|d| d.name == **c))
                .map(String::as_str)
                .collect();
            if !categories.is_empty() {
                instance.raw.fmi3SetDebugLogging(true, &categories)?;
            }
        }
        Ok(instance)
    }

    fn md(&self) -> &ModelDescription {
        &self.fmu.model_description
    }

    /// `canGetAndSetFMUState` and `canSerializeFMUState` of the interface the
    /// instance was made for.
    fn state_flags(&self) -> (bool, bool) {
        let md = self.md();
        match (&md.model_exchange, self.model_exchange) {
            (Some(me), true) => (me.can_get_and_set_fmu_state, me.can_serialize_fmu_state),
            _ => (
                md.cs().can_get_and_set_fmu_state,
                md.cs().can_serialize_fmu_state,
            ),
        }
    }

    /// The raw instance, for the model-exchange calls of [`crate::MeInstance`].
    pub(crate) fn raw_mut(&mut self) -> &mut RawInstance3 {
        &mut self.raw
    }

    fn invalid(&self, function: &'static str, message: String) -> Error {
        Error::InvalidArgument {
            function,
            instance: self.raw.name().to_owned(),
            message,
        }
    }

    /// The variable with value reference `vr`.
    fn variable(&self, function: &'static str, vr: ValueReference) -> Result<&ScalarVariable> {
        match self.index.get(&vr) {
            Some(&i) => Ok(&self.md().model_variables[i]),
            None => Err(self.invalid(
                function,
                format!(
                    "model '{}' has no variable with value reference {vr}",
                    self.md().model_name
                ),
            )),
        }
    }

    /// The number of values of `v` now (1 for a scalar).
    fn count(&self, v: &ScalarVariable) -> Result<usize> {
        if !v.is_array() {
            return Ok(1);
        }
        let structural = &self.structural;
        let sizes = self
            .md()
            .array_sizes_with(v, &|vr| structural.get(&vr).copied())?;
        Ok(sizes.iter().product::<u64>() as usize)
    }

    /// Splits `vrs` into runs of one type accepted by `accepts`, checking that their
    /// values number `n`.
    fn groups(
        &self,
        function: &'static str,
        kind: &str,
        vrs: &[ValueReference],
        n: usize,
        accepts: fn(ValueType) -> bool,
    ) -> Result<Vec<Group>> {
        let mut groups: Vec<Group> = Vec::new();
        let mut offset = 0;
        for (i, &vr) in vrs.iter().enumerate() {
            let v = self.variable(function, vr)?;
            if !accepts(v.value_type) {
                return Err(self.invalid(
                    function,
                    format!(
                        "variable '{}' is {}, not {kind}",
                        v.name,
                        v.value_type.name()
                    ),
                ));
            }
            let count = self.count(v)?;
            match groups.last_mut() {
                Some(g) if g.ty == v.value_type => {
                    g.vrs.end = i + 1;
                    g.values.end = offset + count;
                }
                _ => groups.push(Group {
                    ty: v.value_type,
                    vrs: i..i + 1,
                    values: offset..offset + count,
                }),
            }
            offset += count;
        }
        if offset != n {
            return Err(Error::LengthMismatch {
                function,
                instance: self.raw.name().to_owned(),
                what: "the value slice",
                expected: offset,
                got: n,
            });
        }
        Ok(groups)
    }

    /// The value reference of the group's variable holding value `k` (for messages).
    fn vr_at(&self, vrs: &[ValueReference], g: &Group, k: usize) -> ValueReference {
        let mut offset = g.values.start;
        for &vr in &vrs[g.vrs.clone()] {
            let n = self
                .variable("", vr)
                .and_then(|v| self.count(v))
                .unwrap_or(1);
            if k < offset + n {
                return vr;
            }
            offset += n;
        }
        vrs[g.vrs.start]
    }

    /// Runs `set` in configuration mode when a structural parameter is set before
    /// initialization, and records the new sizes.
    fn with_structural<T: Copy>(
        &mut self,
        vrs: &[ValueReference],
        values: &[T],
        as_u64: fn(T) -> Option<u64>,
        set: impl FnOnce(&mut Self) -> Result<()>,
    ) -> Result<()> {
        let structural: Vec<(ValueReference, Option<u64>)> = vrs
            .iter()
            .zip(values)
            .filter(|(vr, _)| {
                self.index
                    .get(vr)
                    .is_some_and(|&i| self.md().model_variables[i].structural_parameter)
            })
            .map(|(&vr, &x)| (vr, as_u64(x)))
            .collect();
        if structural.is_empty() {
            return set(self);
        }
        let configure = self.phase == Phase::Instantiated;
        if configure {
            self.raw.fmi3EnterConfigurationMode()?;
        }
        let result = set(self);
        if configure {
            // The set's error first: it is the cause of any that follows.
            let exited = self.raw.fmi3ExitConfigurationMode();
            result?;
            exited?;
        } else {
            result?;
        }
        for (vr, value) in structural {
            if let Some(value) = value {
                self.structural.insert(vr, value);
            }
        }
        Ok(())
    }

    fn require(&self, flag: bool, capability: &'static str, operation: &'static str) -> Result<()> {
        if flag {
            Ok(())
        } else {
            Err(Error::MissingCapability {
                model: self.md().model_name.clone(),
                capability,
                operation,
            })
        }
    }

    fn slot_state(&self, slot: Slot, function: &'static str) -> Result<&(RawState3, f64)> {
        self.states
            .get(slot)
            .and_then(Option::as_ref)
            .ok_or_else(|| self.invalid(function, format!("no FMU state saved in slot {slot}")))
    }
}

fn is_float(t: ValueType) -> bool {
    matches!(t, ValueType::Float32 | ValueType::Float64)
}

fn is_integer(t: ValueType) -> bool {
    t.is_integer() || t == ValueType::Enumeration
}

fn is_boolean(t: ValueType) -> bool {
    t == ValueType::Boolean
}

fn is_text(t: ValueType) -> bool {
    matches!(t, ValueType::String | ValueType::Binary)
}

/// Reads one group of integers of type `$t` with `$get`.
macro_rules! get_ints {
    ($self:ident, $vrs:ident, $g:ident, $out:ident, $get:ident, $t:ty) => {{
        let mut wide: Vec<$t> = vec![0; $g.values.len()];
        $self.raw.$get(&$vrs[$g.vrs.clone()], &mut wide)?;
        for (o, x) in $out[$g.values.clone()].iter_mut().zip(wide) {
            *o = Int::from(x);
        }
    }};
}

/// Writes one group of integers as integers of type `$t` with `$set`.
macro_rules! set_ints {
    ($self:ident, $function:expr, $vrs:ident, $g:ident, $values:ident, $set:ident, $t:ty) => {{
        let mut wide: Vec<$t> = Vec::with_capacity($g.values.len());
        for (k, &x) in $values[$g.values.clone()].iter().enumerate() {
            match <$t>::try_from(x) {
                Ok(x) => wide.push(x),
                Err(_) => {
                    let vr = $self.vr_at($vrs, &$g, $g.values.start + k);
                    let name = $self.variable($function, vr)?.name.clone();
                    return Err($self.invalid(
                        $function,
                        format!(
                            "the value {x} is outside the range of {} '{name}'",
                            $g.ty.name()
                        ),
                    ));
                }
            }
        }
        $self.raw.$set(&$vrs[$g.vrs.clone()], &wide)?;
    }};
}

impl FmuInstance for Fmi3Instance {
    fn name(&self) -> &str {
        self.raw.name()
    }
    fn capabilities(&self) -> crate::interface::Capabilities {
        crate::interface::Capabilities::co_simulation(self.model_description())
    }
    fn model_description(&self) -> &ModelDescription {
        self.md()
    }
    fn time(&self) -> f64 {
        self.raw.time
    }
    fn is_fatal(&self) -> bool {
        self.raw.is_fatal()
    }
    fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Result<()> {
        self.raw.fmi3SetDebugLogging(on, categories)
    }
    fn setup(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Result<()> {
        // FMI 3.0 passes the experiment to fmi3EnterInitializationMode.
        self.experiment = (tolerance, start, stop);
        self.raw.time = start;
        Ok(())
    }
    fn enter_initialization(&mut self) -> Result<()> {
        let (tolerance, start, stop) = self.experiment;
        self.raw
            .fmi3EnterInitializationMode(tolerance, start, stop)?;
        self.phase = Phase::Initialized;
        self.raw.time = start;
        Ok(())
    }
    fn exit_initialization(&mut self) -> Result<()> {
        self.raw.fmi3ExitInitializationMode()
    }

    fn get_reals(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        const F: &str = "fmi3GetFloat64";
        if self.plain_reals && vrs.len() == out.len() {
            return self.raw.fmi3GetFloat64(vrs, out);
        }
        for g in self.groups(F, "Float64 or Float32", vrs, out.len(), is_float)? {
            if g.ty == ValueType::Float64 {
                self.raw
                    .fmi3GetFloat64(&vrs[g.vrs.clone()], &mut out[g.values.clone()])?;
            } else {
                let mut narrow = vec![0f32; g.values.len()];
                self.raw.fmi3GetFloat32(&vrs[g.vrs.clone()], &mut narrow)?;
                for (o, x) in out[g.values].iter_mut().zip(narrow) {
                    *o = f64::from(x);
                }
            }
        }
        Ok(())
    }

    fn set_reals(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        // A value set on an input ends its polynomial.
        if self.raw.intermediate_update {
            self.raw.env.hold(vrs);
        }
        self.write_reals(vrs, values)
    }

    fn get_integers(&mut self, vrs: &[ValueReference], out: &mut [Int]) -> Result<()> {
        const F: &str = "fmi3GetInt32";
        for g in self.groups(F, "an integer or enumeration", vrs, out.len(), is_integer)? {
            match g.ty {
                ValueType::Int32 => get_ints!(self, vrs, g, out, fmi3GetInt32, i32),
                ValueType::Int8 => get_ints!(self, vrs, g, out, fmi3GetInt8, i8),
                ValueType::UInt8 => get_ints!(self, vrs, g, out, fmi3GetUInt8, u8),
                ValueType::Int16 => get_ints!(self, vrs, g, out, fmi3GetInt16, i16),
                ValueType::UInt16 => {
                    get_ints!(self, vrs, g, out, fmi3GetUInt16, u16)
                }
                ValueType::UInt32 => {
                    get_ints!(self, vrs, g, out, fmi3GetUInt32, u32)
                }
                ValueType::UInt64 => {
                    get_ints!(self, vrs, g, out, fmi3GetUInt64, u64)
                }
                _ => get_ints!(self, vrs, g, out, fmi3GetInt64, i64),
            }
        }
        Ok(())
    }

    fn set_integers(&mut self, vrs: &[ValueReference], values: &[Int]) -> Result<()> {
        const F: &str = "fmi3SetInt32";
        let groups = self.groups(
            F,
            "an integer or enumeration",
            vrs,
            values.len(),
            is_integer,
        )?;
        self.with_structural(
            vrs,
            values,
            |x| u64::try_from(x).ok(),
            |this| {
                for g in groups {
                    match g.ty {
                        ValueType::Int32 => {
                            set_ints!(this, "fmi3SetInt32", vrs, g, values, fmi3SetInt32, i32)
                        }
                        ValueType::Int8 => {
                            set_ints!(this, "fmi3SetInt8", vrs, g, values, fmi3SetInt8, i8)
                        }
                        ValueType::UInt8 => {
                            set_ints!(this, "fmi3SetUInt8", vrs, g, values, fmi3SetUInt8, u8)
                        }
                        ValueType::Int16 => {
                            set_ints!(this, "fmi3SetInt16", vrs, g, values, fmi3SetInt16, i16)
                        }
                        ValueType::UInt16 => {
                            set_ints!(this, "fmi3SetUInt16", vrs, g, values, fmi3SetUInt16, u16)
                        }
                        ValueType::UInt32 => {
                            set_ints!(this, "fmi3SetUInt32", vrs, g, values, fmi3SetUInt32, u32)
                        }
                        ValueType::UInt64 => {
                            set_ints!(this, "fmi3SetUInt64", vrs, g, values, fmi3SetUInt64, u64)
                        }
                        _ => set_ints!(this, "fmi3SetInt64", vrs, g, values, fmi3SetInt64, i64),
                    }
                }
                Ok(())
            },
        )
    }

    fn get_booleans(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.groups("fmi3GetBoolean", "Boolean", vrs, out.len(), is_boolean)?;
        self.raw.fmi3GetBoolean(vrs, out)
    }

    fn set_booleans(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.groups("fmi3SetBoolean", "Boolean", vrs, values.len(), is_boolean)?;
        self.raw.fmi3SetBoolean(vrs, values)
    }

    fn get_strings(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()> {
        for g in self.groups("fmi3GetString", "String or Binary", vrs, out.len(), is_text)? {
            if g.ty == ValueType::String {
                self.raw
                    .fmi3GetString(&vrs[g.vrs.clone()], &mut out[g.values.clone()])?;
            } else {
                let mut bytes = vec![Vec::new(); g.values.len()];
                self.raw.fmi3GetBinary(&vrs[g.vrs.clone()], &mut bytes)?;
                for (o, b) in out[g.values].iter_mut().zip(bytes) {
                    *o = hex_encode(&b);
                }
            }
        }
        Ok(())
    }

    fn set_strings(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        const F: &str = "fmi3SetBinary";
        for g in self.groups(
            "fmi3SetString",
            "String or Binary",
            vrs,
            values.len(),
            is_text,
        )? {
            if g.ty == ValueType::String {
                self.raw
                    .fmi3SetString(&vrs[g.vrs.clone()], &values[g.values.clone()])?;
            } else {
                let bytes = values[g.values.clone()]
                    .iter()
                    .map(|t| {
                        hex_decode(t).ok_or_else(|| {
                            self.invalid(
                                F,
                                format!("\"{t}\" is not hexadecimal text (a Binary value)"),
                            )
                        })
                    })
                    .collect::<Result<Vec<Vec<u8>>>>()?;
                let slices: Vec<&[u8]> = bytes.iter().map(Vec::as_slice).collect();
                self.raw.fmi3SetBinary(&vrs[g.vrs.clone()], &slices)?;
            }
        }
        Ok(())
    }

    /// The values now; with derivatives, each input's polynomial for the coming
    /// step, which the intermediate update callback evaluates at the FMU's
    /// intermediate times (FMI 3.0 has no input derivatives).
    fn set_inputs(&mut self, inputs: &Inputs<'_>) -> Result<()> {
        if let Some(&vr) = inputs
            .derivative_vrs
            .iter()
            .find(|vr| !self.polynomial_inputs.contains(vr))
        {
            let variable = self.variable("fmi3SetFloat64", vr)?;
            let name = variable.name.clone();
            let md = self.md();
            let why = if md.cs().provides_intermediate_update && variable.intermediate_update {
                format!("instance '{}' was instantiated for values only (InstanceOptions::polynomial_inputs false: no intermediate update callback)", self.raw.name())
            } else {
                format!("FMI 3.0 has no input derivatives, and model '{}' does not provide intermediate update for it (providesIntermediateUpdate and intermediateUpdate=\"true\")", md.model_name)
            };
            return Err(self.invalid(
                "fmi3SetFloat64",
                format!(
                    "input '{name}' cannot take a polynomial (a coupling polynomial of degree k > 0): {why}; use k = 0"
                ),
            ));
        }
        // Each input's polynomial is replaced in place, or ended (held) when it
        // has no derivatives: no allocation once every input has had one.
        self.write_reals(inputs.vrs, inputs.values)?;
        if !self.raw.intermediate_update {
            return Ok(());
        }
        // Around the start of the coming step (`step`).
        self.raw.env.set_polynomials(
            inputs.vrs,
            inputs.values,
            inputs.derivative_vrs,
            inputs.orders,
            inputs.derivatives,
        );
        Ok(())
    }

    fn get_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        const F: &str = "fmi3GetOutputDerivatives";
        self.groups(F, "Float64", vrs, out.len(), |t| t == ValueType::Float64)?;
        self.raw.fmi3GetOutputDerivatives(vrs, orders, out)
    }

    fn step(&mut self, t: f64, h: f64) -> Result<()> {
        let no_set_prior = self.states.iter().all(Option::is_none);
        if self.raw.intermediate_update {
            self.raw.env.begin_step(t);
        }
        let (result, answers) = self.raw.fmi3DoStep(t, h, no_set_prior);
        if result.is_ok() && answers.plain() {
            self.raw.time = t + h;
            return Ok(());
        }
        self.step_answered(t + h, result, answers)
    }

    fn save(&mut self, slot: Slot) -> Result<()> {
        self.require(
            self.state_flags().0,
            "canGetAndSetFMUState",
            "saving an FMU state",
        )?;
        let time = self.raw.time;
        let mut state = self.states[slot].take().map(|(s, _)| s);
        let result = self.raw.fmi3GetFMUState(&mut state);
        self.states[slot] = state.map(|s| (s, time));
        result
    }
    fn restore(&mut self, slot: Slot) -> Result<()> {
        self.slot_state(slot, "fmi3SetFMUState")?;
        let Some((state, time)) = self.states[slot].as_ref() else {
            return Ok(());
        };
        self.raw.fmi3SetFMUState(state)?;
        self.raw.time = *time;
        Ok(())
    }
    fn free(&mut self, slot: Slot) -> Result<()> {
        match self.states.get_mut(slot).and_then(Option::take) {
            Some((state, _)) => self.raw.fmi3FreeFMUState(state),
            None => Ok(()),
        }
    }
    fn serialize(&mut self, slot: Slot, out: &mut Vec<u8>) -> Result<()> {
        self.require(
            self.state_flags().1,
            "canSerializeFMUState",
            "serializing an FMU state",
        )?;
        self.slot_state(slot, "fmi3SerializeFMUState")?;
        let Some((state, _)) = self.states[slot].as_ref() else {
            return Ok(());
        };
        self.raw.fmi3SerializeFMUState(state, out)
    }
    fn deserialize(&mut self, slot: Slot, bytes: &[u8]) -> Result<()> {
        self.require(
            self.state_flags().1,
            "canSerializeFMUState",
            "deserializing an FMU state",
        )?;
        let state = self.raw.fmi3DeserializeFMUState(bytes)?;
        let time = self.raw.time;
        if let Some((old, _)) = self.states[slot].replace((state, time)) {
            self.raw.fmi3FreeFMUState(old)?;
        }
        Ok(())
    }
    fn reset(&mut self) -> Result<()> {
        self.raw.fmi3Reset()?;
        self.phase = Phase::Instantiated;
        self.structural.clear();
        Ok(())
    }
    fn terminate(&mut self) -> Result<()> {
        self.raw.fmi3Terminate()
    }
}

impl Drop for Fmi3Instance {
    /// Frees the saved states; `fmi3FreeInstance` follows when `raw` drops.
    fn drop(&mut self) {
        if self.raw.is_fatal() {
            return;
        }
        for slot in 0..SLOTS {
            if let Err(e) = self.free(slot) {
                log::warn!(target: "tether_fmi::call", "{e}");
            }
        }
    }
}
