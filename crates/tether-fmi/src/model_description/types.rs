//! Plain data types mirroring the FMI 2.0 `modelDescription.xml` schema (co-simulation
//! relevant parts), with the standard's defaults already applied.

/// An FMI value reference.
pub type ValueReference = u32;

/// The parsed `fmiModelDescription` element.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelDescription {
    /// `fmiVersion` (always starts with "2.").
    pub fmi_version: String,
    /// `modelName`.
    pub model_name: String,
    /// `guid`, passed to `fmi2Instantiate`.
    pub guid: String,
    /// `description`.
    pub description: Option<String>,
    /// `author`.
    pub author: Option<String>,
    /// `version`.
    pub version: Option<String>,
    /// `copyright`.
    pub copyright: Option<String>,
    /// `license`.
    pub license: Option<String>,
    /// `generationTool`.
    pub generation_tool: Option<String>,
    /// `generationDateAndTime`.
    pub generation_date_and_time: Option<String>,
    /// `variableNamingConvention` (default flat).
    pub variable_naming_convention: VariableNamingConvention,
    /// `numberOfEventIndicators`.
    pub number_of_event_indicators: Option<u32>,
    /// The `CoSimulation` element.
    pub co_simulation: CoSimulation,
    /// `modelIdentifier` of the `ModelExchange` element, if the FMU has one.
    pub model_exchange: Option<String>,
    /// `UnitDefinitions`.
    pub unit_definitions: Vec<Unit>,
    /// `TypeDefinitions`.
    pub type_definitions: Vec<SimpleType>,
    /// `LogCategories`.
    pub log_categories: Vec<LogCategory>,
    /// `DefaultExperiment`.
    pub default_experiment: Option<DefaultExperiment>,
    /// `ModelVariables`, in file order (index i+1 in FMI's 1-based numbering).
    pub model_variables: Vec<ScalarVariable>,
    /// `ModelStructure`.
    pub model_structure: ModelStructure,
    pub(crate) by_name: std::collections::HashMap<String, usize>,
}

/// `variableNamingConvention`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VariableNamingConvention {
    /// Any string.
    #[default]
    Flat,
    /// Modelica-like structured names.
    Structured,
}

/// The `CoSimulation` element's capability flags.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CoSimulation {
    /// Name of the shared library (without extension) and prefix of the functions.
    pub model_identifier: String,
    /// `needsExecutionTool`.
    pub needs_execution_tool: bool,
    /// `canHandleVariableCommunicationStepSize`.
    pub can_handle_variable_communication_step_size: bool,
    /// `canInterpolateInputs`.
    pub can_interpolate_inputs: bool,
    /// `maxOutputDerivativeOrder`.
    pub max_output_derivative_order: u32,
    /// `canRunAsynchronuously` (sic, as spelled by the standard).
    pub can_run_asynchronuously: bool,
    /// `canBeInstantiatedOnlyOncePerProcess`.
    pub can_be_instantiated_only_once_per_process: bool,
    /// `canNotUseMemoryManagementFunctions`.
    pub can_not_use_memory_management_functions: bool,
    /// `canGetAndSetFMUstate`.
    pub can_get_and_set_fmu_state: bool,
    /// `canSerializeFMUstate`.
    pub can_serialize_fmu_state: bool,
    /// `providesDirectionalDerivative`.
    pub provides_directional_derivative: bool,
}

/// A `Unit` of `UnitDefinitions`.
#[derive(Debug, Clone, PartialEq)]
pub struct Unit {
    /// Unit name, e.g. "N.m".
    pub name: String,
    /// The SI decomposition, if given.
    pub base_unit: Option<BaseUnit>,
    /// Display units derived from this unit.
    pub display_units: Vec<DisplayUnit>,
}

