//! Parallel perturbed runs (`[coupling] parallel`) compute exactly what the
//! sequential path computes: every recorded value bit for bit, on the planar
//! mechanisms, a 3D joint and the oscillator pair, for several methods.

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
            assert_eq!(seq.times.len(), par.times.len(), "{file}, {method}");
            let mut compared = 0;
            for (k, (a, b)) in seq.rows.iter().zip(&par.rows).enumerate() {
                for (c, (x, y)) in a.iter().zip(b).enumerate() {
                    assert_eq!(
                        x.to_bits(),
                        y.to_bits(),
                        "{file}, {method}, step {k}, {}: sequential {x:e}, parallel {y:e}",
                        seq.columns[c]
                    );
                    compared += 1;
                }
            }
            // The same runs were made, some of them on the copies.
            let steps = |s: &RunStats| s.instances.iter().map(|c| c.do_steps).sum::<u64>();
            assert_eq!(steps(&seq_stats), steps(&par_stats), "{file}, {method}");
            eprintln!(
                "{file}, {method}: {compared} values identical; {} doStep calls",
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
