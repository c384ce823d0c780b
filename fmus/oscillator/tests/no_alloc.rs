//! The FMU side of an allocation-free macro step: the oscillator in `exact` mode,
//! driven through the kit's C functions with the call sequence of Tether's
//! predictor/corrector step (state save, predictor, perturbed run, restore,
//! corrector, output reads), allocates nothing once running.
//!
//! This is what makes the C floor of `cargo bench -p tether-bench -- floor` a floor:
//! an FMU that allocates on every call (as the kit used to on state copies, value
//! access and step logging) costs more than the master around it. In Dop853 mode the
//! integrator (ode_solvers) allocates its own work vectors on every step; that is
//! not counted here.

use std::alloc::{GlobalAlloc, Layout, System};
use std::ffi::CString;
use std::ptr;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use oscillator::Oscillator;
use tether_fmu_kit::ffi::{self, Fmi2CallbackFunctions, Fmi2Component, Fmi2FmuState};
use tether_fmu_kit::Model;

struct Counting;

static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every request unchanged to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: the caller's layout is passed on unchanged.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: ptr was allocated by System with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: as in alloc/dealloc.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

type M = Oscillator;
const OK: i32 = 0;
// Value references: exact 6, F 7, F_ext 8, x 9, v 10, a 11.
const EXACT: u32 = 6;
const F: u32 = 7;
const OUTPUTS: [u32; 3] = [9, 10, 11];

fn instance(name: &str) -> Fmi2Component {
    let name = CString::new(name).unwrap();
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
    // SAFETY: c is a live instance of M; the arrays outlive the calls.
    unsafe {
        assert_eq!(
            ffi::set_boolean::<M>(c, [EXACT].as_ptr(), 1, [1].as_ptr()),
            OK
        );
        assert_eq!(ffi::setup_experiment::<M>(c, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(ffi::enter_initialization_mode::<M>(c), OK);
        assert_eq!(ffi::exit_initialization_mode::<M>(c), OK);
    }
    c
}

/// One macro step of the predictor/corrector pattern on one instance, with the input
/// polynomial of degree 1; returns the accepted outputs.
fn macro_step(c: Fmi2Component, state: &mut Fmi2FmuState, t: f64, h: f64, f: f64) -> [f64; 3] {
    let mut y = [0.0; 3];
    let order = [1];
    // SAFETY: c is a live instance of M, *state null or one of its states; every
    // array outlives its call and has the length passed.
    unsafe {
        assert_eq!(ffi::get_fmu_state::<M>(c, state), OK);
        for (input, slope) in [(f, 0.5), (f + 1e-6, 0.5), (f + 2e-3, 0.25)] {
            assert_eq!(ffi::set_fmu_state::<M>(c, *state), OK);
            assert_eq!(ffi::set_real::<M>(c, [F].as_ptr(), 1, [input].as_ptr()), OK);
            assert_eq!(
                ffi::set_real_input_derivatives::<M>(
                    c,
                    [F].as_ptr(),
                    1,
                    order.as_ptr(),
                    [slope].as_ptr()
                ),
                OK
            );
            assert_eq!(ffi::do_step::<M>(c, t, h, 1), OK);
            assert_eq!(
                ffi::get_real::<M>(c, OUTPUTS.as_ptr(), 3, y.as_mut_ptr()),
                OK
            );
        }
    }
    y
}

#[test]
fn the_steady_state_macro_step_allocates_nothing_in_the_fmu() {
    let c = instance("osc");
    let mut state: Fmi2FmuState = ptr::null_mut();
    let h = 1e-3;
    let mut y = [0.0; 3];
    for n in 0..10 {
        y = macro_step(c, &mut state, n as f64 * h, h, -y[0]);
    }
    COUNTING.store(true, Ordering::SeqCst);
    for n in 10..100 {
        y = macro_step(c, &mut state, n as f64 * h, h, -y[0]);
    }
    COUNTING.store(false, Ordering::SeqCst);
    let allocations = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(y.iter().all(|v| v.is_finite()) && y[0] != 0.0, "{y:?}");
    // SAFETY: state and c are live and of this library; each is freed once.
    unsafe {
        assert_eq!(ffi::free_fmu_state::<M>(c, &mut state), OK);
        ffi::free_instance::<M>(c);
    }
    assert_eq!(
        allocations, 0,
        "90 macro steps (1440 FMI calls of the steady-state kinds) allocated {allocations} times"
    );
}
