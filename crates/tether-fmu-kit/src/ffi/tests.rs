//! The C layer: null and bad pointers, wrong GUIDs, FMU states and panics, called the
//! way an importer calls them.

use std::ffi::{c_char, CString};
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
