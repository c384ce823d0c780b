//! The paper's mechanisms (EXAMPLES.md §2–3) through link FMUs and planar
//! joints, against the monolithic references in `tests/support/reference`.
//!
//! Run with `cargo test --test joints_planar -- --nocapture` to see the tables.

use tether_master::{MasterError, MemoryRecorder, Method, RunStats, Simulation, SystemSpec};
use tether_tests::column_value;
use tether_tests::reference::{double_pendulum, slider_crank};

/// The example file with the link FMU packaged where it points.
fn example(name: &str) -> SystemSpec {
    tether_fmu_build::workspace_fmu("link").expect("package the link FMU");
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    SystemSpec::from_file(&root.join("examples").join(name)).expect("read the example")
}

fn run(spec: &SystemSpec) -> Result<MemoryRecorder, MasterError> {
    let mut sim = Simulation::new(spec)?;
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {})?;
    Ok(rec)
}

/// Run `spec` with adaptive steps at rtol = atol = `tol` to its end: the
/// results and the run's statistics.
fn run_adaptive(mut spec: SystemSpec, tol: f64) -> (MemoryRecorder, RunStats) {
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

fn with(mut spec: SystemSpec, method: Method, order: usize, h: f64, stop: f64) -> SystemSpec {
    spec.method = method;
    spec.coupling.order = order;
    spec.experiment.step = h;
    spec.experiment.stop = stop;
    spec
}

/// Fitted order from the errors at successive halvings of H (least squares in log-log).
fn fitted_order(hs: &[f64], errors: &[f64]) -> f64 {
    let n = hs.len() as f64;
    let (lx, ly): (Vec<f64>, Vec<f64>) =
        hs.iter().zip(errors).map(|(h, e)| (h.ln(), e.ln())).unzip();
    let mx = lx.iter().sum::<f64>() / n;
    let my = ly.iter().sum::<f64>() / n;
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

/// Max over time of the difference of `columns` from the reference.
fn max_error(
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

const BAUMGARTE_INDEX1: Method = Method::Baumgarte {
    beta: 2e-3,
    gamma: 1e-6,
};
const WEIGHTED_INDEX1: Method = Method::Weighted { a: 1.0, b: 1.0 };
const HS: [f64; 3] = [4e-3, 2e-3, 1e-3];

fn double_pendulum_errors(method: Method, stop: f64) -> Vec<f64> {
    HS.iter()
        .map(|&h| {
            let spec = with(example("double_pendulum.toml"), method, 0, h, stop);
            let rec = run(&spec).expect("double pendulum runs");
            let times = rec.times.clone();
            let reference = double_pendulum::reference(&times);
            max_error(
                &rec,
                &[
                    "link1.B.r[1]",
                    "link1.B.r[2]",
                    "link2.B.r[1]",
                    "link2.B.r[2]",
                ],
                |k, name| reference[k].column(name).expect("reference column"),
            )
        })
        .collect()
}

#[test]
fn double_pendulum_converges_to_the_monolithic_reference() {
    for (label, method) in [
        ("M1 index 1", BAUMGARTE_INDEX1),
        ("M2 index 1", WEIGHTED_INDEX1),
    ] {
        let errors = double_pendulum_errors(method, 1.0);
        let order = fitted_order(&HS, &errors);
        println!("double pendulum {label}: marker position errors {:?} over H = {HS:?}: order {order:.2}", errors.iter().map(|e| format!("{e:.3e}")).collect::<Vec<_>>());
        for pair in errors.windows(2) {
            assert!(
                pair[1] < pair[0],
                "{label}: error must shrink with H: {errors:?}"
            );
        }
        assert!(order > 0.9, "{label}: order {order}");
    }
}

const BAUMGARTE_INDEX2: Method = Method::Baumgarte {
    beta: 2e-3,
    gamma: 0.0,
};
const WEIGHTED_INDEX2: Method = Method::Weighted { a: 1.0, b: 0.0 };

/// Largest |E(t) − E(0)| of the total mechanical energy of both links.
fn energy_drift(rec: &MemoryRecorder) -> f64 {
    let e1 = rec.series("crank.E").unwrap();
    let e2 = rec.series("rocker.E").unwrap();
    let e0 = e1[0] + e2[0];
    e1.iter()
        .zip(&e2)
        .map(|(a, b)| (a + b - e0).abs())
        .fold(0.0, f64::max)
}

#[test]
fn slider_crank_converges_and_its_energy_drift_shrinks_with_h() {
    for (label, method) in [
        ("M1 index 2", BAUMGARTE_INDEX2),
        ("M2 index 2", WEIGHTED_INDEX2),
    ] {
        let mut errors = Vec::new();
        let mut drifts = Vec::new();
        for &h in &HS {
            let spec = with(example("slider_crank.toml"), method, 0, h, 1.0);
            let rec = run(&spec).expect("slider-crank runs");
            let reference = slider_crank::reference(&rec.times);
            errors.push(max_error(&rec, &["crank.phi", "rocker.phi"], |k, name| {
                reference[k].column(name).expect("reference column")
            }));
            drifts.push(energy_drift(&rec));
        }
        let order = fitted_order(&HS, &errors);
        let drift_order = fitted_order(&HS, &drifts);
        println!(
            "slider-crank {label}, k = 0: angle errors {:?}, energy drift {:?} over H = {HS:?}: orders {order:.2}, {drift_order:.2}",
            errors.iter().map(|e| format!("{e:.3e}")).collect::<Vec<_>>(),
            drifts.iter().map(|e| format!("{e:.3e}")).collect::<Vec<_>>()
        );
        for pair in errors.windows(2).chain(drifts.windows(2)) {
            assert!(
                pair[1] < pair[0],
                "{label}: must shrink with H: {errors:?} {drifts:?}"
            );
        }
    }
}

/// The paper: "the numerical dissipation is significantly reduced if higher order
/// approximation is used (k > 0)". Index 2 with k > 0 is not stable here (as for
/// the oscillator, where the paper calls index 2 only partly stable with k = 1), so
/// the comparison over k is made on index 1 (β = 2e-3, γ = 1e-6), where it holds.
#[test]
fn slider_crank_energy_drift_shrinks_with_k() {
    // Method 2 index 1 (a = b = 1) diverges with k = 2, as on the oscillator.
    for (label, method, top) in [
        ("M1 index 1", BAUMGARTE_INDEX1, 2),
        ("M2 index 1", WEIGHTED_INDEX1, 1),
    ] {
        let drifts: Vec<f64> = (0..=top)
            .map(|k| {
                let spec = with(example("slider_crank.toml"), method, k, 1e-3, 1.0);
                energy_drift(&run(&spec).expect("index 1 is stable for k = 0, 1, 2"))
            })
            .collect();
        println!(
            "slider-crank {label}, H = 1e-3: energy drift for k = 0..={top}: {:?}",
            drifts
                .iter()
                .map(|e| format!("{e:.3e}"))
                .collect::<Vec<_>>()
        );
        assert!(drifts[1] < drifts[0] / 10.0, "{label}: {drifts:?}");
        if top == 2 {
            assert!(drifts[2] < drifts[1] / 10.0, "{label}: {drifts:?}");
        }
    }
    for (label, method) in [
        ("M1 index 2", BAUMGARTE_INDEX2),
        ("M2 index 2", WEIGHTED_INDEX2),
    ] {
        let spec = with(example("slider_crank.toml"), method, 1, 1e-3, 1.0);
        match run(&spec) {
            Err(MasterError::Diverged { time, quantity, .. }) => {
                println!("slider-crank {label}, k = 1: diverged at t = {time} ({quantity})")
            }
            other => panic!(
                "{label} with k = 1 was expected to diverge: {:?}",
                other.map(|_| ())
            ),
        }
    }
}

/// The paper's own style (the FMUs take the multipliers as inputs) against the
/// force ports: for an atpoint joint the port unknowns are exactly ±λ, so both
/// give the same motion up to the finite-difference Jacobians' differences.
#[test]
fn multiplier_inputs_and_force_ports_agree_on_the_double_pendulum() {
    let ports = with(
        example("double_pendulum.toml"),
        BAUMGARTE_INDEX1,
        0,
        1e-3,
        1.0,
    );
    let mut paper = ports.clone();
    paper.joints[0].multipliers = Some(vec![
        "link1.B.F[1] - link2.A.F[1]".into(),
        "link1.B.F[2] - link2.A.F[2]".into(),
    ]);
    let (a, b) = (run(&ports).unwrap(), run(&paper).unwrap());
    let columns = [
        "link1.B.r[1]",
        "link1.B.r[2]",
        "link2.B.r[1]",
        "link2.B.r[2]",
    ];
    let relative = |name: &str| {
        let (x, y) = (a.series(name).unwrap(), b.series(name).unwrap());
        let scale = x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let diff = x
            .iter()
            .zip(&y)
            .fold(0.0_f64, |m, (p, q)| m.max((p - q).abs()));
        println!("{name}: max difference {diff:.3e} (scale {scale:.3})");
        diff / scale
    };
    // Paper style has 2 unknowns, force ports 6 (2 λ + 4 ports); both solve the
    // same conditions and differ only in their finite-difference Jacobians
    // (perturbing λ moves both FMUs at once, a port only one). The corrected
    // multipliers carry that difference (measured 1.3e-7 relative); the motion
    // barely sees it (measured 1.1e-12).
    for name in columns {
        assert!(relative(name) < 1e-10, "{name}");
    }
    for name in ["hinge.lambda[1]", "hinge.lambda[2]"] {
        assert!(relative(name) < 1e-5, "{name}");
    }
}

#[test]
fn a_joint_naming_a_marker_that_does_not_exist_is_a_clear_error() {
    let mut spec = example("double_pendulum.toml");
    spec.joints[0].i = "link1.C".into();
    let err = Simulation::new(&spec).err().expect("must fail").to_string();
    assert_eq!(
        err,
        "joint 'hinge': instance 'link1' has no marker 'C' (no output 'C.r[1]'); its markers are: A, B"
    );
    let mut spec = example("double_pendulum.toml");
    spec.joints[0].j = "link3.A".into();
    let err = Simulation::new(&spec).err().expect("must fail").to_string();
    assert!(
        err.contains("unknown instance 'link3'") && err.contains("link2"),
        "{err}"
    );
}

#[test]
fn a_spatial_joint_on_planar_fmus_names_the_missing_port() {
    let mut spec = example("double_pendulum.toml");
    spec.joints[0].plane = None;
    let err = Simulation::new(&spec).err().expect("must fail").to_string();
    assert!(!err.contains('\n'));
    assert!(err.contains("'B.F[3]'") && err.contains("link1"), "{err}");
}

/// Iterated correction on a nonlinear joint: the second correction, with the
/// same Jacobian from the g at the corrected point, leaves a smaller
/// constraint residual than the paper's single one.
#[test]
fn iterated_correction_reduces_the_double_pendulum_residual() {
    let mut found = Vec::new();
    for iterations in [1, 2, 5] {
        let index3 = Method::Baumgarte {
            beta: 0.0,
            gamma: 0.0,
        };
        let mut spec = with(example("double_pendulum.toml"), index3, 0, 4e-3, 1.0);
        spec.coupling.iterations = iterations;
        let mut sim = Simulation::new(&spec).unwrap();
        let mut rec = MemoryRecorder::default();
        let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
        let reference = double_pendulum::reference(&rec.times);
        let error = max_error(&rec, &["link2.B.r[1]", "link2.B.r[2]"], |k, name| {
            reference[k].column(name).expect("reference column")
        });
        let residual = stats.residuals.iter().map(|r| r.1).fold(0.0, f64::max);
        let per_step = stats.corrections as f64 / stats.macro_steps as f64;
        println!("double pendulum, index 3, H = 4e-3, {iterations} iteration(s): max |g| {residual:.3e}, error {error:.3e}, corrections per step {per_step:.2}");
        found.push((residual, error, per_step));
    }
    // Measured: max |g| 2.7e-10, 3.2e-15, 3.3e-16; errors 7.33e-8 all three;
    // 2.99 corrections per step with 5 allowed (the third update is below
    // iteration_tol).
    let (one, two, five) = (found[0], found[1], found[2]);
    assert!(two.0 < one.0 / 1e3, "{found:?}");
    assert!(five.0 <= two.0, "{found:?}");
    assert!((two.1 - one.1).abs() < 0.01 * one.1, "{found:?}");
    assert!(two.2 == 2.0 && (2.0..5.0).contains(&five.2), "{found:?}");
}

/// "The tolerance is honoured" on the double pendulum: the error of the link
/// angles, angular velocities and the free end's position and velocity
/// against the monolithic reference over atol + rtol·max|y| (atol = rtol),
/// the largest over these columns.
#[test]
fn adaptive_steps_honour_the_tolerance_on_the_double_pendulum() {
    let columns = [
        "link1.phi",
        "link2.phi",
        "link1.omega",
        "link2.omega",
        "link2.B.r[1]",
        "link2.B.r[2]",
        "link2.B.v[1]",
        "link2.B.v[2]",
    ];
    for (label, method, order) in [
        ("M1 index 1", BAUMGARTE_INDEX1, 0),
        ("M1 index 1", BAUMGARTE_INDEX1, 1),
        ("M2 index 1", WEIGHTED_INDEX1, 1),
        ("M1 index 1", BAUMGARTE_INDEX1, 2),
    ] {
        for rtol in [1e-4, 1e-6] {
            let spec = with(example("double_pendulum.toml"), method, order, 1e-4, 1.0);
            let (rec, stats) = run_adaptive(spec, rtol);
            let reference = double_pendulum::reference(&rec.times);
            // The largest error over tolerance: its value, time and column;
            // and the largest after the start-up (t > 0.05).
            let mut worst = (0.0, 0.0, "");
            let mut after_start: f64 = 0.0;
            for name in columns {
                let series = rec.series(name).unwrap();
                let peak = series.iter().fold(0.0, |m: f64, y| m.max(y.abs()));
                for (k, y) in series.iter().enumerate() {
                    let error = (y - reference[k].column(name).unwrap()).abs();
                    let ratio = error / (rtol + rtol * peak);
                    if ratio > worst.0 {
                        worst = (ratio, rec.times[k], name);
                    }
                    if rec.times[k] > 0.05 {
                        after_start = after_start.max(ratio);
                    }
                }
            }
            let (worst, at, column) = worst;
            let a = stats.adaptive.unwrap();
            println!(
                "double pendulum {label}, k = {order}, rtol = atol = {rtol:e}: max error / tolerance {worst:.3} (t = {at:.4}, {column}; after t = 0.05 {after_start:.3}); {} accepted, {} rejected, H {:.2e} … {:.2e}",
                a.accepted, a.rejected, a.h_smallest, a.h_largest
            );
            // Measured: 0.34, 5.5 (M1, k = 0), 0.40, 0.099 (M1, k = 1), 0.075,
            // 0.065 (M2, k = 1), 0.95, 0.35 (M1, k = 2; M2 with k = 2 is
            // unstable at small H: an_unstable_method_stops_with_the_collapsed_step_named
            // in master_oscillator.rs), all in link 1's angular velocity but
            // the last. The goal is [0.1, 10]: k = 1 is more accurate than
            // asked. The estimate is 466 to 2054 times the corrected run's
            // local error in these coordinates with k = 1
            // (error_estimate_against_the_local_error_on_the_double_pendulum);
            // the largest errors sit at the start-up (M1, rtol 1e-6: t = 0.0026;
            // 0.028 after t = 0.05) and on the last steps before t = 1 (M2), and
            // k = 0 has its 5.5 at the start-up too (t = 0.0008; 0.22 after
            // t = 0.05).
            let lowest = if order == 1 { 0.05 } else { 0.1 };
            assert!(
                (lowest..10.0).contains(&worst),
                "{label} k = {order} rtol {rtol}: {worst}"
            );
        }
    }
}

/// Adaptive steps land on the stop time and on the output grid without a
/// sliver step: a target within two steps is reached in two equal ones. With
/// k = 1 a sliver puts two nearby points into the next step's extrapolation,
/// whose slope then amplifies the multipliers' noise by the ratio of H to
/// the sliver.
/// Measured before the halving (Method 2 index 1, k = 1): at rtol 1e-5 the
/// last step was 1.1e-4 s after steps of 5.4e-3 s and the angular velocities'
/// error jumped to 7.1e-5 at t = 1 (6e-8 for link 1 a step before); at
/// rtol 1e-6 with `[output] interval = 0.1` a 2.2e-5 s step landed on
/// t = 0.7, the next steps (2.3e-3 s before) were rejected and shrank to
/// 1e-6 s, and the run stopped with a singular Jacobian at t = 0.70004.
#[test]
fn adaptive_steps_land_without_a_sliver_step() {
    for (rtol, interval) in [(1e-5, None), (1e-6, Some(0.1))] {
        let mut spec = with(
            example("double_pendulum.toml"),
            WEIGHTED_INDEX1,
            1,
            1e-4,
            1.0,
        );
        spec.output.interval = interval;
        let (rec, stats) = run_adaptive(spec, rtol);
        let a = stats.adaptive.unwrap();
        let t = &rec.times;
        let n = t.len();
        let (last, before) = (t[n - 1] - t[n - 2], t[n - 2] - t[n - 3]);
        let reference = double_pendulum::reference(t);
        let error = max_error(&rec, &["link1.omega", "link2.omega"], |k, name| {
            reference[k].column(name).expect("reference column")
        });
        println!(
            "rtol {rtol:e}, interval {interval:?}: {} accepted, {} rejected, H {:.2e} … {:.2e}; rows {:.3e} and {:.3e} apart at the end; max |ω| error {error:.2e}",
            a.accepted, a.rejected, a.h_smallest, a.h_largest, before, last
        );
        assert!(rec.times.last() == Some(&1.0));
        if interval.is_none() {
            // Measured: 2.73e-3 after 2.73e-3 and 2.9e-6 (was 1.1e-4 after
            // 5.4e-3 and 7.1e-5).
            assert!(last >= 0.25 * before, "{before:e} then {last:e}");
            assert!(error < 1e-5, "{error:e}");
        }
    }
}

/// Jacobian reuse on the paper's mechanisms: `fmi2DoStep` calls and the
/// largest error against the monolithic reference, every step vs reuse.
#[test]
fn jacobian_reuse_saves_fmu_calls_at_the_same_accuracy() {
    use tether_master::JacobianMode;
    let cases: [(&str, &str, Method, &[&str]); 2] = [
        (
            "double pendulum",
            "double_pendulum.toml",
            BAUMGARTE_INDEX1,
            &["link1.phi", "link2.phi", "link2.B.r[1]", "link2.B.r[2]"],
        ),
        (
            "slider-crank",
            "slider_crank.toml",
            BAUMGARTE_INDEX2,
            &["crank.phi", "rocker.phi"],
        ),
    ];
    for (label, file, method, columns) in cases {
        let mut found = Vec::new();
        for mode in [JacobianMode::EveryStep, JacobianMode::Reuse] {
            let mut spec = with(example(file), method, 0, 1e-3, 1.0);
            spec.coupling.jacobian = mode;
            let mut sim = Simulation::new(&spec).unwrap();
            let mut rec = MemoryRecorder::default();
            let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
            let calls: u64 = stats.instances.iter().map(|c| c.do_steps).sum();
            let error = if file.starts_with("double") {
                let reference = double_pendulum::reference(&rec.times);
                max_error(&rec, columns, |k, name| reference[k].column(name).unwrap())
            } else {
                let reference = slider_crank::reference(&rec.times);
                max_error(&rec, columns, |k, name| reference[k].column(name).unwrap())
            };
            println!(
                "{label}, {mode:?}: {calls} fmi2DoStep, max error {error:.4e}, Jacobian made in {} steps ({} after a misprediction), reused in {}",
                stats.jacobians, stats.jacobians_remade, stats.jacobians_reused
            );
            found.push((calls as f64, error));
        }
        let (every, reuse) = (found[0], found[1]);
        println!(
            "{label}: reuse makes {:.1} % fewer calls at {:+.1} % max error",
            100.0 * (1.0 - reuse.0 / every.0),
            100.0 * (reuse.1 / every.1 - 1.0)
        );
        // Measured (H = 1e-3, 1 s): double pendulum 47.3 % fewer calls, error
        // unchanged; slider-crank 51.1 % fewer, error 5.1 % smaller.
        assert!(reuse.0 <= 0.7 * every.0, "{label}: {found:?}");
        assert!(reuse.1 <= 1.1 * every.1, "{label}: {found:?}");
    }
}

/// One slider-crank run over 2 s (through its dead centres): total
/// `fmi2DoStep` calls and the largest angle error against the reference.
fn slider_crank_work(spec: &SystemSpec) -> Option<(u64, f64)> {
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

/// Adaptive steps with Jacobian reuse at loose tolerances, on the
/// slider-crank over 2 s through its dead centres. A correction the reused
/// Jacobian mispredicted is made again with a fresh one before the step is
/// judged: accepted as it was, it would leave a constraint residual whose
/// removal the next step's error estimate counts at any H, and the run would
/// stop at h_min. Each run completes, with a max angle error within 10× the
/// tolerance (atol + rtol·max|φ|) and at most 10 % above the same run's
/// without reuse.
#[test]
fn adaptive_steps_with_reuse_run_through_loose_tolerances() {
    use tether_master::JacobianMode;
    for rtol in [1e-2, 3e-3] {
        let mut found = Vec::new();
        for mode in [JacobianMode::EveryStep, JacobianMode::Reuse] {
            let mut spec = with(example("slider_crank.toml"), BAUMGARTE_INDEX2, 0, 1e-3, 2.0);
            spec.coupling.jacobian = mode;
            let (rec, stats) = run_adaptive(spec, rtol);
            let calls: u64 = stats.instances.iter().map(|c| c.do_steps).sum();
            let columns = ["crank.phi", "rocker.phi"];
            let reference = slider_crank::reference(&rec.times);
            let error = max_error(&rec, &columns, |k, name| {
                reference[k].column(name).expect("reference column")
            });
            let peak = columns
                .iter()
                .flat_map(|c| rec.series(c).unwrap())
                .fold(0.0, |m: f64, y| m.max(y.abs()));
            let ratio = error / (rtol + rtol * peak);
            println!(
                "rtol = atol = {rtol:e}, {mode:?}: {calls} fmi2DoStep, max angle error {error:.3e} ({ratio:.2} of the tolerance), Jacobian made in {} tries ({} after a misprediction), reused in {}",
                stats.jacobians, stats.jacobians_remade, stats.jacobians_reused
            );
            found.push((error, ratio));
        }
        // Measured: 792 and 866 calls, 0.372 and 0.335 rad (1e-2); 1341 and
        // 1340 calls, 0.180 and 0.138 rad (3e-3; without reuse that is 10.8
        // times the tolerance, above the 10 asked of reuse). At these tolerances most
        // reused Jacobians mispredict (51 of 80 made after one at 1e-2), so
        // reuse saves no calls; it does from 1e-3 on (work_precision).
        let ((every, _), (reuse, ratio)) = (found[0], found[1]);
        assert!(ratio <= 10.0, "rtol {rtol}: {found:?}");
        assert!(reuse <= 1.1 * every, "rtol {rtol}: {found:?}");
    }
}

/// Work–precision on the slider-crank over 2 s (its fast swing through the
/// dead centres at t ≈ 0.75 s): fixed H = 1e-2, 5e-3, … against adaptive
/// steps (rtol = atol = 1e-3 … 1e-5) without and with Jacobian reuse. Each
/// adaptive run must reach its error with at most a third of the calls of
/// the best fixed H that reaches it (the largest H of the sequence). With
/// `TETHER_FIGURES=DIR` the plot and its table go to DIR (docs/figures).
#[test]
fn work_precision_on_the_slider_crank() {
    use tether_master::{JacobianMode, StepControl};
    use tether_study::{ConvergenceCurve, ConvergencePoint, Outcome};
    let base = |h: f64| with(example("slider_crank.toml"), BAUMGARTE_INDEX2, 0, h, 2.0);
    let curve = |label: &str, points: &[(u64, f64)]| ConvergenceCurve {
        label: label.into(),
        points: points
            .iter()
            .map(|&(calls, error)| ConvergencePoint {
                step: calls as f64,
                outcome: Outcome::Completed,
                errors: vec![error],
                error,
            })
            .collect(),
        order: None,
    };
    let fixed: Vec<(f64, (u64, f64))> = (0..8)
        .map(|i| {
            let h = 1e-2 / f64::powi(2.0, i);
            (h, slider_crank_work(&base(h)).expect("fixed H runs"))
        })
        .collect();
    let mut table = String::from("run,fmi2DoStep calls,max angle error\n");
    for (h, (calls, error)) in &fixed {
        table += &format!("fixed H = {h:e},{calls},{error:e}\n");
    }
    let mut curves = vec![curve(
        "fixed H = 1e-2 … 7.8e-5",
        &fixed.iter().map(|f| f.1).collect::<Vec<_>>(),
    )];
    for (label, mode) in [
        ("adaptive", JacobianMode::EveryStep),
        ("adaptive + Jacobian reuse", JacobianMode::Reuse),
    ] {
        let mut points = Vec::new();
        for rtol in [1e-3, 1e-4, 1e-5] {
            let mut spec = base(1e-3);
            spec.coupling.jacobian = mode;
            spec.step_control = Some(StepControl {
                rtol,
                atol: rtol,
                ..StepControl::default()
            });
            let (calls, error) = slider_crank_work(&spec).expect("adaptive run");
            let (h, (best_calls, best_error)) = fixed
                .iter()
                .find(|(_, (_, e))| *e <= error)
                .expect("a fixed H reaches the error");
            let ratio = calls as f64 / *best_calls as f64;
            println!(
                "{label}, rtol = atol = {rtol:e}: {calls} calls, error {error:.3e}; best fixed H = {h:e} ({best_error:.3e}): {best_calls} calls; ratio {ratio:.3}"
            );
            table += &format!("{label} rtol = atol = {rtol:e},{calls},{error:e}\n");
            assert!(ratio <= 1.0 / 3.0, "{label} rtol {rtol}: ratio {ratio}");
            points.push((calls, error));
        }
        curves.push(curve(label, &points));
    }
    print!("{table}");
    if let Ok(dir) = std::env::var("TETHER_FIGURES") {
        let dir = std::path::Path::new(&dir);
        std::fs::write(dir.join("work_precision.csv"), &table).unwrap();
        let figure = tether_study::plot::ConvergencePlot {
            title: "Slider-crank, 2 s, index 2, k = 0: work vs precision".into(),
            error_label: "max angle error against the reference [rad]".into(),
            x_label: "fmi2DoStep calls (both links)".into(),
            curves: &curves,
            slopes: vec![],
        };
        tether_study::plot::save(&dir.join("work_precision.svg"), &figure).unwrap();
    }
}

/// The local error estimate against the local error in the physical
/// coordinates: the link angles' flow (the monolithic reference's minimal
/// coordinates φ1, φ2, φ̇1, φ̇2) from each step's start over H, compared with
/// the step's result on link 1's end B (position, velocity: the coupled
/// outputs the estimate covers) and both angular velocities. H is held
/// (`h_initial = h_max`; atol = 1, rtol = 0: the raw estimate, never
/// rejected); the last 10 steps before t = 0.3 s are compared. On these
/// stabilised index-1 conditions the corrected run is far more accurate than
/// Milne's relation assumes, so y^p − y^c is mostly the predicted run's
/// error: the estimate is 81 to 2054 times the local error (docs/algorithm.md;
/// the cause: corrected_multipliers_close_the_condition_rather_than_sample_lambda).
/// Near the stability limit of the extrapolation it is not safe: with k = 2
/// at H = 2e-3 (Method 1; 4e-3 diverges) the local error is larger than the
/// estimate.
#[test]
fn error_estimate_against_the_local_error_on_the_double_pendulum() {
    let compared = [
        "link1.B.r[1]",
        "link1.B.r[2]",
        "link1.B.v[1]",
        "link1.B.v[2]",
        "link1.omega",
        "link2.omega",
    ];
    let mut found = Vec::new();
    for (label, method, order, h) in [
        ("M1 index 1", BAUMGARTE_INDEX1, 0, 4e-3),
        ("M1 index 1", BAUMGARTE_INDEX1, 0, 2e-3),
        ("M2 index 1", WEIGHTED_INDEX1, 0, 2e-3),
        ("M1 index 1", BAUMGARTE_INDEX1, 1, 2e-3),
        ("M2 index 1", WEIGHTED_INDEX1, 1, 4e-3),
        ("M2 index 1", WEIGHTED_INDEX1, 1, 2e-3),
        ("M1 index 1", BAUMGARTE_INDEX1, 2, 2e-3),
    ] {
        let mut spec = with(example("double_pendulum.toml"), method, order, h, 1.0);
        spec.step_control = Some(tether_master::StepControl {
            rtol: 0.0,
            atol: 1.0,
            h_initial: Some(h),
            h_max: Some(h),
            ..Default::default()
        });
        let mut sim = Simulation::new(&spec).unwrap();
        let steps = (0.3 / h).round() as usize;
        let mut ratios = Vec::new();
        for n in 1..=steps {
            let start = ["link1.phi", "link2.phi", "link1.omega", "link2.omega"]
                .map(|name| column_value(&sim, name));
            sim.step().unwrap();
            if n + 10 <= steps {
                continue;
            }
            let mut from_start = double_pendulum::PAPER;
            from_start.phi0 = [start[0], start[1]];
            from_start.omega0 = [start[2], start[3]];
            let flow = from_start.solve(&[h])[0];
            let local = compared
                .iter()
                .map(|&c| (column_value(&sim, c) - flow.column(c).unwrap()).abs())
                .fold(0.0, f64::max);
            ratios.push(sim.stats().adaptive.unwrap().last_error / local);
        }
        let (low, high) = ratios
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(l, u), &r| (l.min(r), u.max(r)));
        println!("double pendulum {label}, k = {order}, H = {h:e}: estimate / local error {low:.2} … {high:.2}");
        found.push((order, low, high));
    }
    // Measured: k = 0: 81 … 121 (H = 4e-3), 192 … 247 (2e-3, both
    // methods); k = 1: 1718 … 2023 (Method 1, 2e-3), 466 … 649 and
    // 1766 … 2054 (Method 2, 4e-3 and 2e-3); k = 2: 0.58 … 0.62.
    for &(order, low, high) in &found {
        if order < 2 {
            assert!(low > 50.0, "{found:?}");
        } else {
            assert!(low > 0.5 && high < 2.0, "{found:?}");
        }
    }
}

/// What the corrected multipliers are, against the monolithic reference's
/// joint force λ(t) on the double pendulum (fixed H, t in [0.1, 0.3] s): not
/// samples of λ(T_{N+1}), as Milne's relation in the error estimate assumes,
/// but the values that close the condition at T_{N+1}, and with them the
/// joint's impulse over the step comes out one order more accurate. With
/// k = 0 the corrector's constant input is λ at the step's midpoint (the
/// midpoint rule, not the assumed constant λ(T_{N+1})). With k = 1 it is
/// λ(T_{N+1}) − λ̈(T_{N+1})·H²/12: the line through such values has the
/// impulse of λ up to O(H⁴), the trapezoidal rule's error −λ̈H³/12 cancelled.
/// With them the corrected run is more accurate than the relation assumes:
/// the estimate is 81 to 2054 times its local error there
/// (error_estimate_against_the_local_error_on_the_double_pendulum).
#[test]
fn corrected_multipliers_close_the_condition_rather_than_sample_lambda() {
    // Max over t ≥ 0.1 and both components of |u_(N+1) − λ(T_(N+1) − θH)|
    // for θ = 0 and 1/2, and of |u_(N+1) − λ(T_(N+1)) + λ̈(T_(N+1))·H²/12|.
    let deviations = |method: Method, order: usize, h: f64| -> [f64; 3] {
        let rec = run(&with(
            example("double_pendulum.toml"),
            method,
            order,
            h,
            0.3,
        ))
        .unwrap();
        let u = [
            rec.series("hinge.lambda[1]").unwrap(),
            rec.series("hinge.lambda[2]").unwrap(),
        ];
        let lambda = |shift: f64| -> Vec<[f64; 2]> {
            let times: Vec<f64> = rec.times.iter().map(|t| (t + shift).max(0.0)).collect();
            let states = double_pendulum::reference(&times);
            states.iter().map(|s| s.lambda).collect()
        };
        let eps = 1e-3;
        let (end, middle) = (lambda(0.0), lambda(-h / 2.0));
        let (before, after) = (lambda(-eps), lambda(eps));
        let mut found = [0.0f64; 3];
        for n in (0..rec.times.len()).filter(|&n| rec.times[n] >= 0.1) {
            for c in 0..2 {
                let second = (after[n][c] - 2.0 * end[n][c] + before[n][c]) / (eps * eps);
                let trapezoid = end[n][c] - second * h * h / 12.0;
                for (worst, value) in found.iter_mut().zip([end[n][c], middle[n][c], trapezoid]) {
                    *worst = worst.max((u[c][n] - value).abs());
                }
            }
        }
        found
    };
    for (label, method) in [("M1", BAUMGARTE_INDEX1), ("M2", WEIGHTED_INDEX1)] {
        for (order, hs) in [(0, [4e-3, 2e-3, 1e-3]), (1, [2e-3, 1e-3, 5e-4])] {
            for h in hs {
                let found @ [end, middle, trapezoid] = deviations(method, order, h);
                println!(
                    "double pendulum {label} index 1, k = {order}, H = {h:e}: max |u_(N+1) - x| [N] for x = lambda(T_(N+1)) {end:.2e}, lambda at the midpoint {middle:.2e}, lambda(T_(N+1)) - lambda''·H²/12 {trapezoid:.2e}"
                );
                // Measured (Method 1; Method 2 within a factor 3.3): k = 0 4.9e-4, 1.5e-4,
                // 5.2e-5 at the midpoint against 6.0e-2, 3.0e-2, 1.5e-2 at
                // T_(N+1); k = 1 at H = 2e-3: 1.0e-4 at T_(N+1), 5.4e-7 with
                // the trapezoidal term, 3.0e-2 at the midpoint.
                if order == 0 {
                    assert!(middle < end / 30.0, "{label} k = 0, H = {h}: {found:?}");
                } else {
                    assert!(end < middle / 30.0, "{label} k = 1, H = {h}: {found:?}");
                    assert!(trapezoid < end / 30.0, "{label} k = 1, H = {h}: {found:?}");
                }
            }
        }
    }
}
