//! The steady-state macro-step loop does not allocate: every method on the
//! paper's oscillator pair, with CSV recording, counted by a global allocator.
//!
//! Only the master's allocations are counted: the FMUs are separate shared
//! libraries with their own allocator (and the C API hands them no Rust heap).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use tether_master::{CsvRecorder, Observer, Simulation, SystemSpec};

/// Counts allocations (and reallocations) made by the current thread, so the
/// test harness's other threads do not disturb the count.
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting
// touches only a thread-local `Cell` (const-initialised, no allocation).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
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

/// The oscillator pair of examples/oscillator.toml with `method` and order `k`.
fn system(method: &str, order: usize, pairs: usize) -> SystemSpec {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    pairs_of(&fmu, method, order, pairs)
}

/// `pairs` oscillator pairs of the oscillator FMU at `fmu`.
fn pairs_of(fmu: &std::path::Path, method: &str, order: usize, pairs: usize) -> SystemSpec {
    let mut text = format!(
        r#"
        [experiment]
        stop = 0.1
        step = 1e-3

        [method]
        {method}

        [coupling]
        order = {order}
        "#
    );
    for p in 0..pairs {
        text += &format!(
            r#"
            [[instance]]
            name = "mass1_{p}"
            fmu = "{fmu}"
            parameters = {{ m = 1.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}

            [[instance]]
            name = "mass2_{p}"
            fmu = "{fmu}"
            parameters = {{ m = 2.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}

            [[constraint]]
            name = "link_{p}"
            position = "mass2_{p}.x - mass1_{p}.x"
            velocity = "mass2_{p}.v - mass1_{p}.v"
            acceleration = "mass2_{p}.a - mass1_{p}.a"
            drives = "mass1_{p}.F - mass2_{p}.F"
            "#,
            fmu = fmu.display()
        );
    }
    SystemSpec::from_toml(&text).expect("valid system")
}

/// Allocations during macro steps 10..=100, with a CSV recorder attached and
/// the phases timed or not.
fn steady_state_allocations(spec: &SystemSpec, timed: bool) -> u64 {
    let mut sim = Simulation::new(spec).expect("simulation");
    sim.time_phases(timed);
    allocations_after_warm_up(&mut sim, &mut CsvRecorder::new(std::io::sink()))
}

/// Allocations on this thread from macro step 10 to the end of the run.
fn allocations_after_warm_up(sim: &mut Simulation, observer: &mut dyn Observer) -> u64 {
    const WARM_UP: u64 = 10;
    let mut at_warm_up = None;
    let mut at_end = 0;
    sim.run(&mut [observer], &mut |n, total| {
        if n == WARM_UP {
            at_warm_up = Some(allocations());
        }
        if n == total {
            at_end = allocations();
        }
    })
    .expect("run");
    at_end - at_warm_up.expect("ran past the warm-up")
}

#[test]
fn macro_steps_do_not_allocate_for_any_method() {
    let cases = [
        (
            "baumgarte index 1",
            "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6",
            &[0, 1, 2][..],
        ),
        (
            "baumgarte index 2",
            "kind = \"baumgarte\"\nbeta = 2e-3",
            &[0][..],
        ),
        ("baumgarte index 3", "kind = \"baumgarte\"", &[0][..]),
        (
            "weighted index 1",
            "kind = \"weighted\"\na = 1.0\nb = 1.0",
            &[0, 1][..],
        ),
        ("weighted index 2", "kind = \"weighted\"\na = 1.0", &[0][..]),
        ("weighted index 3", "kind = \"weighted\"", &[0][..]),
        ("explicit", "kind = \"explicit\"\nmu = 1e-2", &[0][..]),
    ];
    let mut failures = Vec::new();
    for (name, method, orders) in cases {
        for &k in orders {
            // One pair, and two pairs (a vector of multipliers, a 2 × 2 solve),
            // with and without phase timing.
            for (pairs, timed) in [(1, false), (1, true), (2, false), (2, true)] {
                let n = steady_state_allocations(&system(method, k, pairs), timed);
                eprintln!(
                    "{name}, k = {k}, {pairs} pair(s), phases timed {timed}: {n} allocations in 90 steps"
                );
                if n != 0 {
                    failures.push(format!("{name}, k = {k}, {pairs} pair(s): {n}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "allocations per run: {failures:?}");
}

/// The FMI 3.0 builds take the inputs' polynomial (k > 0) through the
/// intermediate update callback: a new polynomial replaces the last one in
/// place, and the master's side of the callback allocates nothing either.
#[test]
fn fmi3_macro_steps_do_not_allocate() {
    let fmu =
        tether_fmu_build::workspace_fmu3("oscillator").expect("package the FMI 3.0 oscillator");
    let method = "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6";
    for k in [0, 1, 2] {
        let n = steady_state_allocations(&pairs_of(&fmu, method, k, 1), false);
        assert_eq!(n, 0, "FMI 3.0 builds, k = {k}: {n} allocations in 90 steps");
    }
}

/// With the CSV written from a writer thread (`CsvRecorder::background`, what
/// `tether run` uses), the master's thread allocates nothing either, over
/// 3000 steps: its blocks of rows go to the writer and come back several
/// times (~900 rows a block for this width).
#[test]
fn background_csv_recording_does_not_allocate() {
    let mut spec = system("kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6", 1, 1);
    spec.experiment.stop = 3.0;
    let mut sim = Simulation::new(&spec).expect("simulation");
    let n = allocations_after_warm_up(&mut sim, &mut CsvRecorder::background(std::io::sink()));
    assert_eq!(n, 0, "{n} allocations in 2990 steps");
}

/// The counter sees allocations at all (so zero above means something).
#[test]
fn the_allocation_counter_sees_allocations() {
    let before = allocations();
    let v: Vec<u64> = std::hint::black_box((0..100).collect());
    assert!(allocations() > before, "{}", v.len());
}

/// Joints (force ports, nonlinear conditions): the double pendulum and the
/// slider-crank examples and one 3D joint, for the predictor/corrector methods
/// and the explicit method.
#[test]
fn joint_macro_steps_do_not_allocate() {
    tether_fmu_build::workspace_fmu("link").expect("package the link FMU");
    tether_fmu_build::workspace_fmu("body3d").expect("package the body3d FMU");
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    let mut failures = Vec::new();
    for file in [
        "double_pendulum.toml",
        "slider_crank.toml",
        "3d_revolute.toml",
    ] {
        let base = SystemSpec::from_file(&root.join("examples").join(file)).expect("example");
        for method in [
            tether_master::Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            tether_master::Method::Weighted { a: 1.0, b: 0.0 },
            tether_master::Method::Explicit { mu: 1e-2 },
        ] {
            let mut spec = base.clone();
            spec.method = method;
            spec.experiment.stop = 0.1;
            let n = steady_state_allocations(&spec, false);
            eprintln!("{file}, {method}: {n} allocations in 90 steps");
            if n != 0 {
                failures.push(format!("{file}, {method}: {n}"));
            }
        }
    }
    assert!(failures.is_empty(), "allocations per run: {failures:?}");
}

/// The sparse path (more than 20 unknowns): a chain of 40 oscillators and a
/// chain of 12 hinged bars (11 hinges: 22 multipliers and 44 force ports),
/// written with array blocks, for the predictor/corrector methods and the
/// explicit method.
#[test]
fn sparse_macro_steps_do_not_allocate() {
    let oscillator = tether_fmu_build::workspace_fmu("oscillator").expect("oscillator FMU");
    let link = tether_fmu_build::workspace_fmu("link").expect("link FMU");
    let oscillators = format!(
        r#"
        [experiment]
        stop = 0.1
        step = 1e-3
        [[instance]]
        name = "mass{{i}}"
        count = 40
        fmu = "{}"
        parameters = {{ m = "{{1.0 + i % 2}}", c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}
        [[constraint]]
        name = "link{{i}}"
        count = 39
        position = "mass{{i + 1}}.x - mass{{i}}.x"
        velocity = "mass{{i + 1}}.v - mass{{i}}.v"
        acceleration = "mass{{i + 1}}.a - mass{{i}}.a"
        drives = "mass{{i}}.F - mass{{i + 1}}.F"
        "#,
        oscillator.display()
    );
    let bars = format!(
        r#"
        [experiment]
        stop = 0.1
        step = 1e-3
        [[instance]]
        name = "bar0"
        fmu = "{fmu}"
        parameters = {{ pinned = true, phi0 = -0.7853981633974483 }}
        [[instance]]
        name = "bar{{i + 1}}"
        count = 11
        fmu = "{fmu}"
        parameters = {{ phi0 = -0.7853981633974483, x0 = "{{0.7071067811865476 * (i + 1)}}", y0 = "{{-0.7071067811865476 * (i + 1)}}" }}
        [[joint]]
        name = "hinge{{i}}"
        count = 11
        kind = "atpoint"
        plane = "xy"
        i = "bar{{i}}.B"
        j = "bar{{i + 1}}.A"
        "#,
        fmu = link.display()
    );
    let mut failures = Vec::new();
    for (name, text) in [("oscillator chain", oscillators), ("bar chain", bars)] {
        let base = SystemSpec::from_toml(&text).expect("valid system");
        for method in [
            tether_master::Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            tether_master::Method::Baumgarte {
                beta: 2e-3,
                gamma: 0.0,
            },
            tether_master::Method::Weighted { a: 1.0, b: 0.0 },
            tether_master::Method::Explicit { mu: 1e-2 },
        ] {
            let mut spec = base.clone();
            spec.method = method;
            let n = steady_state_allocations(&spec, false);
            eprintln!("{name}, {method}: {n} allocations in 90 steps");
            if n != 0 {
                failures.push(format!("{name}, {method}: {n}"));
            }
        }
    }
    assert!(failures.is_empty(), "allocations per run: {failures:?}");
}

/// A model-exchange instance (rk45, the integrator's buffers kept by the
/// instance) steps and rolls back without allocating: the kit's oscillator,
/// and the Reference FMU BouncingBall through its state events (located by
/// bisection) and event iterations.
#[test]
fn model_exchange_steps_do_not_allocate() {
    use tether_fmi::{Fmu, FmuInstance, Integrator, MeInstance, Method};
    let mut fmus = vec![(
        tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU"),
        "oscillator",
    )];
    if let Some(ball) = tether_fmu_build::fixture_fmu("reference-fmus/fmi2/BouncingBall.fmu") {
        fmus.push((ball, "BouncingBall"));
    }
    for (path, name) in fmus {
        let fmu = Fmu::open(&path).expect("open");
        let integrator = Integrator {
            method: Method::Rk45,
            rtol: Some(1e-10),
            ..Integrator::default()
        };
        let mut me = MeInstance::new(&fmu, name, Default::default(), integrator).expect(name);
        me.setup(None, 0.0, Some(10.0)).unwrap();
        me.enter_initialization().unwrap();
        me.exit_initialization().unwrap();
        let h = 1e-3;
        // Each step is saved, made, restored and made again (a rollback).
        let step = |me: &mut MeInstance, n: u32| {
            let t = f64::from(n) * h;
            me.save(0).unwrap();
            me.step(t, h).unwrap();
            me.restore(0).unwrap();
            me.step(t, h).unwrap();
        };
        for n in 0..10 {
            step(&mut me, n);
        }
        let before = allocations();
        for n in 10..3000 {
            step(&mut me, n);
        }
        let n = allocations() - before;
        let (events, _) = me.events();
        eprintln!("{name}: {n} allocations in 2990 steps ({events} events)");
        assert_eq!(n, 0, "{name}: {n} allocations in 2990 steps");
        if name == "BouncingBall" {
            assert!(events >= 2, "the ball bounced {events} times");
        }
    }
}
