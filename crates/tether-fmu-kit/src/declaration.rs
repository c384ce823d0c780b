//! The static declaration of a model: everything `modelDescription.xml` says about it.
//!
//! A model author writes one `const DECLARATION: Declaration` with the `const fn`
//! builders below; the kit derives the value references, the XML and the checks from it.

/// A Real variable: a parameter (with start, min, max) or an input (with start).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Real {
    pub name: &'static str,
    pub start: f64,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub unit: Option<&'static str>,
    pub description: &'static str,
}

impl Real {
    pub const fn new(name: &'static str, start: f64) -> Self {
        Real {
            name,
            start,
            min: None,
            max: None,
            unit: None,
            description: "",
        }
    }
    pub const fn min(mut self, min: f64) -> Self {
        self.min = Some(min);
        self
    }
    pub const fn max(mut self, max: f64) -> Self {
        self.max = Some(max);
        self
    }
    pub const fn unit(mut self, unit: &'static str) -> Self {
        self.unit = Some(unit);
        self
    }
    pub const fn description(mut self, description: &'static str) -> Self {
        self.description = description;
        self
    }
}

/// An Integer parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Integer {
    pub name: &'static str,
    pub start: i32,
    pub min: Option<i32>,
    pub max: Option<i32>,
    pub description: &'static str,
}

impl Integer {
    pub const fn new(name: &'static str, start: i32) -> Self {
        Integer {
            name,
            start,
            min: None,
            max: None,
            description: "",
        }
    }
    pub const fn min(mut self, min: i32) -> Self {
        self.min = Some(min);
        self
    }
    pub const fn max(mut self, max: i32) -> Self {
        self.max = Some(max);
        self
    }
    pub const fn description(mut self, description: &'static str) -> Self {
        self.description = description;
        self
    }
}

/// A Boolean parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Boolean {
    pub name: &'static str,
    pub start: bool,
    pub description: &'static str,
}

impl Boolean {
    pub const fn new(name: &'static str, start: bool) -> Self {
        Boolean {
            name,
            start,
            description: "",
        }
    }
    pub const fn description(mut self, description: &'static str) -> Self {
        self.description = description;
        self
    }
}

/// A Real output, computed by [`crate::Model::outputs`]. `depends_on` names the
/// states and inputs it is a function of (ModelStructure/Outputs dependencies); an
/// output that names an input has direct feedthrough.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Output {
    pub name: &'static str,
    pub unit: Option<&'static str>,
    pub description: &'static str,
    pub depends_on: &'static [&'static str],
}

impl Output {
    pub const fn new(name: &'static str) -> Self {
        Output {
            name,
            unit: None,
            description: "",
            depends_on: &[],
        }
    }
    pub const fn unit(mut self, unit: &'static str) -> Self {
        self.unit = Some(unit);
        self
    }
    pub const fn description(mut self, description: &'static str) -> Self {
        self.description = description;
        self
    }
    pub const fn depends_on(mut self, names: &'static [&'static str]) -> Self {
        self.depends_on = names;
        self
    }
}

/// A continuous state, exposed as a local variable together with its derivative
/// `der(<name>)`. Its initial value comes from [`crate::Model::initial_states`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct State {
    pub name: &'static str,
    pub unit: Option<&'static str>,
    /// Unit of the derivative, e.g. "m/s" for a position in "m".
    pub derivative_unit: Option<&'static str>,
    pub description: &'static str,
}

impl State {
    pub const fn new(name: &'static str) -> Self {
        State {
            name,
            unit: None,
            derivative_unit: None,
            description: "",
        }
    }
    pub const fn unit(mut self, unit: &'static str, derivative_unit: &'static str) -> Self {
        self.unit = Some(unit);
        self.derivative_unit = Some(derivative_unit);
        self
    }
    pub const fn description(mut self, description: &'static str) -> Self {
        self.description = description;
        self
    }
}

/// `<DefaultExperiment>` of the model description.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: f64,
    pub stop_time: f64,
    pub step_size: f64,
}

/// The optional capabilities an FMU declares in `<CoSimulation>`. The kit
/// implements all of them; a model may declare fewer, as many tool-exported
/// FMUs do, and the kit then refuses the calls it does not declare
/// (fmi2Error).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capabilities {
    /// `canGetAndSetFMUstate` (and `canSerializeFMUstate`): fmi2GetFMUstate,
    /// fmi2SetFMUstate, fmi2FreeFMUstate and the serialization functions.
    pub can_get_and_set_fmu_state: bool,
    /// `canInterpolateInputs`: fmi2SetRealInputDerivatives.
    pub can_interpolate_inputs: bool,
}

