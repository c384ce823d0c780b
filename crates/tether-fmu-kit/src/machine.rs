//! The FMI 2.0 co-simulation state machine (FMI 2.0 §4.2.4) as one table: for every
//! call, the set of states in which it is allowed. Checked at the top of every
//! function, as in modelica/Reference-FMUs.

/// States of a co-simulation slave. `StepInProgress` is absent: the kit never runs
/// asynchronously (`canRunAsynchronuously="false"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum MachineState {
    Instantiated = 0,
    InitializationMode = 1,
    StepComplete = 2,
    StepFailed = 3,
    StepCanceled = 4,
    Terminated = 5,
    Error = 6,
    Fatal = 7,
}

impl MachineState {
    const ALL: [MachineState; 8] = [
        MachineState::Instantiated,
        MachineState::InitializationMode,
        MachineState::StepComplete,
        MachineState::StepFailed,
        MachineState::StepCanceled,
        MachineState::Terminated,
        MachineState::Error,
        MachineState::Fatal,
    ];

    const fn bit(self) -> u16 {
        1 << self as u8
    }

    pub fn from_u8(value: u8) -> Option<Self> {
        Self::ALL.get(usize::from(value)).copied()
    }
}

/// Every function of the FMI 2.0 co-simulation interface that takes an instance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Call {
    SetDebugLogging,
    FreeInstance,
    SetupExperiment,
    EnterInitializationMode,
    ExitInitializationMode,
    Terminate,
    Reset,
    GetReal,
    GetInteger,
    GetBoolean,
    GetString,
    SetReal,
    SetInteger,
    SetBoolean,
    SetString,
    GetFMUstate,
    SetFMUstate,
    FreeFMUstate,
    SerializedFMUstateSize,
    SerializeFMUstate,
    DeSerializeFMUstate,
    GetDirectionalDerivative,
    SetRealInputDerivatives,
    GetRealOutputDerivatives,
    DoStep,
    CancelStep,
    GetStatus,
    GetRealStatus,
    GetIntegerStatus,
    GetBooleanStatus,
    GetStringStatus,
    /// An FMI 3.0 function the kit does not support (named): refused with an error.
    Unsupported(&'static str),
    /// A model-exchange function (named) that reads the instance:
    /// fmi2GetDerivatives, fmi2GetContinuousStates, … Model exchange has no
    /// states of its own in the table: its event and continuous-time modes are
    /// both `StepComplete` (the kit's models have no events).
    MeGet(&'static str),
    /// A model-exchange function (named) that sets the time or the states or
    /// changes the mode: only after initialization (`StepComplete`).
    MeSet(&'static str),
    /// A model-exchange function (named) that answers from the declaration
    /// (fmi3GetNumberOfContinuousStates, …): in any state but Fatal.
    MeInfo(&'static str),
}

use MachineState::*;

const fn mask(states: &[MachineState]) -> u16 {
    let mut m = 0;
    let mut i = 0;
    while i < states.len() {
        m |= states[i].bit();
        i += 1;
    }
    m
}

const ANY: u16 = mask(&MachineState::ALL);
const NOT_FATAL: u16 = ANY & !Fatal.bit();
const SETTABLE: u16 = mask(&[Instantiated, InitializationMode, StepComplete]);
const GETTABLE: u16 = mask(&[
    InitializationMode,
    StepComplete,
    StepFailed,
    StepCanceled,
    Terminated,
    Error,
]);
const AFTER_STEP: u16 = mask(&[StepComplete, StepFailed, StepCanceled, Terminated, Error]);
const STATUS: u16 = mask(&[StepComplete, StepFailed, StepCanceled, Terminated]);

impl Call {
    /// The FMI function name, for log messages.
    pub fn name(self) -> &'static str {
        match self {
            Call::SetDebugLogging => "fmi2SetDebugLogging",
            Call::FreeInstance => "fmi2FreeInstance",
            Call::SetupExperiment => "fmi2SetupExperiment",
            Call::EnterInitializationMode => "fmi2EnterInitializationMode",
            Call::ExitInitializationMode => "fmi2ExitInitializationMode",
            Call::Terminate => "fmi2Terminate",
            Call::Reset => "fmi2Reset",
            Call::GetReal => "fmi2GetReal",
            Call::GetInteger => "fmi2GetInteger",
            Call::GetBoolean => "fmi2GetBoolean",
            Call::GetString => "fmi2GetString",
            Call::SetReal => "fmi2SetReal",
            Call::SetInteger => "fmi2SetInteger",
            Call::SetBoolean => "fmi2SetBoolean",
            Call::SetString => "fmi2SetString",
            Call::GetFMUstate => "fmi2GetFMUstate",
            Call::SetFMUstate => "fmi2SetFMUstate",
            Call::FreeFMUstate => "fmi2FreeFMUstate",
            Call::SerializedFMUstateSize => "fmi2SerializedFMUstateSize",
            Call::SerializeFMUstate => "fmi2SerializeFMUstate",
            Call::DeSerializeFMUstate => "fmi2DeSerializeFMUstate",
            Call::GetDirectionalDerivative => "fmi2GetDirectionalDerivative",
            Call::SetRealInputDerivatives => "fmi2SetRealInputDerivatives",
            Call::GetRealOutputDerivatives => "fmi2GetRealOutputDerivatives",
            Call::DoStep => "fmi2DoStep",
            Call::CancelStep => "fmi2CancelStep",
            Call::GetStatus => "fmi2GetStatus",
            Call::GetRealStatus => "fmi2GetRealStatus",
            Call::GetIntegerStatus => "fmi2GetIntegerStatus",
            Call::GetBooleanStatus => "fmi2GetBooleanStatus",
            Call::GetStringStatus => "fmi2GetStringStatus",
            Call::Unsupported(name)
            | Call::MeGet(name)
            | Call::MeSet(name)
            | Call::MeInfo(name) => name,
        }
    }

    /// The FMI 3.0 function a call of the FMI 3.0 layer ([`crate::ffi::fmi3`]) came
    /// through, for log messages (`fmi2SetupExperiment` has none: its arguments come
    /// with `fmi3EnterInitializationMode`).
    pub fn fmi3_name(self) -> &'static str {
        match self {
            Call::SetDebugLogging => "fmi3SetDebugLogging",
            Call::FreeInstance => "fmi3FreeInstance",
            Call::SetupExperiment | Call::EnterInitializationMode => "fmi3EnterInitializationMode",
            Call::ExitInitializationMode => "fmi3ExitInitializationMode",
            Call::Terminate => "fmi3Terminate",
            Call::Reset => "fmi3Reset",
            Call::GetReal => "fmi3GetFloat64",
            Call::GetInteger => "fmi3GetInt32",
            Call::GetBoolean => "fmi3GetBoolean",
            Call::GetString => "fmi3GetString",
            Call::SetReal => "fmi3SetFloat64",
            Call::SetInteger => "fmi3SetInt32",
            Call::SetBoolean => "fmi3SetBoolean",
            Call::SetString => "fmi3SetString",
            Call::GetFMUstate => "fmi3GetFMUState",
            Call::SetFMUstate => "fmi3SetFMUState",
            Call::FreeFMUstate => "fmi3FreeFMUState",
            Call::SerializedFMUstateSize => "fmi3SerializedFMUStateSize",
            Call::SerializeFMUstate => "fmi3SerializeFMUState",
            Call::DeSerializeFMUstate => "fmi3DeserializeFMUState",
            Call::GetDirectionalDerivative => "fmi3GetDirectionalDerivative",
            Call::GetRealOutputDerivatives => "fmi3GetOutputDerivatives",
            Call::DoStep => "fmi3DoStep",
            Call::SetRealInputDerivatives
            | Call::CancelStep
            | Call::GetStatus
            | Call::GetRealStatus
            | Call::GetIntegerStatus
            | Call::GetBooleanStatus
            | Call::GetStringStatus => self.name(),
            Call::Unsupported(name)
            | Call::MeGet(name)
            | Call::MeSet(name)
            | Call::MeInfo(name) => name,
        }
    }

    /// The table: the states in which this call is allowed.
    const fn allowed_mask(self) -> u16 {
        match self {
            // Freeing is always possible, even after fmi2Fatal: nothing the kit holds
            // is corrupted by a model failure, and refusing would only leak.
            Call::FreeInstance => ANY,
            Call::SetDebugLogging | Call::Reset => NOT_FATAL,
            Call::SetupExperiment | Call::EnterInitializationMode => Instantiated.bit(),
            Call::ExitInitializationMode => InitializationMode.bit(),
            Call::Terminate => mask(&[StepComplete, StepFailed, StepCanceled]),
            Call::GetReal | Call::GetInteger | Call::GetBoolean | Call::GetString => GETTABLE,
            Call::SetReal | Call::SetInteger | Call::SetBoolean | Call::SetString => SETTABLE,
            Call::GetFMUstate
            | Call::SetFMUstate
            | Call::FreeFMUstate
            | Call::SerializedFMUstateSize
            | Call::SerializeFMUstate
            | Call::DeSerializeFMUstate => NOT_FATAL,
            Call::GetDirectionalDerivative => GETTABLE,
            Call::SetRealInputDerivatives => SETTABLE,
            Call::GetRealOutputDerivatives => AFTER_STEP,
            Call::DoStep => StepComplete.bit(),
            // Only in StepInProgress, which this kit never enters.
            Call::CancelStep => 0,
            Call::GetStatus
            | Call::GetRealStatus
            | Call::GetIntegerStatus
            | Call::GetBooleanStatus
            | Call::GetStringStatus => STATUS,
            Call::Unsupported(_) | Call::MeInfo(_) => NOT_FATAL,
            Call::MeGet(_) => GETTABLE,
            Call::MeSet(_) => StepComplete.bit(),
        }
    }

    #[inline]
    pub fn allowed_in(self, state: MachineState) -> bool {
        self.allowed_mask() & state.bit() != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn do_step_is_allowed_only_after_initialization() {
        assert!(Call::DoStep.allowed_in(StepComplete));
        for s in [
            Instantiated,
            InitializationMode,
            StepFailed,
            StepCanceled,
            Terminated,
            Error,
            Fatal,
        ] {
            assert!(!Call::DoStep.allowed_in(s), "{s:?}");
        }
    }

    #[test]
    fn parameters_and_inputs_are_settable_until_terminate() {
        for s in [Instantiated, InitializationMode, StepComplete] {
            assert!(Call::SetReal.allowed_in(s));
            assert!(Call::SetRealInputDerivatives.allowed_in(s));
        }
        for s in [StepFailed, Terminated, Error, Fatal] {
            assert!(!Call::SetReal.allowed_in(s));
        }
    }

    #[test]
    fn values_are_not_readable_before_initialization_mode() {
        assert!(!Call::GetReal.allowed_in(Instantiated));
        assert!(Call::GetReal.allowed_in(InitializationMode));
        assert!(Call::GetReal.allowed_in(Error));
        assert!(!Call::GetReal.allowed_in(Fatal));
        assert!(!Call::GetRealOutputDerivatives.allowed_in(InitializationMode));
    }

    #[test]
    fn fatal_allows_only_free_instance() {
        let all = [
            Call::SetDebugLogging,
            Call::SetupExperiment,
            Call::Reset,
            Call::GetReal,
            Call::SetReal,
            Call::GetFMUstate,
            Call::SetFMUstate,
            Call::DoStep,
            Call::GetStatus,
        ];
        for call in all {
            assert!(!call.allowed_in(Fatal), "{}", call.name());
        }
        assert!(Call::FreeInstance.allowed_in(Fatal));
    }

    #[test]
    fn machine_state_round_trips_through_u8() {
        for s in MachineState::ALL {
            assert_eq!(MachineState::from_u8(s as u8), Some(s));
        }
        assert_eq!(MachineState::from_u8(8), None);
    }
}
