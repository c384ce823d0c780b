//! Large systems: chains written with array blocks (`count = N`), solved on
//! the dense path (≤ 20 unknowns) and on the sparse path (more), against the
//! closed form of the rigid chain, and the number of perturbed runs per step.
//!
//! A chain of oscillators joined by rigid links moves as one oscillator with
//! the sums of the masses, springs and dampers; the masses alternate 1, 2 so
//! that the links carry forces.

use tether_master::{InitialMultiplier, MemoryRecorder, Simulation, SystemSpec};

const C: f64 = 1000.0;
const D: f64 = 10.0;
const V0: f64 = 100.0;

fn chain(n: usize, method: &str) -> SystemSpec {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let text = format!(
        r#"
        [experiment]
        stop = 0.5
        step = 1e-3

        [method]
        {method}

        [[instance]]
        name = "mass{{i}}"
        count = {n}
        fmu = "{fmu}"
        parameters = {{ m = "{{1.0 + i % 2}}", c = {C:?}, d = {D:?}, x0 = 0.0, v0 = {V0:?}, exact = true }}

        [[constraint]]
        name = "link{{i}}"
        count = {links}
        position = "mass{{i + 1}}.x - mass{{i}}.x"
        velocity = "mass{{i + 1}}.v - mass{{i}}.v"
        acceleration = "mass{{i + 1}}.a - mass{{i}}.a"
        drives = "mass{{i}}.F - mass{{i + 1}}.F"
        "#,
        fmu = fmu.display(),
        links = n - 1
    );
    SystemSpec::from_toml(&text).expect("valid system")
}

/// Largest |x_k − x(t)| over every mass and recorded point.
fn chain_error(n: usize, method: &str) -> (f64, usize) {
    let spec = chain(n, method);
    assert_eq!(spec.instances.len(), n);
    assert_eq!(spec.constraints.len(), n - 1);
    let mut sim = Simulation::new(&spec).expect("simulation");
    let groups = sim.perturbation_groups();
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {}).expect("run");
    let m: f64 = (0..n).map(|i| 1.0 + (i % 2) as f64).sum();
    let (c, d) = (n as f64 * C, n as f64 * D);
    let delta = d / (2.0 * m);
    let wd = (c / m - delta * delta).sqrt();
    let mut error = 0.0_f64;
    for k in 0..n {
        let x = rec.series(&format!("mass{k}.x")).unwrap();
        for (i, &t) in rec.times.iter().enumerate() {
            let exact = (-delta * t).exp() * V0 / wd * (wd * t).sin();
            error = error.max((x[i] - exact).abs());
        }
    }
    (error, groups)
}

#[test]
fn long_chains_on_the_sparse_path_are_as_accurate_as_short_ones_on_the_dense_path() {
    for (name, method) in [
        ("baumgarte index 2", "kind = \"baumgarte\"\nbeta = 2e-3"),
        ("weighted index 1", "kind = \"weighted\"\na = 1.0\nb = 1.0"),
    ] {
        // 7 unknowns (dense) and 79 (sparse).
        let (dense, groups_short) = chain_error(8, method);
        let (sparse, groups_long) = chain_error(80, method);
        eprintln!("{name}: max |x - x_exact| N = 8: {dense:.3e}, N = 80: {sparse:.3e}");
        // About 2× the measured 4.6e-6 (index 2) and 1.0e-5 (index 1); the
        // long chain moves as the short one: the same error to 1 %.
        assert!(dense < 2.5e-5, "{name}: {dense:e}");
        assert!(
            (sparse - dense).abs() <= 0.01 * dense,
            "{name}: {dense:e}, {sparse:e}"
        );
        // Each link drives two neighbours: two perturbed runs per step, at any length.
        assert_eq!((groups_short, groups_long), (2, 2), "{name}");
    }
}

/// A singular interface Jacobian on the sparse path: two links over the
/// same pair of masses (identical rows) stop the run with the condition
/// error, not a wrong result.
#[test]
fn a_singular_long_chain_is_reported() {
    // At setup (consistent initial multipliers) and, with given initial
    // multipliers, at the first macro step.
    for (initial, stage) in [(None, "setup"), (Some(0.0), "first step")] {
        let mut spec = chain(40, "kind = \"baumgarte\"\nbeta = 2e-3");
        let mut twin = spec.constraints[20].clone();
        twin.name = "twin".into();
        spec.constraints.push(twin);
        if let Some(value) = initial {
            for c in &mut spec.constraints {
                c.initial = InitialMultiplier::Value(value);
            }
        }
        let err = match Simulation::new(&spec) {
            Err(e) => e.to_string(),
            Ok(mut sim) => {
                assert_eq!(stage, "first step", "setup accepted a singular system");
                let e = sim.run(&mut [], &mut |_, _| {}).map(|_| ()).unwrap_err();
                e.to_string()
            }
        };
        assert!(
            err.contains("condition") && err.contains("t = "),
            "{stage}: {err}"
        );
    }
}
