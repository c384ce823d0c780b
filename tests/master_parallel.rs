//! Parallel runs (`[coupling] parallel`, `threads`) compute exactly what the
//! sequential path computes: every recorded value bit for bit, on the planar
//! mechanisms, 3D joints and the oscillator pair for several methods, on
//! systems of signals only (Jacobi, Gauss–Seidel, iterated), with adaptive
//! steps, the explicit method, and every thread count.

use std::time::Duration;

use tether_master::{
    MemoryRecorder, Method, Parallel, RunStats, Simulation, StartValue, SystemSpec,
};

fn example(name: &str) -> SystemSpec {
    for fmu in ["link", "body3d", "oscillator"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the FMU");
    }
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    SystemSpec::from_file(&root.join("examples").join(name)).expect("read the example")
}

fn run(spec: &SystemSpec, parallel: Parallel) -> (MemoryRecorder, RunStats) {
    let mut spec = spec.clone();
    spec.coupling.parallel = parallel;
    let mut sim = Simulation::new(&spec).expect("simulation");
    let mut rec = MemoryRecorder::default();
    let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).expect("run");
    (rec, stats)
}

#[test]
fn parallel_runs_are_bit_identical_to_sequential() {
    let methods = [
        (
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            0,
        ),
        (
            Method::Baumgarte {
                beta: 1e-3,
                gamma: 0.0,
            },
            0,
        ),
        (Method::Weighted { a: 1.0, b: 1.0 }, 1),
    ];
    let cases = [
        ("double_pendulum.toml", 0.3),
        ("slider_crank.toml", 0.3),
        ("3d_revolute.toml", 0.2),
        ("3d_universal.toml", 0.2),
        ("oscillator.toml", 0.3),
    ];
    for (file, stop) in cases {
        for (method, order) in methods {
            let mut spec = example(file);
            spec.method = method;
            spec.experiment.stop = stop;
            spec.coupling.order = order;
            let (seq, seq_stats) = run(&spec, Parallel::Off);
            let (par, par_stats) = run(&spec, Parallel::On);
            assert_eq!(seq_stats.parallel.workers, 0);
            assert!(par_stats.parallel.workers >= 1, "{file}: no worker used");
            assert_identical(&seq, &par, &format!("{file}, {method}"));
            // The same runs were made, some of them on a worker.
            let steps = |s: &RunStats| s.instances.iter().map(|c| c.do_steps).sum::<u64>();
            assert_eq!(steps(&seq_stats), steps(&par_stats), "{file}, {method}");
            eprintln!(
                "{file}, {method}: {} values identical; {} doStep calls",
                seq.rows.len() * seq.columns.len(),
                steps(&par_stats)
            );
        }
    }
}

/// "auto" times the FMU steps of the first macro steps. When even a hand-off
/// far cheaper than any real one (`HANDOFF_FLOOR`, 2 µs) could not pay, as for
/// the exact oscillators, it stays sequential without starting a worker or
/// timing a hand-off, and computes what "off" computes. An expensive FMU gets
/// its workers started and its hand-off timed. The times themselves are the
/// bench's (`cargo bench -p tether-bench -- parallel` prints auto's hand-off and
/// predicted runs for both systems).
#[test]
fn auto_starts_workers_only_when_the_steps_could_pay() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut cheap = example("oscillator.toml");
    for instance in &mut cheap.instances {
        instance
            .parameters
            .insert("exact".into(), StartValue::Boolean(true));
    }
    cheap.experiment.stop = 0.05;
    let (off, _) = run(&cheap, Parallel::Off);
    let (auto, stats) = run(&cheap, Parallel::Auto);
    let p = stats.parallel;
    assert_eq!(p.workers, 0, "{p:?}");
    assert!(p.handoff.is_zero(), "a hand-off was timed: {p:?}");
    if cores >= 2 {
        assert!(
            p.sequential > Duration::ZERO,
            "the first steps' runs were not measured: {p:?}"
        );
    }
    assert_eq!(off.rows.len(), auto.rows.len());
    for (k, (a, b)) in off.rows.iter().zip(&auto.rows).enumerate() {
        for (c, (x, y)) in a.iter().zip(b).enumerate() {
            assert_eq!(x.to_bits(), y.to_bits(), "step {k}, {}", off.columns[c]);
        }
    }

    // The body integrated as if with a fixed-rate solver: ~400 µs a step.
    let mut expensive = example("3d_revolute.toml");
    for instance in &mut expensive.instances {
        instance
            .parameters
            .insert("max_step".into(), StartValue::Real(1e-5));
    }
    expensive.experiment.stop = 8.0 * expensive.experiment.step;
    let (_, stats) = run(&expensive, Parallel::Auto);
    let p = stats.parallel;
    if cores >= 2 {
        assert!(p.handoff > Duration::ZERO, "no hand-off timed: {p:?}");
        assert!(
            p.sequential > Duration::ZERO,
            "the runs were not measured: {p:?}"
        );
    } else {
        assert_eq!(p, Default::default(), "one core: no pool at all");
    }
}

#[test]
fn the_setting_is_read_and_checked() {
    let spec = SystemSpec::from_toml(
        "[experiment]\nstop = 1\nstep = 0.1\n[coupling]\nparallel = \"on\"\n\
         [[instance]]\nname = \"a\"\nfmu = \"a.fmu\"\n",
    )
    .expect("valid");
    assert_eq!(spec.coupling.parallel, Parallel::On);
    let err = SystemSpec::from_toml(
        "[experiment]\nstop = 1\nstep = 0.1\n[coupling]\nparallel = \"sometimes\"\n\
         [[instance]]\nname = \"a\"\nfmu = \"a.fmu\"\n",
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("parallel") || err.contains("sometimes"),
        "{err}"
    );
}

