//! The controller through the kit's C functions: what it declares, the calls
//! it refuses, and its integral against the closed form.

use std::ffi::CString;
use std::ptr;

use controller::Controller;
use tether_fmu_kit::ffi::{self, Fmi2CallbackFunctions, Fmi2Component, Fmi2FmuState};
use tether_fmu_kit::Model;

type M = Controller;
const OK: i32 = 0;
const ERROR: i32 = 3;
// Value references: kp 0, ki 1, r 2, tolerance 3, y 4, u 5.
const Y: u32 = 4;
const U: u32 = 5;

fn instance() -> Fmi2Component {
    let name = CString::new("ctrl").unwrap();
    let guid = CString::new(tether_fmu_kit::xml::guid(&M::DECLARATION)).unwrap();
    let callbacks = Fmi2CallbackFunctions {
        logger: None,
        allocate_memory: None,
        free_memory: None,
        step_finished: None,
        component_environment: ptr::null_mut(),
    };
    // SAFETY: valid NUL-terminated strings and callbacks; the kit copies what it keeps.
    let c = unsafe { ffi::instantiate::<M>(name.as_ptr(), 1, guid.as_ptr(), &callbacks, 0) };
    assert!(!c.is_null());
    // SAFETY: c is a live instance of M.
    unsafe {
        assert_eq!(ffi::setup_experiment::<M>(c, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(ffi::enter_initialization_mode::<M>(c), OK);
        assert_eq!(ffi::exit_initialization_mode::<M>(c), OK);
    }
    c
}

#[test]
fn declares_no_fmu_states_and_no_input_interpolation() {
    let xml = tether_fmu_kit::xml::model_description(&M::DECLARATION).unwrap();
    assert!(xml.contains(r#"canInterpolateInputs="false""#), "{xml}");
    assert!(xml.contains(r#"canGetAndSetFMUstate="false" canSerializeFMUstate="false""#));
    assert!(xml.contains(r#"<ScalarVariable name="y" valueReference="4""#));
    assert!(xml.contains(r#"<ScalarVariable name="u" valueReference="5""#));
}

#[test]
fn refuses_fmu_states_and_input_derivatives() {
    let c = instance();
    let mut state: Fmi2FmuState = ptr::null_mut();
    // SAFETY: c is a live instance of M; the arrays outlive the calls.
    unsafe {
        assert_eq!(ffi::get_fmu_state::<M>(c, &mut state), ERROR);
        assert!(state.is_null());
        let status =
            ffi::set_real_input_derivatives::<M>(c, [Y].as_ptr(), 1, [1].as_ptr(), [1.0].as_ptr());
        assert_eq!(status, ERROR);
        ffi::free_instance::<M>(c);
    }
}

/// u = kp (r − y) + ki z with z the integral of r − y: with y held at 0.04
/// for 10 steps of 0.01, z = 0.1·(0.1 − 0.04) = 0.006.
#[test]
fn the_integral_is_exact_for_a_held_input() {
    let c = instance();
    let mut u = [0.0];
    // SAFETY: c is a live instance of M; the arrays outlive the calls.
    unsafe {
        assert_eq!(ffi::set_real::<M>(c, [Y].as_ptr(), 1, [0.04].as_ptr()), OK);
        for n in 0..10 {
            assert_eq!(ffi::do_step::<M>(c, n as f64 * 0.01, 0.01, 1), OK);
        }
        assert_eq!(ffi::get_real::<M>(c, [U].as_ptr(), 1, u.as_mut_ptr()), OK);
        ffi::free_instance::<M>(c);
    }
    let expected = 1000.0 * (0.1 - 0.04) + 10000.0 * 0.006;
    assert!((u[0] - expected).abs() < 1e-9, "{} vs {expected}", u[0]);
}
