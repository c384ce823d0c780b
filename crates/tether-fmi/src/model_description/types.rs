//! Plain data types mirroring the `modelDescription.xml` schema (co-simulation relevant
//! parts), with the standard's defaults already applied.
//!
//! One set of types serves FMI 2.0 and FMI 3.0. An FMI 3.0 description is mapped onto
//! the FMI 2.0 shapes callers already use (a `Float64` or `Float32` variable is a
//! [`VariableKind::Real`], an integer type of any width an [`VariableKind::Integer`],
//! `structuralParameter` a [`Causality::Parameter`] with
//! [`ScalarVariable::structural_parameter`] set, value references in `derivative` and
//! `ModelStructure` turned into 1-based indices), and what FMI 2.0 has no place for is
//! added beside them: [`ScalarVariable::value_type`] (the exact type),
//! [`ScalarVariable::dimensions`], [`ScalarVariable::start_values`] and the FMI 3.0
//! capability flags of [`CoSimulation`] and [`ModelExchange`].

/// An FMI value reference.
pub type ValueReference = u32;

/// The parsed `fmiModelDescription` element.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelDescription {
    /// `fmiVersion` (starts with "2." or "3.").
    pub fmi_version: String,
    /// The standard the description follows (from `fmiVersion`).
    pub standard: FmiStandard,
    /// `modelName`.
    pub model_name: String,
    /// `guid` (FMI 2.0) or `instantiationToken` (FMI 3.0), passed to
    /// `fmi2Instantiate` / `fmi3InstantiateCoSimulation`.
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
    /// The `CoSimulation` element, if the FMU has one ([`cs`](Self::cs) reads
    /// its flags as all false when it has not).
    pub co_simulation: Option<CoSimulation>,
    /// The `ModelExchange` element, if the FMU has one.
    pub model_exchange: Option<ModelExchange>,
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
    /// What the file does that FMI does not allow and Tether works around,
    /// in file order (`Fmu::open` reports them, one line per kind).
    pub quirks: Vec<Quirk>,
    pub(crate) by_name: std::collections::HashMap<String, usize>,
}

/// A quirk of a model description: what it declares that FMI does not
/// allow, and what Tether does instead.
#[derive(Debug, Clone, PartialEq)]
pub struct Quirk {
    /// The kind (one line per kind and FMU): `"initial"` for an `initial`
    /// attribute its causality and variability do not allow.
    pub kind: &'static str,
    /// The line in `modelDescription.xml`.
    pub line: usize,
    /// What is wrong and what Tether does, without the file and line.
    pub message: String,
}

/// The FMI standard of a model description.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FmiStandard {
    /// FMI 2.0.
    #[default]
    Fmi2,
    /// FMI 3.0.
    Fmi3,
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
#[derive(Debug, Clone, PartialEq, Default)]
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
    /// `providesDirectionalDerivative` (FMI 3.0: `providesDirectionalDerivatives`).
    pub provides_directional_derivative: bool,
    /// FMI 3.0 `providesAdjointDerivatives`.
    pub provides_adjoint_derivatives: bool,
    /// FMI 3.0 `providesPerElementDependencies`.
    pub provides_per_element_dependencies: bool,
    /// FMI 3.0 `fixedInternalStepSize`.
    pub fixed_internal_step_size: Option<f64>,
    /// FMI 3.0 `recommendedIntermediateInputSmoothness` (default 0).
    pub recommended_intermediate_input_smoothness: i32,
    /// FMI 3.0 `providesIntermediateUpdate`.
    pub provides_intermediate_update: bool,
    /// FMI 3.0 `mightReturnEarlyFromDoStep`.
    pub might_return_early_from_do_step: bool,
    /// FMI 3.0 `canReturnEarlyAfterIntermediateUpdate`.
    pub can_return_early_after_intermediate_update: bool,
    /// FMI 3.0 `hasEventMode`.
    pub has_event_mode: bool,
    /// FMI 3.0 `providesEvaluateDiscreteStates`.
    pub provides_evaluate_discrete_states: bool,
}