/// Every recorded value of `b` is `a`'s, bit for bit.
fn assert_identical(a: &MemoryRecorder, b: &MemoryRecorder, case: &str) {
    assert_eq!(a.times.len(), b.times.len(), "{case}");
    assert_eq!(a.columns, b.columns, "{case}");
    for (k, (x, y)) in a.rows.iter().zip(&b.rows).enumerate() {
        for (c, (x, y)) in x.iter().zip(y).enumerate() {
            assert_eq!(
                x.to_bits(),
                y.to_bits(),
                "{case}, step {k}, {}: off {x:e}, parallel {y:e}",
                a.columns[c]
            );
        }
    }
}

/// `n` body3d instances (each `fmi2DoStep` with Dop853 steps of at most
/// 1e-4 s) coupled by signals: body k's torque input from the energy of the
/// body two places before it, scaled (Gauss–Seidel's stages are then pairs:
/// b0 and b1, b2 and b3, …).
fn body_ring(n: usize, scheme: &str, extra: &str) -> SystemSpec {
    tether_fmu_build::workspace_fmu("body3d").expect("package the FMU");
    let fmu = tether_fmu_build::workspace_root()
        .expect("workspace root")
        .join("target/fmus/body3d.fmu");
    let mut text = format!(
        "[experiment]\nstop = 0.02\nstep = 1e-3\n[signals]\nscheme = \"{scheme}\"\n{extra}\n"
    );
    for k in 0..n {
        text += &format!(
            "[[instance]]\nname = \"b{k}\"\nfmu = {:?}\n\
             parameters = {{ max_step = 1e-4, \"v0[1]\" = {}, \"w0[3]\" = {} }}\n",
            fmu.display().to_string(),
            0.1 * k as f64,
            0.3 + 0.1 * k as f64
        );
    }
    for k in 0..n {
        text += &format!(
            "[[connection]]\nfrom = \"b{}.E\"\nto = \"b{k}.A.T[1]\"\ngain = 0.01\n",
            (k + n - 2) % n
        );
    }
    SystemSpec::from_toml(&text).expect("a valid system")
}

fn run_with(
    spec: &SystemSpec,
    parallel: Parallel,
    threads: Option<usize>,
) -> (MemoryRecorder, RunStats) {
    let mut spec = spec.clone();
    spec.coupling.threads = threads;
    run(&spec, parallel)
}

/// Signal systems: the Jacobi steps of all instances, Gauss–Seidel's stages
/// and the repetitions of iterated steps go to the workers, and compute what
/// "off" computes, with 2, 3 and 4 threads and "auto".
#[test]
fn signal_systems_run_in_parallel_bit_for_bit() {
    for (scheme, extra) in [
        ("jacobi", ""),
        ("gauss_seidel", ""),
        ("jacobi", "iterations = 3"),
    ] {
        let spec = body_ring(4, scheme, extra);
        let (off, _) = run_with(&spec, Parallel::Off, None);
        for threads in [2, 3, 4] {
            let (on, stats) = run_with(&spec, Parallel::On, Some(threads));
            assert_eq!(stats.parallel.workers, threads - 1, "{scheme} {extra}");
            assert_identical(&off, &on, &format!("{scheme} {extra}, {threads} threads"));
        }
        let (auto, _) = run_with(&spec, Parallel::Auto, None);
        assert_identical(&off, &auto, &format!("{scheme} {extra}, auto"));
    }
}

/// Adaptive steps (rejected steps rolled back) and the explicit method on
/// 3d_revolute: the same values with the runs on a worker.
#[test]
fn adaptive_steps_and_the_explicit_method_run_in_parallel_bit_for_bit() {
    let mut adaptive = example("3d_revolute.toml");
    adaptive.experiment.stop = 0.2;
    adaptive.step_control = Some(
        SystemSpec::from_toml(
            "[experiment]\nstop = 1\nstep = 1e-3\n[step_control]\nrtol = 1e-6\natol = 1e-8\n\
             [[instance]]\nname = \"a\"\nfmu = \"a.fmu\"\n",
        )
        .expect("valid")
        .step_control
        .expect("step control"),
    );
    let mut explicit = example("3d_revolute.toml");
    explicit.experiment.stop = 0.2;
    explicit.method = Method::Explicit { mu: 1e-2 };
    for (name, spec) in [("adaptive", adaptive), ("explicit", explicit)] {
        let (off, _) = run_with(&spec, Parallel::Off, None);
        let (on, stats) = run_with(&spec, Parallel::On, Some(2));
        assert_eq!(stats.parallel.workers, 1, "{name}");
        assert_identical(&off, &on, name);
    }
}

/// `parallel = false` on an `[[instance]]` keeps its runs on the main
/// thread: with both instances marked, no worker is started even with
/// `parallel = "on"`; with one marked, the other goes to the one worker.
#[test]
fn an_instance_marked_parallel_false_stays_on_the_main_thread() {
    let mut spec = example("3d_revolute.toml");
    spec.experiment.stop = 0.05;
    let (off, _) = run_with(&spec, Parallel::Off, None);
    spec.instances[0].parallel = Some(false);
    let (one, stats) = run_with(&spec, Parallel::On, Some(4));
    assert_eq!(
        stats.parallel.workers, 1,
        "one instance may leave: one worker"
    );
    assert_identical(&off, &one, "body1 on the main thread");
    spec.instances[1].parallel = Some(false);
    let (none, stats) = run_with(&spec, Parallel::On, Some(4));
    assert_eq!(stats.parallel.workers, 0, "every instance stays");
    assert_identical(&off, &none, "both on the main thread");
}