impl Capabilities {
    /// Every capability the kit implements (the default).
    pub const ALL: Capabilities = Capabilities {
        can_get_and_set_fmu_state: true,
        can_interpolate_inputs: true,
    };
}

/// Everything static about a model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Declaration {
    pub model_name: &'static str,
    /// Also the name of the shared library and of the `.fmu` file.
    pub model_identifier: &'static str,
    pub description: &'static str,
    pub real_parameters: &'static [Real],
    pub integer_parameters: &'static [Integer],
    pub boolean_parameters: &'static [Boolean],
    pub inputs: &'static [Real],
    pub outputs: &'static [Output],
    pub states: &'static [State],
    /// 0 if [`crate::Model::output_derivatives`] is not implemented.
    pub max_output_derivative_order: u32,
    pub default_experiment: DefaultExperiment,
    /// The optional capabilities declared (default [`Capabilities::ALL`]).
    pub capabilities: Capabilities,
    /// Whether the FMU also offers model exchange (`<ModelExchange>` beside
    /// `<CoSimulation>`, in FMI 2.0 and 3.0): the importer integrates the
    /// model's [`derivatives`](crate::Model::derivatives) itself. Default
    /// `false`: co-simulation only.
    pub model_exchange: bool,
}

impl Declaration {
    /// A declaration with nothing in it, for `..Declaration::EMPTY`.
    pub const EMPTY: Declaration = Declaration {
        model_name: "",
        model_identifier: "",
        description: "",
        real_parameters: &[],
        integer_parameters: &[],
        boolean_parameters: &[],
        inputs: &[],
        outputs: &[],
        states: &[],
        max_output_derivative_order: 0,
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-3,
        },
        capabilities: Capabilities::ALL,
        model_exchange: false,
    };
}

/// Name of the parameter the kit adds to every model: the integrator's relative and
/// absolute tolerance.
pub const TOLERANCE: &str = "tolerance";
/// Default of [`TOLERANCE`].
pub const DEFAULT_TOLERANCE: f64 = 1e-10;

/// What a value reference points at. Value references are the positions in
/// `<ModelVariables>` (0-based), unique across all types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// Real parameter `i`; the last one is [`TOLERANCE`].
    RealParameter(usize),
    IntegerParameter(usize),
    BooleanParameter(usize),
    Input(usize),
    Output(usize),
    State(usize),
    Derivative(usize),
    /// The independent variable `time` (FMI 3.0 only: the value reference after
    /// every other variable, read-only).
    Time,
}

/// The FMI type of a variable, as the get/set functions see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarType {
    Real,
    Integer,
    Boolean,
}

impl VarType {
    pub fn name(self) -> &'static str {
        match self {
            VarType::Real => "Real",
            VarType::Integer => "Integer",
            VarType::Boolean => "Boolean",
        }
    }
}

impl Slot {
    #[inline]
    pub fn var_type(self) -> VarType {
        match self {
            Slot::IntegerParameter(_) => VarType::Integer,
            Slot::BooleanParameter(_) => VarType::Boolean,
            _ => VarType::Real,
        }
    }
}

impl Declaration {
    /// The Real parameters including the kit's [`TOLERANCE`] (last).
    pub fn all_real_parameters(&self) -> Vec<Real> {
        let mut all = self.real_parameters.to_vec();
        all.push(
            Real::new(TOLERANCE, DEFAULT_TOLERANCE)
                .min(0.0)
                .description("Relative and absolute tolerance of the integrator"),
        );
        all
    }

    /// Every variable in `<ModelVariables>` order; the index is the value reference.
    pub fn slots(&self) -> Vec<Slot> {
        let mut slots = Vec::new();
        slots.extend((0..self.real_parameters.len() + 1).map(Slot::RealParameter));
        slots.extend((0..self.integer_parameters.len()).map(Slot::IntegerParameter));
        slots.extend((0..self.boolean_parameters.len()).map(Slot::BooleanParameter));
        slots.extend((0..self.inputs.len()).map(Slot::Input));
        slots.extend((0..self.outputs.len()).map(Slot::Output));
        slots.extend((0..self.states.len()).map(Slot::State));
        slots.extend((0..self.states.len()).map(Slot::Derivative));
        slots
    }