/// The `ModelExchange` element's capability flags, with the numbers of
/// continuous states and event indicators the model description declares.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ModelExchange {
    /// Name of the shared library (without extension) and prefix of the functions.
    pub model_identifier: String,
    /// `needsExecutionTool`.
    pub needs_execution_tool: bool,
    /// FMI 2.0 `completedIntegratorStepNotNeeded`; for FMI 3.0 the negation of
    /// `needsCompletedIntegratorStep`.
    pub completed_integrator_step_not_needed: bool,
    /// FMI 3.0 `needsCompletedIntegratorStep` (FMI 2.0: the negation of
    /// `completedIntegratorStepNotNeeded`).
    pub needs_completed_integrator_step: bool,
    /// `canBeInstantiatedOnlyOncePerProcess`.
    pub can_be_instantiated_only_once_per_process: bool,
    /// `canNotUseMemoryManagementFunctions` (FMI 2.0).
    pub can_not_use_memory_management_functions: bool,
    /// `canGetAndSetFMUstate` (FMI 3.0: `canGetAndSetFMUState`).
    pub can_get_and_set_fmu_state: bool,
    /// `canSerializeFMUstate` (FMI 3.0: `canSerializeFMUState`).
    pub can_serialize_fmu_state: bool,
    /// `providesDirectionalDerivative` (FMI 3.0: `providesDirectionalDerivatives`).
    pub provides_directional_derivative: bool,
    /// FMI 3.0 `providesAdjointDerivatives`.
    pub provides_adjoint_derivatives: bool,
    /// FMI 3.0 `providesEvaluateDiscreteStates`.
    pub provides_evaluate_discrete_states: bool,
    /// The number of continuous states: the `Derivatives` (FMI 3.0
    /// `ContinuousStateDerivative`s) of `ModelStructure`.
    pub number_of_continuous_states: usize,
    /// The number of event indicators: FMI 2.0 `numberOfEventIndicators`
    /// (default 0), FMI 3.0 the `EventIndicator`s of `ModelStructure`.
    pub number_of_event_indicators: usize,
}

/// The flags of a model description without a `CoSimulation` element: every
/// capability false, no model identifier.
pub(crate) static NO_CO_SIMULATION: CoSimulation = CoSimulation {
    model_identifier: String::new(),
    needs_execution_tool: false,
    can_handle_variable_communication_step_size: false,
    can_interpolate_inputs: false,
    max_output_derivative_order: 0,
    can_run_asynchronuously: false,
    can_be_instantiated_only_once_per_process: false,
    can_not_use_memory_management_functions: false,
    can_get_and_set_fmu_state: false,
    can_serialize_fmu_state: false,
    provides_directional_derivative: false,
    provides_adjoint_derivatives: false,
    provides_per_element_dependencies: false,
    fixed_internal_step_size: None,
    recommended_intermediate_input_smoothness: 0,
    provides_intermediate_update: false,
    might_return_early_from_do_step: false,
    can_return_early_after_intermediate_update: false,
    has_event_mode: false,
    provides_evaluate_discrete_states: false,
};

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
    /// FMI 3.0 `inverse`: value_display = 1/(factor·value + offset).
    pub inverse: bool,
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
    /// The exact type (FMI 3.0 `Int8Type` … ; FMI 2.0 `Real` is `Float64`, `Integer` is
    /// `Int32`).
    pub value_type: ValueType,
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
    /// FMI 3.0 `BinaryType`.
    Binary,
    /// FMI 3.0 `ClockType`.
    Clock,
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
    /// The type element with its attributes (for FMI 3.0, the FMI 2.0 view: see
    /// the module documentation).
    pub kind: VariableKind,
    /// The exact type: FMI 3.0's element name; for FMI 2.0 `Real` is `Float64` and
    /// `Integer` is `Int32`.
    pub value_type: ValueType,
    /// FMI 3.0 `<Dimension>`s, outermost first; empty for a scalar.
    pub dimensions: Vec<Dimension>,
    /// FMI 3.0 `causality="structuralParameter"` (then `causality` is `Parameter`).
    pub structural_parameter: bool,
    /// FMI 3.0 `intermediateUpdate`.
    pub intermediate_update: bool,
    /// FMI 3.0 `previous` (a value reference).
    pub previous: Option<ValueReference>,
    /// FMI 3.0 `clocks` (value references of the clocks the variable belongs to).
    pub clocks: Vec<ValueReference>,
    /// FMI 3.0: every start value, row-major for an array (`None` without a start
    /// value, and always for FMI 2.0, whose start values are in `kind`).
    pub start_values: Option<Values>,
    /// 1-based line in modelDescription.xml.
    pub line: usize,
}

