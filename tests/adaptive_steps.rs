//! Adaptive macro steps: the local error estimate against the true local error,
//! the tolerance honoured, steps landing on the output grid and the stop time,
//! and the run stopping clearly when the step collapses — on the paper's
//! oscillator (against its closed form), on its planar mechanisms (against
//! the monolithic references in `tests/support/reference`), and with signal
//! connections (which instances roll back, what is refused at setup).

mod oscillator {
    use tether_master::{MasterError, MemoryRecorder, Simulation, StepControl, SystemSpec};
    use tether_tests::column_value;
    use tether_tests::oscillator::*;

    /// The oscillator with adaptive macro steps.
    fn adaptive(method: &str, order: usize, control: StepControl) -> SystemSpec {
        let mut spec = system(method, order, 1e-4, 1.0);
        spec.step_control = Some(control);
        spec
    }

    /// Milne's device: the first step starts from the exact state and the exact
    /// λ0, so its error against the closed form is the true local error; the
    /// estimate (atol = 1, rtol = 0: the raw estimate) must match it.
    #[test]
    fn error_estimate_matches_the_true_local_error() {
        for (name, method) in [VARIANTS[1], VARIANTS[4], VARIANTS[0]] {
            for h in [4e-3, 2e-3, 1e-3, 5e-4] {
                let control = StepControl {
                    rtol: 0.0,
                    atol: 1.0,
                    h_initial: Some(h),
                    ..StepControl::default()
                };
                let mut sim = Simulation::new(&adaptive(method, 0, control)).unwrap();
                sim.step().unwrap();
                let estimate = sim.stats().adaptive.unwrap().last_error;
                let (x, v, _) = reference(sim.time());
                let value = |name: &str| column_value(&sim, name);
                let true_error = [
                    ("mass1.x", x),
                    ("mass1.v", v),
                    ("mass2.x", x),
                    ("mass2.v", v),
                ]
                .iter()
                .map(|&(c, exact)| (value(c) - exact).abs())
                .fold(0.0, f64::max);
                let ratio = estimate / true_error;
                eprintln!("{name}, H = {h:e}: estimate {estimate:.3e}, true local error {true_error:.3e}, ratio {ratio:.3}");
                // Measured: 2.5 for Method 2 index 2 at every H; 2.5 … 13 for
                // Method 1 index 2 and 1.6 … 11 for index 1 (docs/algorithm.md).
                // Never below the true error: the estimate is on the safe side.
                assert!(
                    (1.0..20.0).contains(&ratio),
                    "{name}, H = {h}: ratio {ratio}"
                );
            }
        }
    }

    /// Milne's device after the start-up, k = 0, 1, 2, against the local error
    /// of Method 1 index 1. Its condition γg̈ + βġ + g = 0 makes λ a function of
    /// the state, so the coupled system is an ODE, and a step's local error is
    /// its result minus that ODE's flow over H from the step's start (RK4 with
    /// H/4000 here). H is held (`h_initial = h_max`; atol = 1, rtol = 0: the raw
    /// estimate, never rejected); steps 7 to 12 are compared, well after the
    /// start-up. The estimate is on the safe side, close to the local error
    /// while H ≪ √γ = 1 ms (the stabilisation's time scale) and several times
    /// it from H ≈ √γ on (docs/algorithm.md).
    #[test]
    fn error_estimate_against_the_local_error_of_the_stabilised_system() {
        let (beta, gamma) = (2e-3, 1e-6);
        let rate = |y: [f64; 4]| {
            let [x1, v1, x2, v2] = y;
            let free = (-C * x2 - D * v2) / M2 - (-C * x1 - D * v1) / M1;
            let g = (x2 - x1) + beta * (v2 - v1) + gamma * free;
            let lambda = g / (gamma * (1.0 / M1 + 1.0 / M2));
            [
                v1,
                (-C * x1 - D * v1 + lambda) / M1,
                v2,
                (-C * x2 - D * v2 - lambda) / M2,
            ]
        };
        let flow = |mut y: [f64; 4], h: f64| {
            let dt = h / 4000.0;
            let at = |y: [f64; 4], k: [f64; 4], s: f64| std::array::from_fn(|i| y[i] + s * k[i]);
            for _ in 0..4000 {
                let k1 = rate(y);
                let k2 = rate(at(y, k1, dt / 2.0));
                let k3 = rate(at(y, k2, dt / 2.0));
                let k4 = rate(at(y, k3, dt));
                y = std::array::from_fn(|i| {
                    y[i] + dt / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
                });
            }
            y
        };
        for order in [0, 1, 2] {
            for h in [2e-3, 1e-3, 5e-4] {
                let control = StepControl {
                    rtol: 0.0,
                    atol: 1.0,
                    h_initial: Some(h),
                    h_max: Some(h),
                    ..StepControl::default()
                };
                let mut sim = Simulation::new(&adaptive(VARIANTS[0].1, order, control)).unwrap();
                let state = |sim: &Simulation| {
                    ["mass1.x", "mass1.v", "mass2.x", "mass2.v"].map(|name| column_value(sim, name))
                };
                let mut ratios = Vec::new();
                for _ in 1..=12 {
                    let start = state(&sim);
                    sim.step().unwrap();
                    let local = state(&sim)
                        .iter()
                        .zip(flow(start, h))
                        .map(|(y, exact)| (y - exact).abs())
                        .fold(0.0, f64::max);
                    ratios.push(sim.stats().adaptive.unwrap().last_error / local);
                }
                let (first, ratios) = (ratios[0], &ratios[6..]);
                eprintln!("Method 1 index 1, k = {order}, H = {h:e}: estimate / local error at step 1 {first:.1}, at steps 7 to 12 {ratios:.2?}");
                // Measured: k = 0: 31 to 33, 3.1, 1.7; k = 1: 7.1 to 7.3, 2.7,
                // 1.6; k = 2: 3.1 to 3.7, 1.7 to 3.3, 1.7 (H = 2e-3, 1e-3, 5e-4).
                // Step 1 with k ≥ 1 (a degree-0 predictor under a higher
                // corrector): 166 to 225, far above but safe.
                assert!(first >= 1.0, "k = {order}, H = {h}: step 1 {first}");
                for &ratio in ratios {
                    assert!(
                        (1.0..40.0).contains(&ratio),
                        "k = {order}, H = {h}: {ratios:?}"
                    );
                    if h < 1e-3 {
                        assert!(ratio < 2.0, "k = {order}, H = {h}: {ratios:?}");
                    }
                }
            }
        }
    }

