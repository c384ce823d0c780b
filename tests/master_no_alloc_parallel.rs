//! With parallel runs the steady-state macro step still allocates
//! nothing, on the main thread or the worker threads: counted by a global
//! allocator over all threads (this binary holds a single test so that no other
//! test's allocations mix in).
//!
//! Only the master's allocations are counted: the FMUs are separate shared
//! libraries with their own allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

use tether_master::{CsvRecorder, Method, Parallel, Simulation, SystemSpec};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::SeqCst)
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting
// touches only an atomic.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn parallel_macro_steps_do_not_allocate_on_any_thread() {
    const WARM_UP: u64 = 10;
    for fmu in ["link", "body3d", "oscillator"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the FMU");
    }
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    // The counter sees allocations at all (so zero below means something).
    let before = allocations();
    let v: Vec<u64> = std::hint::black_box((0..100).collect());
    assert!(allocations() > before, "{}", v.len());
    let mut failures = Vec::new();
    for file in [
        "oscillator.toml",
        "double_pendulum.toml",
        "slider_crank.toml",
        "3d_revolute.toml",
    ] {
        for (method, order) in [
            (
                Method::Baumgarte {
                    beta: 2e-3,
                    gamma: 1e-6,
                },
                1,
            ),
            (Method::Weighted { a: 1.0, b: 0.0 }, 0),
        ] {
            let mut spec =
                SystemSpec::from_file(&root.join("examples").join(file)).expect("example");
            spec.method = method;
            spec.coupling.order = order;
            spec.coupling.parallel = Parallel::On;
            spec.experiment.stop = spec.experiment.start + 100.0 * spec.experiment.step;
            let mut sim = Simulation::new(&spec).expect("simulation");
            let mut csv = CsvRecorder::new(std::io::sink());
            let mut at_warm_up = None;
            let mut at_end = 0;
            let stats = sim
                .run(&mut [&mut csv], &mut |n, total| {
                    if n == WARM_UP {
                        at_warm_up = Some(allocations());
                    }
                    if n == total {
                        at_end = allocations();
                    }
                })
                .expect("run");
            assert!(stats.parallel.workers >= 1, "{file}: no worker used");
            let n = at_end - at_warm_up.expect("ran past the warm-up");
            eprintln!("{file}, {method}, k = {order}, parallel: {n} allocations in 90 steps");
            if n != 0 {
                failures.push(format!("{file}, {method}: {n}"));
            }
        }
    }
    assert!(failures.is_empty(), "allocations per run: {failures:?}");
}