/// `BaseUnit`: value_SI = factor·value + offset, unit = kg^kg·m^m·…
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[allow(non_snake_case)] // field names are the SI symbols used by the standard
pub struct BaseUnit {
    /// Exponent of kilogram.
    pub kg: i32,
    /// Exponent of metre.
    pub m: i32,
    /// Exponent of second.
    pub s: i32,
    /// Exponent of ampere.
    pub A: i32,
    /// Exponent of kelvin.
    pub K: i32,
    /// Exponent of mole.
    pub mol: i32,
    /// Exponent of candela.
    pub cd: i32,
    /// Exponent of radian.
    pub rad: i32,
    /// Factor (default 1).
    pub factor: f64,
    /// Offset (default 0).
    pub offset: f64,
}

/// `DisplayUnit`: value_display = factor·value + offset.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayUnit {
    /// Display unit name.
    pub name: String,
    /// Factor (default 1).
    pub factor: f64,
    /// Offset (default 0).
    pub offset: f64,
}

/// A `SimpleType` of `TypeDefinitions`.
#[derive(Debug, Clone, PartialEq)]
pub struct SimpleType {
    /// Type name, referenced by `declaredType`.
    pub name: String,
    /// `description`.
    pub description: Option<String>,
    /// The type element and its attributes.
    pub kind: SimpleTypeKind,
}

/// The type element of a `SimpleType`.
#[derive(Debug, Clone, PartialEq)]
pub enum SimpleTypeKind {
    /// `Real`.
    Real(RealType),
    /// `Integer`.
    Integer(IntegerType),
    /// `Boolean`.
    Boolean,
    /// `String`.
    String,
    /// `Enumeration` with its items.
    Enumeration {
        /// `quantity`.
        quantity: Option<String>,
        /// The `Item` children.
        items: Vec<EnumerationItem>,
    },
}

/// Attributes shared by `Real` type definitions and `Real` variables.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RealType {
    /// `quantity`.
    pub quantity: Option<String>,
    /// `unit`.
    pub unit: Option<String>,
    /// `displayUnit`.
    pub display_unit: Option<String>,
    /// `relativeQuantity`.
    pub relative_quantity: bool,
    /// `min`.
    pub min: Option<f64>,
    /// `max`.
    pub max: Option<f64>,
    /// `nominal`.
    pub nominal: Option<f64>,
    /// `unbounded`.
    pub unbounded: bool,
}

/// Attributes shared by `Integer` (and `Enumeration`) definitions and variables.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IntegerType {
    /// `quantity`.
    pub quantity: Option<String>,
    /// `min`.
    pub min: Option<i32>,
    /// `max`.
    pub max: Option<i32>,
}

/// An `Item` of an enumeration type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EnumerationItem {
    /// Item name.
    pub name: String,
    /// Item value.
    pub value: i32,
    /// `description`.
    pub description: Option<String>,
}

/// A `Category` of `LogCategories`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogCategory {
    /// Category name, passed to `fmi2SetDebugLogging`.
    pub name: String,
    /// `description`.
    pub description: Option<String>,
}

/// `DefaultExperiment`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DefaultExperiment {
    /// `startTime`.
    pub start_time: Option<f64>,
    /// `stopTime`.
    pub stop_time: Option<f64>,
    /// `tolerance`.
    pub tolerance: Option<f64>,
    /// `stepSize`.
    pub step_size: Option<f64>,
}

/// `causality`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Causality {
    /// `parameter`.
    Parameter,
    /// `calculatedParameter`.
    CalculatedParameter,
    /// `input`.
    Input,
    /// `output`.
    Output,
    /// `local` (the default).
    #[default]
    Local,
    /// `independent`.
    Independent,
}

/// `variability`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Variability {
    /// `constant`.
    Constant,
    /// `fixed`.
    Fixed,
    /// `tunable`.
    Tunable,
    /// `discrete`.
    Discrete,
    /// `continuous` (the default for Real variables).
    #[default]
    Continuous,
}

/// `initial`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Initial {
    /// `exact`: the start value is used.
    Exact,
    /// `approx`: the start value is an iteration guess.
    Approx,
    /// `calculated`: computed by the FMU from other variables.
    Calculated,
}

