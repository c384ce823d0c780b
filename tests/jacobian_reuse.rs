//! Jacobian reuse (`[coupling] jacobian = "reuse"`) on the paper's planar
//! mechanisms: fewer `fmi2DoStep` calls at the same accuracy against the
//! monolithic references, and the work–precision of fixed and adaptive steps
//! with and without reuse.

use tether_master::{MemoryRecorder, Method, Simulation};
use tether_tests::planar::*;
use tether_tests::reference::{double_pendulum, slider_crank};

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

/// Work–precision on the slider-crank over 2 s (its fast swing through the
/// dead centres at t ≈ 0.75 s): fixed H = 1e-2, 5e-3, … against adaptive
/// steps (rtol = atol = 1e-3 … 1e-5) without and with Jacobian reuse. Each
/// adaptive run must reach its error with at most a third of the calls of
/// the best fixed H that reaches it (the largest H of the sequence). With
/// `TETHER_FIGURES=DIR` the plot and its table go to DIR (docs/figures).
#[test]
fn adaptive_steps_reach_each_error_with_a_third_of_the_fixed_step_calls() {
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