/// The exact type of a variable, as FMI 3.0 names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ValueType {
    /// `Float32`.
    Float32,
    /// `Float64` (FMI 2.0 `Real`).
    Float64,
    /// `Int8`.
    Int8,
    /// `UInt8`.
    UInt8,
    /// `Int16`.
    Int16,
    /// `UInt16`.
    UInt16,
    /// `Int32` (FMI 2.0 `Integer`).
    Int32,
    /// `UInt32`.
    UInt32,
    /// `Int64`.
    Int64,
    /// `UInt64`.
    UInt64,
    /// `Boolean`.
    Boolean,
    /// `String`.
    String,
    /// `Binary`.
    Binary,
    /// `Enumeration` (FMI 3.0: accessed as `Int64`).
    Enumeration,
    /// `Clock`.
    Clock,
}

impl ValueType {
    /// The element name in an FMI 3.0 model description.
    pub fn name(self) -> &'static str {
        match self {
            ValueType::Float32 => "Float32",
            ValueType::Float64 => "Float64",
            ValueType::Int8 => "Int8",
            ValueType::UInt8 => "UInt8",
            ValueType::Int16 => "Int16",
            ValueType::UInt16 => "UInt16",
            ValueType::Int32 => "Int32",
            ValueType::UInt32 => "UInt32",
            ValueType::Int64 => "Int64",
            ValueType::UInt64 => "UInt64",
            ValueType::Boolean => "Boolean",
            ValueType::String => "String",
            ValueType::Binary => "Binary",
            ValueType::Enumeration => "Enumeration",
            ValueType::Clock => "Clock",
        }
    }

    /// The type of the element called `name`, if it is a variable element of FMI 3.0.
    pub fn from_name(name: &str) -> Option<ValueType> {
        Some(match name {
            "Float32" => ValueType::Float32,
            "Float64" => ValueType::Float64,
            "Int8" => ValueType::Int8,
            "UInt8" => ValueType::UInt8,
            "Int16" => ValueType::Int16,
            "UInt16" => ValueType::UInt16,
            "Int32" => ValueType::Int32,
            "UInt32" => ValueType::UInt32,
            "Int64" => ValueType::Int64,
            "UInt64" => ValueType::UInt64,
            "Boolean" => ValueType::Boolean,
            "String" => ValueType::String,
            "Binary" => ValueType::Binary,
            "Enumeration" => ValueType::Enumeration,
            "Clock" => ValueType::Clock,
            _ => return None,
        })
    }

    /// Whether this is one of the eight integer types.
    pub fn is_integer(self) -> bool {
        matches!(
            self,
            ValueType::Int8
                | ValueType::UInt8
                | ValueType::Int16
                | ValueType::UInt16
                | ValueType::Int32
                | ValueType::UInt32
                | ValueType::Int64
                | ValueType::UInt64
        )
    }
}

/// One FMI 3.0 `<Dimension>` of an array variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Dimension {
    /// `start`: a fixed size.
    Fixed(u64),
    /// `valueReference`: the size is the value of this structural parameter.
    Parameter(ValueReference),
}

/// Values of one variable (FMI 3.0 start values), row-major for an array.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// `Float32`/`Float64`.
    Float(Vec<f64>),
    /// `Int8` … `Int64` and `Enumeration`.
    Int(Vec<i64>),
    /// `UInt8` … `UInt64`.
    UInt(Vec<u64>),
    /// `Boolean`.
    Boolean(Vec<bool>),
    /// `String`.
    String(Vec<String>),
    /// `Binary`.
    Binary(Vec<Vec<u8>>),
}

impl Values {
    /// The number of values.
    pub fn len(&self) -> usize {
        match self {
            Values::Float(v) => v.len(),
            Values::Int(v) => v.len(),
            Values::UInt(v) => v.len(),
            Values::Boolean(v) => v.len(),
            Values::String(v) => v.len(),
            Values::Binary(v) => v.len(),
        }
    }

    /// Whether there is no value.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
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

    /// Whether the variable is an FMI 3.0 array.
    pub fn is_array(&self) -> bool {
        !self.dimensions.is_empty()
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
    /// FMI 3.0 `ClockedState`s.
    pub clocked_states: Vec<Unknown>,
    /// FMI 3.0 `EventIndicator`s.
    pub event_indicators: Vec<Unknown>,
}