    /// docs/validation.md, "The tolerance is honoured": the global error against the closed form
    /// over atol + rtol·max|y|, for x1 and v1, with atol = rtol. (Index 2 with
    /// k = 1 is unstable at every H, docs/paper-reproduction.md: the controller
    /// shrinks the step to h_min and stops the run, so it is not among these;
    /// nor is Method 2 index 1 with k = 2, unstable at small H:
    /// an_unstable_method_stops_with_the_collapsed_step_named.)
    #[test]
    fn adaptive_steps_honour_the_tolerance() {
        for (name, method, order) in [
            (VARIANTS[1].0, VARIANTS[1].1, 0),
            (VARIANTS[4].0, VARIANTS[4].1, 0),
            (VARIANTS[0].0, VARIANTS[0].1, 0),
            (VARIANTS[0].0, VARIANTS[0].1, 1),
            (VARIANTS[3].0, VARIANTS[3].1, 1),
            (VARIANTS[0].0, VARIANTS[0].1, 2),
        ] {
            {
                for rtol in [1e-4, 1e-6] {
                    let atol = rtol;
                    let control = StepControl {
                        rtol,
                        atol,
                        ..StepControl::default()
                    };
                    let mut sim = Simulation::new(&adaptive(method, order, control)).unwrap();
                    let mut rec = MemoryRecorder::default();
                    let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
                    let e = errors(&rec);
                    let peak = |c: &str| {
                        rec.series(c)
                            .unwrap()
                            .iter()
                            .fold(0.0, |m: f64, y| m.max(y.abs()))
                    };
                    let rx = e.x / (atol + rtol * peak("mass1.x"));
                    let rv = e.v / (atol + rtol * peak("mass1.v"));
                    let a = stats.adaptive.unwrap();
                    eprintln!("{name} k = {order} rtol {rtol:e}: x1 {rx:.3}, v1 {rv:.3}; {} accepted, {} rejected, H {:.2e} … {:.2e}", a.accepted, a.rejected, a.h_smallest, a.h_largest);
                    // Measured: max(x1, v1) from 0.16 to 3.3 (docs/algorithm.md);
                    // Method 1 index 1 with k = 2: 1.1 and 0.42.
                    let worst = rx.max(rv);
                    assert!(
                        (0.1..10.0).contains(&worst),
                        "{name} k = {order} rtol {rtol}: {worst}"
                    );
                    assert_eq!(
                        a.accepted as usize + 1,
                        rec.times.len(),
                        "one row per accepted step"
                    );
                    assert_eq!(
                        *rec.times.last().unwrap(),
                        1.0,
                        "ends exactly at the stop time"
                    );
                }
            }
        }
    }

