//! The C layer: null and bad pointers, wrong GUIDs, FMU states and panics, called the
//! way an importer calls them.

use std::ffi::{c_char, c_void, CStr, CString};
use std::ptr;

use super::*;
use crate::tests::Decay;
use crate::xml;

type D = Decay;
const OK: Fmi2Status = 0;

fn callbacks() -> Fmi2CallbackFunctions {
    Fmi2CallbackFunctions {
        logger: None,
        allocate_memory: None,
        free_memory: None,
        step_finished: None,
        component_environment: ptr::null_mut(),
    }
}

fn new_instance() -> Fmi2Component {
    let name = CString::new("decay").unwrap();
    let guid = CString::new(xml::guid(&D::DECLARATION)).unwrap();
    let functions = callbacks();
    // SAFETY: valid NUL-terminated strings and a valid callback struct.
    let c = unsafe { instantiate::<D>(name.as_ptr(), 1, guid.as_ptr(), &functions, 0) };
    assert!(!c.is_null());
    c
}

fn initialized() -> Fmi2Component {
    let c = new_instance();
    // SAFETY: c is a live instance of D.
    unsafe {
        assert_eq!(setup_experiment::<D>(c, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(enter_initialization_mode::<D>(c), OK);
        assert_eq!(exit_initialization_mode::<D>(c), OK);
    }
    c
}

#[test]
fn instantiate_refuses_bad_arguments_with_null() {
    let name = CString::new("decay").unwrap();
    let wrong = CString::new("{00000000-0000-0000-0000-000000000000}").unwrap();
    let right = CString::new(xml::guid(&D::DECLARATION)).unwrap();
    let f = callbacks();
    // SAFETY: every non-null pointer is valid.
    unsafe {
        assert!(instantiate::<D>(ptr::null(), 1, right.as_ptr(), &f, 0).is_null());
        assert!(instantiate::<D>(name.as_ptr(), 1, right.as_ptr(), ptr::null(), 0).is_null());
        assert!(instantiate::<D>(name.as_ptr(), 1, wrong.as_ptr(), &f, 0).is_null());
        assert!(instantiate::<D>(name.as_ptr(), 1, ptr::null(), &f, 0).is_null());
        assert!(
            instantiate::<D>(name.as_ptr(), 0, right.as_ptr(), &f, 0).is_null(),
            "model exchange"
        );
    }
}

#[test]
fn null_pointers_return_error_never_crash() {
    let c = initialized();
    let vr = [4u32];
    let mut v = [0.0];
    // SAFETY: c is live; the null pointers are what is tested.
    unsafe {
        assert_eq!(do_step::<D>(ptr::null_mut(), 0.0, 0.1, 0), ERROR);
        assert_eq!(get_real::<D>(c, ptr::null(), 1, v.as_mut_ptr()), ERROR);
        assert_eq!(get_real::<D>(c, vr.as_ptr(), 1, ptr::null_mut()), ERROR);
        assert_eq!(
            get_real::<D>(c, ptr::null(), 0, ptr::null_mut()),
            OK,
            "nothing requested"
        );
        assert_eq!(
            set_real_input_derivatives::<D>(c, vr.as_ptr(), 1, ptr::null(), v.as_ptr()),
            ERROR
        );
        assert_eq!(get_fmu_state::<D>(c, ptr::null_mut()), ERROR);
        assert_eq!(set_fmu_state::<D>(c, ptr::null_mut()), ERROR);
        assert_eq!(get_real_status::<D>(c, 2, ptr::null_mut()), ERROR);
        assert_eq!(set_debug_logging::<D>(c, 1, 1, ptr::null()), ERROR);
        assert_eq!(get_directional_derivative::<D>(c), ERROR);
        assert_eq!(
            get_real::<D>(c, vr.as_ptr(), 1, v.as_mut_ptr()),
            OK,
            "still usable"
        );
        free_instance::<D>(c);
        free_instance::<D>(ptr::null_mut());
    }
}

#[test]
fn fmu_states_are_updated_in_place_and_serialized() {
    let c = initialized();
    let z = [5u32];
    let mut state: Fmi2FmuState = ptr::null_mut();
    let (mut x1, mut x2) = ([0.0], [0.0]);
    // SAFETY: c is live; state pointers come from this library.
    unsafe {
        assert_eq!(get_fmu_state::<D>(c, &mut state), OK);
        let first = state;
        assert_eq!(do_step::<D>(c, 0.0, 0.5, 0), OK);
        assert_eq!(get_real::<D>(c, z.as_ptr(), 1, x1.as_mut_ptr()), OK);
        assert_eq!(get_fmu_state::<D>(c, &mut state), OK);
        assert_eq!(state, first, "a non-null state is updated in place");
        let mut size = 0;
        assert_eq!(serialized_fmu_state_size::<D>(c, state, &mut size), OK);
        let mut bytes = vec![0 as c_char; size];
        assert_eq!(
            serialize_fmu_state::<D>(c, state, bytes.as_mut_ptr(), size - 1),
            ERROR
        );
        assert_eq!(
            serialize_fmu_state::<D>(c, state, bytes.as_mut_ptr(), size),
            OK
        );
        assert_eq!(do_step::<D>(c, 0.5, 0.5, 0), OK);
        let mut restored: Fmi2FmuState = ptr::null_mut();
        assert_eq!(
            deserialize_fmu_state::<D>(c, bytes.as_ptr(), size, &mut restored),
            OK
        );
        assert_eq!(
            deserialize_fmu_state::<D>(c, bytes.as_ptr(), size - 1, &mut restored),
            ERROR
        );
        let mut garbage = bytes.clone();
        garbage[0] = 0;
        assert_eq!(
            deserialize_fmu_state::<D>(c, garbage.as_ptr(), size, &mut restored),
            ERROR
        );
        assert_eq!(set_fmu_state::<D>(c, restored), OK);
        assert_eq!(get_real::<D>(c, z.as_ptr(), 1, x2.as_mut_ptr()), OK);
        assert_eq!(x1, x2);
        let mut t = 0.0;
        assert_eq!(get_real_status::<D>(c, 2, &mut t), OK);
        assert_eq!(t, 0.5);
        assert_eq!(free_fmu_state::<D>(c, &mut state), OK);
        assert!(state.is_null());
        assert_eq!(free_fmu_state::<D>(c, &mut restored), OK);
        assert_eq!(
            free_fmu_state::<D>(c, &mut restored),
            OK,
            "freeing null is a no-op"
        );
        free_instance::<D>(c);
    }
}

#[test]
fn a_panicking_model_returns_fatal_and_the_instance_stays_fatal() {
    let c = new_instance();
    let k = [0u32];
    // SAFETY: c is live.
    unsafe {
        assert_eq!(set_real::<D>(c, k.as_ptr(), 1, [123.0].as_ptr()), OK);
        assert_eq!(enter_initialization_mode::<D>(c), OK);
        assert_eq!(exit_initialization_mode::<D>(c), OK);
        assert_eq!(do_step::<D>(c, 0.0, 0.1, 0), Status::Fatal as Fmi2Status);
        assert_eq!(
            do_step::<D>(c, 0.0, 0.1, 0),
            ERROR,
            "nothing but fmi2FreeInstance after fatal"
        );
        assert_eq!(reset::<D>(c), ERROR);
        free_instance::<D>(c);
    }
}

/// What [`environment_logger`] gave inside the last `fmi2DoStep` of [`Probe`]:
/// the component environment and the instance name.
type Seen = Option<(usize, String)>;

std::thread_local! {
    static SEEN: std::cell::RefCell<Option<Seen>> = const { std::cell::RefCell::new(None) };
}

/// Decay, recording the logger hook from inside `fmi2DoStep`; `LOGS` as the
/// model declares it.
struct Probe<const LOGS: bool>(Decay);

impl<const L: bool> Model for Probe<L> {
    const DECLARATION: crate::Declaration = Decay::DECLARATION;
    const LOGS: bool = L;
    fn new(p: &crate::Parameters) -> Result<Self, String> {
        Decay::new(p).map(Probe)
    }
    fn initial_states(&self, x: &mut [f64]) {
        self.0.initial_states(x)
    }
    fn derivatives(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.0.derivatives(t, x, u, dx)
    }
    fn outputs(&self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        self.0.outputs(t, x, u, y)
    }
    fn exact_step(&self, _t: f64, _h: f64, _x: &mut [f64], _u: &[crate::InputJet]) -> bool {
        let seen = environment_logger().map(|l| {
            // SAFETY: the hook's name is NUL-terminated and alive during the call.
            let name = unsafe { CStr::from_ptr(l.instance_name) };
            (
                l.component_environment as usize,
                name.to_string_lossy().into_owned(),
            )
        });
        SEEN.set(Some(seen));
        false
    }
}

/// Stands in for a logger: only its address is handed around, it is never called
/// (stable Rust cannot define a C-variadic function).
extern "C" fn never_called() {
    unreachable!("the test never logs");
}

/// Runs one `fmi2DoStep` of a [`Probe`] named `probe` instantiated with
/// `functions`; what the model saw of the logger hook.
fn seen_by_the_model<const LOGS: bool>(functions: &Fmi2CallbackFunctions) -> Seen {
    let name = CString::new("probe").unwrap();
    let guid = CString::new(xml::guid(&Probe::<LOGS>::DECLARATION)).unwrap();
    SEEN.set(None);
    // SAFETY: valid NUL-terminated strings and a valid callback struct whose
    // logger is never called; c is used while live.
    unsafe {
        let c = instantiate::<Probe<LOGS>>(name.as_ptr(), 1, guid.as_ptr(), functions, 0);
        assert!(!c.is_null());
        assert_eq!(enter_initialization_mode::<Probe<LOGS>>(c), OK);
        assert_eq!(exit_initialization_mode::<Probe<LOGS>>(c), OK);
        assert_eq!(do_step::<Probe<LOGS>>(c, 0.0, 0.1, 0), OK);
        free_instance::<Probe<LOGS>>(c);
    }
    SEEN.take().expect("fmi2DoStep reached the model")
}

/// A model that declares `LOGS` reaches its instance's logger through the hook
/// during a call, and only then; one that does not never sees it.
#[test]
fn the_model_reaches_the_environments_logger_during_a_call() {
    assert!(environment_logger().is_none(), "outside any call");
    let mut environment = 0u8;
    let mut functions = callbacks();
    // SAFETY: only the pointer's type changes; the function is never called.
    functions.logger = Some(unsafe {
        std::mem::transmute::<
            extern "C" fn(),
            unsafe extern "C" fn(*mut c_void, Fmi2String, Fmi2Status, Fmi2String, Fmi2String, ...),
        >(never_called)
    });
    functions.component_environment = (&raw mut environment).cast();
    assert_eq!(
        seen_by_the_model::<true>(&functions),
        Some((&raw mut environment as usize, "probe".to_string()))
    );
    assert!(environment_logger().is_none(), "the call ended");
    assert_eq!(
        seen_by_the_model::<true>(&callbacks()),
        None,
        "no logger given"
    );
    assert_eq!(
        seen_by_the_model::<false>(&functions),
        None,
        "the model does not declare LOGS"
    );
}

/// The test model with model exchange declared (value references as `Decay`'s:
/// k 0, x0 1, tolerance 2, u 3, y 4, z 5, x 6, der(x) 7).
struct DecayMe(Decay);

impl Model for DecayMe {
    const DECLARATION: crate::declaration::Declaration = crate::declaration::Declaration {
        model_exchange: true,
        ..Decay::DECLARATION
    };
    fn new(p: &crate::declaration::Parameters) -> Result<Self, String> {
        Decay::new(p).map(DecayMe)
    }
    fn initial_states(&self, x: &mut [f64]) {
        self.0.initial_states(x);
    }
    fn derivatives(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.0.derivatives(t, x, u, dx);
    }
    fn outputs(&self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        self.0.outputs(t, x, u, y);
    }
    fn terminate(&self, _t: f64, x: &[f64]) -> bool {
        x[0] > 100.0
    }
}

fn me_instance(fmu_type: c_int) -> Fmi2Component {
    let name = CString::new("decay").unwrap();
    let guid = CString::new(xml::guid(&DecayMe::DECLARATION)).unwrap();
    let functions = callbacks();
    // SAFETY: valid NUL-terminated strings and a valid callback struct.
    unsafe { instantiate::<DecayMe>(name.as_ptr(), fmu_type, guid.as_ptr(), &functions, 0) }
}

#[test]
fn model_exchange_evaluates_the_model_at_the_importers_time_and_states() {
    type E = DecayMe;
    let c = me_instance(0);
    assert!(!c.is_null());
    let (mut x, mut dx, mut y) = ([0.0], [0.0], [0.0; 2]);
    let (mut enter, mut end) = (7, 7);
    let mut info = me::Fmi2EventInfo {
        new_discrete_states_needed: 7,
        terminate_simulation: 7,
        nominals_of_continuous_states_changed: 7,
        values_of_continuous_states_changed: 7,
        next_event_time_defined: 7,
        next_event_time: 7.0,
    };
    // SAFETY: c is a live instance of E; every array holds the count given.
    unsafe {
        assert_eq!(me::set_time::<E>(c, 0.5), ERROR, "before initialization");
        assert_eq!(setup_experiment::<E>(c, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(enter_initialization_mode::<E>(c), OK);
        assert_eq!(me::get_continuous_states::<E>(c, x.as_mut_ptr(), 1), OK);
        assert_eq!(x, [1.0], "x0");
        assert_eq!(exit_initialization_mode::<E>(c), OK);
        assert_eq!(me::new_discrete_states::<E>(c, &mut info), OK);
        assert_eq!(
            (info.new_discrete_states_needed, info.terminate_simulation),
            (0, 0)
        );
        assert_eq!(info.next_event_time_defined, 0);
        assert_eq!(me::change_mode::<E>(c, "fmi2EnterContinuousTimeMode"), OK);
        assert_eq!(set_real::<E>(c, [3].as_ptr(), 1, [2.0].as_ptr()), OK);
        assert_eq!(me::set_time::<E>(c, 0.5), OK);
        assert_eq!(me::set_continuous_states::<E>(c, [3.0].as_ptr(), 1), OK);
        assert_eq!(me::get_derivatives::<E>(c, dx.as_mut_ptr(), 1), OK);
        assert_eq!(dx, [2.0 - 3.0], "u - k x");
        assert_eq!(get_real::<E>(c, [4, 5].as_ptr(), 2, y.as_mut_ptr()), OK);
        assert_eq!(y, [3.0 + 2.0, 3.0], "y = x + u, z = x");
        assert_eq!(get_real::<E>(c, [7].as_ptr(), 1, dx.as_mut_ptr()), OK);
        assert_eq!(dx, [-1.0], "der(x) through fmi2GetReal");
        assert_eq!(me::get_continuous_states::<E>(c, x.as_mut_ptr(), 1), OK);
        assert_eq!(x, [3.0]);
        assert_eq!(me::get_nominals::<E>(c, x.as_mut_ptr(), 1), OK);
        assert_eq!(x, [1.0]);
        assert_eq!(
            me::completed_integrator_step::<E, Fmi2Boolean>(c, &mut enter, &mut end),
            OK
        );
        assert_eq!((enter, end), (0, 0));
        assert_eq!(me::get_event_indicators::<E>(c, ptr::null_mut(), 0), OK);
        assert_eq!(me::get_event_indicators::<E>(c, x.as_mut_ptr(), 1), ERROR);
        assert_eq!(me::get_derivatives::<E>(c, dx.as_mut_ptr(), 2), ERROR);
        assert_eq!(me::set_continuous_states::<E>(c, ptr::null(), 1), ERROR);
        assert_eq!(do_step::<E>(c, 0.5, 0.1, 0), ERROR, "no steps in ME");
        // The model asks to end the simulation above x = 100.
        assert_eq!(me::set_continuous_states::<E>(c, [101.0].as_ptr(), 1), OK);
        assert_eq!(
            me::completed_integrator_step::<E, Fmi2Boolean>(c, &mut enter, &mut end),
            OK
        );
        assert_eq!((enter, end), (0, 1));
        assert_eq!(terminate::<E>(c), OK);
        free_instance::<E>(c);
    }
}

#[test]
fn model_exchange_needs_the_declaration_and_a_model_exchange_instance() {
    let name = CString::new("decay").unwrap();
    let guid = CString::new(xml::guid(&D::DECLARATION)).unwrap();
    assert!(me_instance(2).is_null(), "neither ME nor CS");
    let c = me_instance(1);
    assert!(!c.is_null());
    // SAFETY: c is a live co-simulation instance of DecayMe; the strings are valid.
    unsafe {
        assert_eq!(setup_experiment::<DecayMe>(c, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(enter_initialization_mode::<DecayMe>(c), OK);
        assert_eq!(exit_initialization_mode::<DecayMe>(c), OK);
        assert_eq!(me::set_time::<DecayMe>(c, 0.5), ERROR, "CS instance");
        assert_eq!(do_step::<DecayMe>(c, 0.0, 0.1, 0), OK);
        free_instance::<DecayMe>(c);
        let none = fmi3::instantiate_model_exchange::<D>(
            name.as_ptr(),
            guid.as_ptr(),
            0,
            ptr::null_mut(),
            None,
        );
        assert!(none.is_null(), "co-simulation only");
        let me_guid = CString::new(xml::guid(&DecayMe::DECLARATION)).unwrap();
        let c3 = fmi3::instantiate_model_exchange::<DecayMe>(
            name.as_ptr(),
            me_guid.as_ptr(),
            0,
            ptr::null_mut(),
            None,
        );
        assert!(!c3.is_null());
        let mut n = 9;
        assert_eq!(me::get_number::<DecayMe>(c3, "n", &mut n, 1), OK);
        assert_eq!(n, 1);
        free_instance::<DecayMe>(c3);
    }
    let cs2 = xml::model_description(&D::DECLARATION).unwrap();
    let cs3 = xml::model_description_fmi3(&D::DECLARATION).unwrap();
    let me2 = xml::model_description(&DecayMe::DECLARATION).unwrap();
    let me3 = xml::model_description_fmi3(&DecayMe::DECLARATION).unwrap();
    assert!(!cs2.contains("<ModelExchange") && !cs3.contains("<ModelExchange"));
    assert!(!cs3.contains("ContinuousStateDerivative"));
    assert!(me2.contains(r#"<ModelExchange modelIdentifier="decay""#));
    assert!(me2.contains(r#"completedIntegratorStepNotNeeded="true""#));
    assert!(me3.contains(r#"needsCompletedIntegratorStep="false""#));
    assert!(me3.contains(r#"<ContinuousStateDerivative valueReference="7"/>"#));
}