    /// The variable name of a slot.
    pub fn name(&self, slot: Slot) -> String {
        match slot {
            Slot::RealParameter(i) if i == self.real_parameters.len() => TOLERANCE.to_string(),
            Slot::RealParameter(i) => self.real_parameters[i].name.to_string(),
            Slot::IntegerParameter(i) => self.integer_parameters[i].name.to_string(),
            Slot::BooleanParameter(i) => self.boolean_parameters[i].name.to_string(),
            Slot::Input(i) => self.inputs[i].name.to_string(),
            Slot::Output(i) => self.outputs[i].name.to_string(),
            Slot::State(i) => self.states[i].name.to_string(),
            Slot::Derivative(i) => format!("der({})", self.states[i].name),
            Slot::Time => "time".to_string(),
        }
    }

    /// Checks what the type system cannot: unique names, known dependencies, a
    /// model identifier that is a C identifier, sane starts and ranges.
    pub fn check(&self) -> Result<(), String> {
        let id = self.model_identifier;
        let is_c_identifier = id
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !is_c_identifier {
            return Err(format!("modelIdentifier {id:?} is not a C identifier"));
        }
        let slots = self.slots();
        let names: Vec<String> = slots.iter().map(|&s| self.name(s)).collect();
        for (i, name) in names.iter().enumerate() {
            if name.is_empty() {
                return Err("a variable has an empty name".to_string());
            }
            if names[..i].contains(name) {
                return Err(format!("variable name {name:?} is declared twice"));
            }
        }
        for output in self.outputs {
            for dep in output.depends_on {
                let known = self.states.iter().any(|s| s.name == *dep)
                    || self.inputs.iter().any(|u| u.name == *dep);
                if !known {
                    return Err(format!(
                        "output {:?} depends on {dep:?}, which is neither a state nor an input",
                        output.name
                    ));
                }
            }
        }
        for p in self.real_parameters.iter().chain(self.inputs) {
            if !p.start.is_finite()
                || p.min.is_some_and(|m| p.start < m)
                || p.max.is_some_and(|m| p.start > m)
            {
                return Err(format!(
                    "start value {} of {:?} is outside [min, max] or not finite",
                    p.start, p.name
                ));
            }
        }
        for p in self.integer_parameters {
            if p.min.is_some_and(|m| p.start < m) || p.max.is_some_and(|m| p.start > m) {
                return Err(format!(
                    "start value {} of {:?} is outside [min, max]",
                    p.start, p.name
                ));
            }
        }
        Ok(())
    }
}

/// Parameter values handed to [`crate::Model::new`], looked up by name.
#[derive(Clone, Copy, Debug)]
pub struct Parameters<'a> {
    pub(crate) declaration: &'a Declaration,
    pub(crate) reals: &'a [f64],
    pub(crate) integers: &'a [i32],
    pub(crate) booleans: &'a [bool],
}

impl<'a> Parameters<'a> {
    pub fn new(
        declaration: &'a Declaration,
        reals: &'a [f64],
        integers: &'a [i32],
        booleans: &'a [bool],
    ) -> Self {
        Parameters {
            declaration,
            reals,
            integers,
            booleans,
        }
    }

    /// Value of the Real parameter `name` (including [`TOLERANCE`]).
    pub fn real(&self, name: &str) -> Result<f64, String> {
        let index = if name == TOLERANCE {
            Some(self.declaration.real_parameters.len())
        } else {
            self.declaration
                .real_parameters
                .iter()
                .position(|p| p.name == name)
        };
        index
            .and_then(|i| self.reals.get(i).copied())
            .ok_or_else(|| format!("no Real parameter {name:?}"))
    }

    pub fn integer(&self, name: &str) -> Result<i32, String> {
        let index = self
            .declaration
            .integer_parameters
            .iter()
            .position(|p| p.name == name);
        index
            .and_then(|i| self.integers.get(i).copied())
            .ok_or_else(|| format!("no Integer parameter {name:?}"))
    }

    pub fn boolean(&self, name: &str) -> Result<bool, String> {
        let index = self
            .declaration
            .boolean_parameters
            .iter()
            .position(|p| p.name == name);
        index
            .and_then(|i| self.booleans.get(i).copied())
            .ok_or_else(|| format!("no Boolean parameter {name:?}"))
    }
}