    /// Method 2 index 1 with k = 2 is unstable at small H
    /// (docs/paper-reproduction.md). With adaptive steps at rtol 1e-6 the
    /// controller shrinks the step until the position level's sensitivities
    /// (∝ H²) vanish, and the run stops with a singular Jacobian whose message
    /// names that macro step, instead of crawling on.
    #[test]
    fn an_unstable_method_stops_with_the_collapsed_step_named() {
        let control = StepControl {
            rtol: 1e-6,
            atol: 1e-6,
            ..StepControl::default()
        };
        let mut sim = Simulation::new(&adaptive(VARIANTS[3].1, 2, control)).unwrap();
        let err = sim.run(&mut [], &mut |_, _| {}).unwrap_err();
        let text = err.to_string();
        eprintln!("{text}");
        // Measured: t = 0.0469, H = 7.9e-7.
        assert!(text.contains("(macro step H = "), "{text}");
        match err {
            MasterError::SingularJacobian {
                time,
                step: Some(h),
                ..
            } => assert!(time < 0.1 && h < 1e-5, "{time} {h}"),
            e => panic!("{e}"),
        }
    }

    /// With `[output] interval`, adaptive steps are clipped to land on its grid
    /// points and exactly those are recorded (the stop time is one): the rows
    /// lie on the grid to 1e-12 whether the controller's steps are smaller than
    /// the interval (rtol 1e-6) or would be larger (rtol 1e-3), and the run
    /// still honours its tolerance against the closed form.
    #[test]
    fn adaptive_steps_land_on_the_output_grid() {
        let (name, method) = VARIANTS[1];
        let interval = 0.01;
        for rtol in [1e-3, 1e-6] {
            let control = StepControl {
                rtol,
                atol: rtol,
                ..StepControl::default()
            };
            let mut spec = adaptive(method, 0, control);
            spec.output.interval = Some(interval);
            let mut sim = Simulation::new(&spec).unwrap();
            let mut rec = MemoryRecorder::default();
            let mut progress = Vec::new();
            let stats = sim
                .run(&mut [&mut rec], &mut |n, total| progress.push((n, total)))
                .unwrap();
            assert!(stats.completed);
            // Progress counts the steps of [experiment] step the time spans.
            assert!(progress
                .windows(2)
                .all(|w| w[0].0 <= w[1].0 && w[1].0 <= w[1].1));
            assert_eq!(progress.last(), Some(&(10_000, 10_000)));
            assert_eq!(
                rec.times.len(),
                101,
                "{name} rtol {rtol}: T_0 and 100 grid points"
            );
            for (j, t) in rec.times.iter().enumerate() {
                assert!(
                    (t - j as f64 * interval).abs() < 1e-12,
                    "row {j} at t = {t}"
                );
            }
            let a = stats.adaptive.unwrap();
            let e = errors(&rec);
            let peak = |c: &str| {
                rec.series(c)
                    .unwrap()
                    .iter()
                    .fold(0.0, |m: f64, y| m.max(y.abs()))
            };
            let worst =
                (e.x / (rtol + rtol * peak("mass1.x"))).max(e.v / (rtol + rtol * peak("mass1.v")));
            eprintln!(
                "{name} rtol {rtol:e}, interval {interval}: error/tolerance {worst:.3}; {} accepted, {} rejected, H {:.2e} … {:.2e}",
                a.accepted, a.rejected, a.h_smallest, a.h_largest
            );
            assert!((0.1..10.0).contains(&worst), "rtol {rtol}: {worst}");
            assert!(
                a.h_largest <= interval * (1.0 + 1e-12),
                "no step passes a grid point"
            );
            if rtol == 1e-6 {
                assert!(a.accepted > 100, "smaller steps between the grid points");
            }
        }
    }
}

mod mechanisms {
    use tether_master::Simulation;
    use tether_tests::column_value;
    use tether_tests::planar::*;
    use tether_tests::reference::{double_pendulum, slider_crank};

    /// docs/validation.md, "The tolerance is honoured", on the double pendulum: the error of the link
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
                // in the oscillator module above), all in link 1's angular velocity but
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
}

mod signals {
    use nalgebra::{Matrix4, Vector4};
    use tether_master::{ConnectionSpec, MemoryRecorder, Simulation, StartValue};
    use tether_tests::signals::*;

