//! The paper's planar mechanisms (EXAMPLES.md §2–3) from the examples, for the
//! tests that run them (tests/joints_planar.rs, tests/adaptive_steps.rs).

use tether_master::{MasterError, MemoryRecorder, Method, RunStats, Simulation, SystemSpec};

use crate::reference::slider_crank;

/// The example file with the link FMU packaged where it points.
pub fn example(name: &str) -> SystemSpec {
    tether_fmu_build::workspace_fmu("link").expect("package the link FMU");
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    SystemSpec::from_file(&root.join("examples").join(name)).expect("read the example")
}

pub fn run(spec: &SystemSpec) -> Result<MemoryRecorder, MasterError> {
    let mut sim = Simulation::new(spec)?;
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {})?;
    Ok(rec)
}

/// Run `spec` with adaptive steps at rtol = atol = `tol` to its end: the
/// results and the run's statistics.
pub fn run_adaptive(mut spec: SystemSpec, tol: f64) -> (MemoryRecorder, RunStats) {
    spec.step_control = Some(tether_master::StepControl {
        rtol: tol,
        atol: tol,
        ..Default::default()
    });
    let mut sim = Simulation::new(&spec).unwrap();
    let mut rec = MemoryRecorder::default();
    let stats = sim
        .run(&mut [&mut rec], &mut |_, _| {})
        .expect("the run completes");
    (rec, stats)
}

pub fn with(mut spec: SystemSpec, method: Method, order: usize, h: f64, stop: f64) -> SystemSpec {
    spec.method = method;
    spec.coupling.order = order;
    spec.experiment.step = h;
    spec.experiment.stop = stop;
    spec
}

/// Fitted order from the errors at successive halvings of H (least squares in log-log).
pub fn fitted_order(hs: &[f64], errors: &[f64]) -> f64 {
    let n = hs.len() as f64;
    let (lx, ly): (Vec<f64>, Vec<f64>) =
        hs.iter().zip(errors).map(|(h, e)| (h.ln(), e.ln())).unzip();
    let mx = lx.iter().sum::<f64>() / n;
    let my = ly.iter().sum::<f64>() / n;
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

/// The double pendulum's largest marker-position error (the free ends of
/// both links) against the monolithic reference at the recorded times.
pub fn double_pendulum_error(rec: &MemoryRecorder) -> f64 {
    let reference = crate::reference::double_pendulum::reference(&rec.times);
    max_error(
        rec,
        &[
            "link1.B.r[1]",
            "link1.B.r[2]",
            "link2.B.r[1]",
            "link2.B.r[2]",
        ],
        |k, name| reference[k].column(name).expect("reference column"),
    )
}

/// Max over time of the difference of `columns` from the reference.
pub fn max_error(
    rec: &MemoryRecorder,
    columns: &[&str],
    reference: impl Fn(usize, &str) -> f64,
) -> f64 {
    let mut worst: f64 = 0.0;
    for name in columns {
        let series = rec
            .series(name)
            .unwrap_or_else(|| panic!("no column {name}"));
        for (k, v) in series.iter().enumerate() {
            worst = worst.max((v - reference(k, name)).abs());
        }
    }
    worst
}

pub const BAUMGARTE_INDEX1: Method = Method::Baumgarte {
    beta: 2e-3,
    gamma: 1e-6,
};
pub const WEIGHTED_INDEX1: Method = Method::Weighted { a: 1.0, b: 1.0 };
pub const BAUMGARTE_INDEX2: Method = Method::Baumgarte {
    beta: 2e-3,
    gamma: 0.0,
};
pub const WEIGHTED_INDEX2: Method = Method::Weighted { a: 1.0, b: 0.0 };

/// One slider-crank run over 2 s (through its dead centres): total
/// `fmi2DoStep` calls and the largest angle error against the reference.
pub fn slider_crank_work(spec: &SystemSpec) -> Option<(u64, f64)> {
    let mut sim = Simulation::new(spec).ok()?;
    let mut rec = MemoryRecorder::default();
    let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).ok()?;
    let calls = stats.instances.iter().map(|c| c.do_steps).sum();
    let reference = slider_crank::reference(&rec.times);
    let error = max_error(&rec, &["crank.phi", "rocker.phi"], |k, name| {
        reference[k].column(name).expect("reference column")
    });
    Some((calls, error))
}