/// One `ScalarVariable`.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarVariable {
    /// `name`.
    pub name: String,
    /// `valueReference`.
    pub value_reference: ValueReference,
    /// `description`.
    pub description: Option<String>,
    /// `causality` (default local).
    pub causality: Causality,
    /// `variability` (default continuous for Real, discrete otherwise).
    pub variability: Variability,
    /// `initial`, with the standard's default applied; `None` where the standard forbids
    /// it (inputs, independent variable).
    pub initial: Option<Initial>,
    /// `canHandleMultipleSetPerTimeInstant` (meaningful for inputs only).
    pub can_handle_multiple_set_per_time_instant: Option<bool>,
    /// The type element with its attributes.
    pub kind: VariableKind,
    /// 1-based line in modelDescription.xml.
    pub line: usize,
}

/// The type element of a `ScalarVariable`, with `declaredType` attributes inherited.
#[derive(Debug, Clone, PartialEq)]
pub enum VariableKind {
    /// `Real`.
    Real(RealVariable),
    /// `Integer`.
    Integer(IntegerVariable),
    /// `Boolean`.
    Boolean(BooleanVariable),
    /// `String`.
    String(StringVariable),
    /// `Enumeration`.
    Enumeration(IntegerVariable),
}

/// The base type of a variable, as the get/set functions see it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BaseType {
    /// `fmi2Real`.
    Real,
    /// `fmi2Integer` (also used for enumerations).
    Integer,
    /// `fmi2Boolean`.
    Boolean,
    /// `fmi2String`.
    String,
    /// Enumeration (accessed with the Integer functions).
    Enumeration,
}

/// A `Real` type element of a variable.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RealVariable {
    /// `declaredType`.
    pub declared_type: Option<String>,
    /// Attributes, inherited from the declared type where absent.
    pub attributes: RealType,
    /// `start`.
    pub start: Option<f64>,
    /// `derivative`: 1-based index of the variable this one is the derivative of.
    pub derivative: Option<usize>,
    /// `reinit`.
    pub reinit: bool,
}

/// An `Integer` or `Enumeration` type element of a variable.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IntegerVariable {
    /// `declaredType` (required for enumerations).
    pub declared_type: Option<String>,
    /// Attributes, inherited from the declared type where absent.
    pub attributes: IntegerType,
    /// `start`.
    pub start: Option<i32>,
}

/// A `Boolean` type element of a variable.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct BooleanVariable {
    /// `declaredType`.
    pub declared_type: Option<String>,
    /// `start`.
    pub start: Option<bool>,
}

/// A `String` type element of a variable.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct StringVariable {
    /// `declaredType`.
    pub declared_type: Option<String>,
    /// `start`.
    pub start: Option<String>,
}

impl ScalarVariable {
    /// The variable's base type.
    pub fn base_type(&self) -> BaseType {
        match self.kind {
            VariableKind::Real(_) => BaseType::Real,
            VariableKind::Integer(_) => BaseType::Integer,
            VariableKind::Boolean(_) => BaseType::Boolean,
            VariableKind::String(_) => BaseType::String,
            VariableKind::Enumeration(_) => BaseType::Enumeration,
        }
    }

    /// The `Real` attributes, if this is a Real variable.
    pub fn real(&self) -> Option<&RealVariable> {
        match &self.kind {
            VariableKind::Real(r) => Some(r),
            _ => None,
        }
    }
}

/// `dependenciesKind` entries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DependencyKind {
    /// `dependent`.
    Dependent,
    /// `constant`.
    Constant,
    /// `fixed`.
    Fixed,
    /// `tunable`.
    Tunable,
    /// `discrete`.
    Discrete,
}

/// An `Unknown` of `ModelStructure`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unknown {
    /// 1-based index into `ModelVariables`.
    pub index: usize,
    /// `dependencies` (1-based indices); `None` means "depends on all knowns".
    pub dependencies: Option<Vec<usize>>,
    /// `dependenciesKind`, one per dependency, if given.
    pub dependencies_kind: Option<Vec<DependencyKind>>,
}

/// `ModelStructure`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModelStructure {
    /// `Outputs`.
    pub outputs: Vec<Unknown>,
    /// `Derivatives`.
    pub derivatives: Vec<Unknown>,
    /// `InitialUnknowns`.
    pub initial_unknowns: Vec<Unknown>,
}