    /// Adaptive macro steps roll every instance back on a rejected step, the
    /// signal-only ones too: an instance that cannot (the controller, without
    /// FMU states) is refused at setup, by name.
    #[test]
    fn adaptive_steps_refuse_a_signal_only_instance_without_rollback() {
        let mut spec = system(1e-3, 0, "jacobi", "");
        spec.step_control = Some(tether_master::StepControl::default());
        let message = setup_error(&spec);
        assert!(
            message.contains("'ctrl'")
                && message.contains("canGetAndSetFMUstate")
                && message.contains("signal-only")
                && !message.contains('\n'),
            "{message}"
        );
    }

    /// Without constraints, joints or coupling variables the error estimate has
    /// nothing to measure: adaptive steps are refused at setup.
    #[test]
    fn adaptive_steps_need_coupled_quantities() {
        let mut spec = system(1e-3, 0, "jacobi", "");
        spec.instances.remove(0);
        spec.constraints.clear();
        spec.connections.clear();
        spec.step_control = Some(tether_master::StepControl::default());
        let message = setup_error(&spec);
        assert!(
            message.contains("step_control") && message.contains("constraints"),
            "{message}"
        );
    }

    /// A signal-only instance that can roll back does, with the retry: the
    /// linked pair (mass 1 + mass 2, from x = 0.1 at rest) drives oscillator B
    /// through a one-way spring (`B.F_ext = 1000·mass1.x`), with adaptive steps
    /// whose first tries (h_initial = 0.02) are rejected. B is restored with
    /// the others and its run follows the exact solution (matrix exponential);
    /// a B stepped again after a rejected try would be off by the whole try.
    #[test]
    fn adaptive_steps_roll_back_signal_only_instances() {
        const G: f64 = 1000.0;
        let exact = |t: f64| {
            let (m, c, d) = (M1 + M2, 2.0 * C, 2.0 * D);
            #[rustfmt::skip]
            let a = Matrix4::new(
                0.0,    1.0,    0.0,     0.0,
                -c / m, -d / m, 0.0,     0.0,
                0.0,    0.0,    0.0,     1.0,
                G / M2, 0.0,    -C / M2, -D / M2,
            );
            (a * t).exp() * Vector4::new(0.1, 0.0, 0.0, 0.0)
        };
        for scheme in ["jacobi", "gauss_seidel"] {
            // The controlled pair without its controller, from x = 0.1, and B.
            let mut spec = system(1e-3, 0, scheme, "");
            spec.experiment.stop = 0.2;
            spec.method = tether_master::Method::Baumgarte {
                beta: 2e-3,
                gamma: 0.0,
            };
            spec.step_control = Some(tether_master::StepControl {
                rtol: 1e-6,
                atol: 1e-6,
                h_initial: Some(0.02),
                ..tether_master::StepControl::default()
            });
            spec.instances.remove(0);
            let mut b = spec.instances[1].clone();
            for mass in &mut spec.instances {
                mass.parameters.insert("x0".into(), StartValue::Real(0.1));
            }
            b.name = "b".into();
            spec.instances.push(b);
            spec.connections = vec![ConnectionSpec {
                from: "mass1.x".into(),
                to: "b.F_ext".into(),
                gain: Some(G),
                offset: None,
            }];
            let mut sim = Simulation::new(&spec).unwrap();
            let mut rec = MemoryRecorder::default();
            let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
            let a = stats.adaptive.unwrap();
            let b = &stats.instances[2];
            let column = |name: &str| rec.columns.iter().position(|c| c == name).unwrap();
            let (x1, xb) = (column("mass1.x"), column("b.x"));
            let (mut e1, mut eb, mut peak) = (0.0f64, 0.0f64, 0.0f64);
            for (t, row) in rec.times.iter().zip(&rec.rows) {
                let s = exact(*t);
                e1 = e1.max((row[x1] - s[0]).abs());
                eb = eb.max((row[xb] - s[2]).abs());
                peak = peak.max(s[2].abs());
            }
            println!(
                "{scheme}: {} accepted, {} rejected; B rolled back {} times; max error mass1.x {e1:.2e}, b.x {eb:.2e} (peak |b.x| {peak:.2e})",
                a.accepted, a.rejected, b.state_sets
            );
            assert!(stats.completed && a.rejected > 0, "{scheme}: {a:?}");
            assert_eq!(
                b.state_sets, a.rejected,
                "{scheme}: B restored on each rejection"
            );
            assert_eq!(
                b.do_steps,
                a.accepted + a.rejected,
                "{scheme}: one step per try"
            );
            // Measured: 1.0e-4 of 0.12 (the held signal's first-order error);
            // a B stepped twice over the first rejected try is off by ~1e-2.
            assert!(eb < 2e-3 * peak, "{scheme}: b.x error {eb} of {peak}");
        }
    }
}
