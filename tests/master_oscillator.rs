//! The paper's two-mass oscillator (Sect. 2 and 4.1) against its closed form.
//!
//! The coupled system is one damped oscillator with m = m1 + m2, c = c1 + c2,
//! d = d1 + d2, so x(t), v(t) and λ(t) are known exactly (EXAMPLES.md §1). The
//! FMUs integrate exactly (`exact = true`), so every error measured here is
//! the coupling error.

use tether_master::{MasterError, MemoryRecorder, Simulation, StepControl, SystemSpec};
use tether_tests::column_value;

const M1: f64 = 1.0;
const M2: f64 = 2.0;
const C: f64 = 1000.0;
const D: f64 = 10.0;
const V0: f64 = 100.0;

/// Closed form of the coupled oscillator: (x, v, λ) at time t.
fn reference(t: f64) -> (f64, f64, f64) {
    let (m, c, d) = (M1 + M2, 2.0 * C, 2.0 * D);
    let delta = d / (2.0 * m);
    let wd = (c / m - delta * delta).sqrt();
    let (s, co, e) = ((wd * t).sin(), (wd * t).cos(), (-delta * t).exp());
    let x = e * V0 / wd * s;
    let v = e * V0 * (co - delta / wd * s);
    let lambda = M1 * M2 / (M1 + M2) * ((C / M1 - C / M2) * x + (D / M1 - D / M2) * v);
    (x, v, lambda)
}

fn system(method: &str, order: usize, h: f64, stop: f64) -> SystemSpec {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let text = format!(
        r#"
        [experiment]
        stop = {stop}
        step = {h}

        [method]
        {method}

        [coupling]
        order = {order}

        [[instance]]
        name = "mass1"
        fmu = "{fmu}"
        parameters = {{ m = {M1}, c = {C}, d = {D}, x0 = 0.0, v0 = {V0}, exact = true }}

        [[instance]]
        name = "mass2"
        fmu = "{fmu}"
        parameters = {{ m = {M2}, c = {C}, d = {D}, x0 = 0.0, v0 = {V0}, exact = true }}

        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"
        "#,
        fmu = fmu.display()
    );
    SystemSpec::from_toml(&text).expect("valid system")
}

fn run(spec: &SystemSpec) -> Result<MemoryRecorder, MasterError> {
    let mut sim = Simulation::new(spec)?;
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {})?;
    Ok(rec)
}

/// Max-norm errors of x1, v1 and λ over the whole run.
#[derive(Debug, Clone, Copy)]
struct Errors {
    x: f64,
    v: f64,
    lambda: f64,
}

impl Errors {
    /// The global state error: the larger of the x1 and v1 errors.
    fn state(&self) -> f64 {
        self.x.max(self.v)
    }
}

fn errors(rec: &MemoryRecorder) -> Errors {
    let (x1, v1, lam) = (
        rec.series("mass1.x").unwrap(),
        rec.series("mass1.v").unwrap(),
        rec.series("link.lambda").unwrap(),
    );
    let mut e = Errors {
        x: 0.0,
        v: 0.0,
        lambda: 0.0,
    };
    for (i, &t) in rec.times.iter().enumerate() {
        let (x, v, l) = reference(t);
        e.x = e.x.max((x1[i] - x).abs());
        e.v = e.v.max((v1[i] - v).abs());
        e.lambda = e.lambda.max((lam[i] - l).abs());
    }
    e
}

const VARIANTS: [(&str, &str); 6] = [
    (
        "baumgarte index 1",
        "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6",
    ),
    ("baumgarte index 2", "kind = \"baumgarte\"\nbeta = 2e-3"),
    ("baumgarte index 3", "kind = \"baumgarte\""),
    ("weighted index 1", "kind = \"weighted\"\na = 1.0\nb = 1.0"),
    ("weighted index 2", "kind = \"weighted\"\na = 1.0"),
    ("weighted index 3", "kind = \"weighted\""),
];

#[test]
fn consistent_initial_multiplier_is_1000_over_3() {
    let spec = system(VARIANTS[0].1, 0, 1e-3, 1e-3);
    let sim = Simulation::new(&spec).unwrap();
    let lambda0 = sim.unknowns()[0];
    assert!((lambda0 - 1000.0 / 3.0).abs() < 1e-6, "λ0 = {lambda0}");
}

#[test]
fn errors_at_h_1e_3_for_every_index_of_both_methods() {
    let mut table = String::from("variant             err x1      err v1      err lambda\n");
    for (name, method) in VARIANTS {
        let e = errors(&run(&system(method, 0, 1e-3, 1.0)).unwrap());
        table += &format!(
            "{name:<18} {:10.3e}  {:10.3e}  {:10.3e}\n",
            e.x, e.v, e.lambda
        );
        // Measured (exact FMU integration): x1 errors 1.4e-9 … 1.9e-5, v1 errors
        // 2.3e-3 … 5.1e-3, λ errors 16 … 21 (k = 0 holds λ constant over a step,
        // so λ lags the closed form by about H·λ'/2 ≈ 17). Bounds at about 2×.
        assert!(e.x < 5e-5 && e.v < 1e-2, "{name}: {e:?}");
        assert!(e.lambda < 40.0, "{name}: {e:?}");
    }
    eprintln!("{table}");
}

/// Least-squares slope of log(error) over log(H).
fn fitted_order(hs: &[f64], errs: &[f64]) -> f64 {
    let xs: Vec<f64> = hs.iter().map(|h| h.ln()).collect();
    let ys: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    sxy / sxx
}

fn convergence(method: &str, order: usize, hs: &[f64]) -> (Vec<f64>, f64) {
    let errs: Vec<f64> = hs
        .iter()
        .map(|&h| errors(&run(&system(method, order, h, 1.0)).unwrap()).state())
        .collect();
    let p = fitted_order(hs, &errs);
    (errs, p)
}

fn sci(v: &[f64]) -> Vec<String> {
    v.iter().map(|x| format!("{x:.3e}")).collect()
}

const HS: [f64; 4] = [4e-3, 2e-3, 1e-3, 5e-4];

#[test]
fn index2_and_index3_converge_with_order_two_for_both_methods() {
    for (name, method) in [VARIANTS[1], VARIANTS[2], VARIANTS[4], VARIANTS[5]] {
        let (errs, p) = convergence(method, 0, &HS);
        eprintln!("{name}: errors {:?}, order {p:.2}", sci(&errs));
        assert!(
            (1.8..2.3).contains(&p),
            "{name}: order {p}, errors {errs:?}"
        );
    }
}

#[test]
fn method2_index1_converges_with_order_two() {
    // The paper (Fig. 11): no order reduction for Method 2 on index 1.
    let (errs, p) = convergence(VARIANTS[3].1, 0, &HS);
    eprintln!("weighted index 1: errors {:?}, order {p:.2}", sci(&errs));
    assert!((1.8..2.3).contains(&p), "order {p}, errors {errs:?}");
}

#[test]
fn method1_index1_has_a_larger_error_and_a_lower_order() {
    // The paper (Fig. 6): index 1 of Method 1 loses order, index 2 does not.
    let (e1, p1) = convergence(VARIANTS[0].1, 0, &HS);
    let (e2, _) = convergence(VARIANTS[1].1, 0, &HS);
    eprintln!("baumgarte index 1: errors {:?}, order {p1:.2}", sci(&e1));
    assert!(p1 < 1.8, "order {p1}, errors {e1:?}");
    // Measured: about equal at H = 4e-3, 1.6× at 1e-3 and 3.9× at 5e-4.
    assert!(
        e1[2] > 1.3 * e2[2] && e1[3] > 3.0 * e2[3],
        "{e1:?} vs index 2 {e2:?}"
    );
}

#[test]
fn index3_with_linear_polynomials_is_detected_as_unstable() {
    for method in [VARIANTS[2].1, VARIANTS[5].1] {
        let err = run(&system(method, 1, 1e-3, 1.0)).unwrap_err();
        assert!(matches!(err, MasterError::Diverged { .. }), "{err}");
        eprintln!("{err}");
    }
}

#[test]
fn index1_is_stable_and_more_accurate_with_linear_polynomials() {
    for method in [VARIANTS[0].1, VARIANTS[3].1] {
        let e0 = errors(&run(&system(method, 0, 1e-3, 1.0)).unwrap());
        let e1 = errors(&run(&system(method, 1, 1e-3, 1.0)).unwrap());
        eprintln!("{method:?}: k = 0 {e0:?}, k = 1 {e1:?}");
        assert!(e1.state() < e0.state() / 10.0, "{method}: {e0:?} vs {e1:?}");
        assert!(e1.lambda < e0.lambda / 10.0, "{method}: {e0:?} vs {e1:?}");
    }
}

#[test]
fn call_counts_per_step_match_the_algorithm() {
    let steps = 50;
    let spec = system(VARIANTS[0].1, 0, 1e-3, steps as f64 * 1e-3);
    let mut sim = Simulation::new(&spec).unwrap();
    let stats = sim.run(&mut [], &mut |_, _| {}).unwrap();
    assert_eq!(stats.macro_steps, steps);
    for c in &stats.instances {
        // Predictor + one perturbed run + corrector; one state get; two sets.
        assert_eq!(c.do_steps, 3 * steps, "{c:?}");
        assert_eq!(c.state_gets, steps, "{c:?}");
        assert_eq!(c.state_sets, 2 * steps, "{c:?}");
    }
    assert_eq!(
        stats.jacobian_solves,
        steps + 2,
        "one per step plus two at T0"
    );
}

/// Phase times are taken only when asked, and asking changes no result.
#[test]
fn phases_are_timed_only_when_asked() {
    let spec = system(VARIANTS[0].1, 1, 1e-3, 0.2);
    let run = |timed: bool| {
        let mut sim = Simulation::new(&spec).unwrap();
        sim.time_phases(timed);
        let mut rec = MemoryRecorder::default();
        let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
        (rec, stats)
    };
    let (plain, untimed) = run(false);
    let (timed_rec, timed) = run(true);
    assert_eq!(plain.rows, timed_rec.rows, "timing changed the results");

    let t = untimed.times;
    assert!(!t.measured);
    let zero = std::time::Duration::ZERO;
    assert_eq!(
        [t.predictor, t.jacobian, t.solve, t.corrector, t.recording],
        [zero; 5]
    );
    assert!(t.setup > zero && untimed.wall > t.setup, "{untimed}");
    assert!(
        untimed.to_string().contains("(phases not timed)"),
        "{untimed}"
    );

    let t = timed.times;
    assert!(t.measured);
    for (name, phase) in [
        ("predictor", t.predictor),
        ("jacobian", t.jacobian),
        ("solve", t.solve),
        ("corrector", t.corrector),
        ("recording", t.recording),
    ] {
        assert!(phase > zero, "{name} not timed: {timed}");
    }
    let phases = t.setup + t.predictor + t.jacobian + t.solve + t.corrector + t.recording;
    assert!(
        phases <= timed.wall,
        "phases {phases:?} > wall {:?}",
        timed.wall
    );
    assert!(timed.to_string().contains("predictor"), "{timed}");
}

#[test]
fn explicit_method_converges_with_order_at_least_one() {
    let method = "kind = \"explicit\"\nmu = 1e-2";
    let (errs, p) = convergence(method, 0, &HS);
    eprintln!("explicit mu = 1e-2: errors {:?}, order {p:.2}", sci(&errs));
    assert!(p >= 0.9, "order {p}, errors {errs:?}");
    // The paper (Fig. 13): larger errors than the semi-implicit methods.
    let (implicit, _) = convergence(VARIANTS[1].1, 0, &HS);
    assert!(
        errs.iter().zip(&implicit).all(|(e, i)| e > i),
        "{errs:?} vs {implicit:?}"
    );
}

#[test]
fn method2_index3_equals_method1_index3() {
    let a = run(&system(VARIANTS[2].1, 0, 1e-3, 0.2)).unwrap();
    let b = run(&system(VARIANTS[5].1, 0, 1e-3, 0.2)).unwrap();
    let (xa, xb) = (a.series("mass1.x").unwrap(), b.series("mass1.x").unwrap());
    for (p, q) in xa.iter().zip(&xb) {
        assert!((p - q).abs() <= 1e-14 * p.abs().max(1.0));
    }
}

/// Two independent oscillator pairs in one system: a vector of two multipliers
/// whose perturbations share one run (they drive different instances), giving
/// the same numbers as each pair alone.
#[test]
fn several_constraints_share_perturbed_runs_and_match_single_pairs() {
    let single = system(VARIANTS[1].1, 0, 1e-3, 0.2);
    let mut text = toml_of(&single);
    // Append a second pair with its own names.
    let second: String = toml_of(&single)
        .split("[[instance]]")
        .skip(1)
        .map(|part| format!("[[instance]]{part}"))
        .collect::<String>()
        .replace("mass1", "pair2_m1")
        .replace("mass2", "pair2_m2")
        .replace("\"link\"", "\"link2\"");
    text.push_str(&second);
    let double = SystemSpec::from_toml(&text).unwrap();
    let mut sim = Simulation::new(&double).unwrap();
    let mut rec = MemoryRecorder::default();
    let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
    for c in &stats.instances {
        assert_eq!(
            c.do_steps,
            3 * 200,
            "one shared perturbed run per step: {c:?}"
        );
    }
    let alone = run(&single).unwrap();
    for (a, b) in [("mass1.x", "pair2_m1.x"), ("link.lambda", "link2.lambda")] {
        assert_eq!(rec.series(a).unwrap(), alone.series(a).unwrap());
        assert_eq!(rec.series(b).unwrap(), alone.series(a).unwrap());
    }
}

fn toml_of(spec: &SystemSpec) -> String {
    toml::to_string(spec).unwrap()
}

/// What the paper leaves open or states as "partly": measured at H = 1e-3.
#[test]
fn higher_degree_polynomials_at_h_1e_3() {
    for method in [VARIANTS[1].1, VARIANTS[4].1] {
        let err = run(&system(method, 1, 1e-3, 1.0)).unwrap_err();
        assert!(
            matches!(err, MasterError::Diverged { .. }),
            "index 2, k = 1: {err}"
        );
    }
    let e = errors(&run(&system(VARIANTS[0].1, 2, 1e-3, 1.0)).unwrap());
    eprintln!("baumgarte index 1, k = 2: {e:?}");
    assert!(e.state() < 1e-3, "{e:?}");
    let err = run(&system(VARIANTS[3].1, 2, 1e-3, 1.0)).unwrap_err();
    assert!(
        matches!(err, MasterError::Diverged { .. }),
        "weighted index 1, k = 2: {err}"
    );
}

/// An observer whose `finish` fails (as a results file on a full disk does).
struct FailsToFinish;

impl tether_master::Observer for FailsToFinish {
    fn start(&mut self, _columns: &[String]) -> std::io::Result<()> {
        Ok(())
    }
    fn sample(&mut self, _sample: tether_master::Sample<'_>) -> std::io::Result<()> {
        Ok(())
    }
    fn finish(&mut self, _failure: Option<&str>) -> std::io::Result<()> {
        Err(std::io::Error::other("disk full"))
    }
}

/// Counts rows and `finish` calls.
#[derive(Default)]
struct Counts {
    rows: usize,
    finished: usize,
}

impl tether_master::Observer for Counts {
    fn start(&mut self, _columns: &[String]) -> std::io::Result<()> {
        Ok(())
    }
    fn sample(&mut self, _sample: tether_master::Sample<'_>) -> std::io::Result<()> {
        self.rows += 1;
        Ok(())
    }
    fn finish(&mut self, _failure: Option<&str>) -> std::io::Result<()> {
        self.finished += 1;
        Ok(())
    }
}

/// When one observer cannot finish, the others after it are still finished,
/// the run reports the observer's error (naming its cause once), and the
/// run's statistics keep its wall time.
#[test]
fn a_failing_observer_does_not_keep_the_others_from_finishing() {
    let spec = system(
        "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6",
        0,
        1e-3,
        0.01,
    );
    let mut sim = Simulation::new(&spec).expect("simulation");
    let mut failing = FailsToFinish;
    let mut counts = Counts::default();
    let err = sim
        .run(&mut [&mut failing, &mut counts], &mut |_, _| {})
        .unwrap_err();
    assert!(matches!(err, MasterError::Recording(_)), "{err}");
    assert_eq!(err.to_string(), "recording results: disk full");
    assert!(
        std::error::Error::source(&err).is_none(),
        "the cause is printed once"
    );
    assert_eq!(counts.rows, 11, "the second observer saw every row");
    assert_eq!(counts.finished, 1, "and was finished");
    assert!(sim.stats().wall > std::time::Duration::ZERO);
}

/// The state error with `iterations` corrections per step (None: diverged).
fn iterated(method: &str, order: usize, iterations: usize) -> (Option<Errors>, f64) {
    let mut spec = system(method, order, 1e-3, 1.0);
    spec.coupling.iterations = iterations;
    let mut sim = Simulation::new(&spec).unwrap();
    let mut rec = MemoryRecorder::default();
    match sim.run(&mut [&mut rec], &mut |_, _| {}) {
        Ok(stats) => (
            Some(errors(&rec)),
            stats.corrections as f64 / stats.macro_steps as f64,
        ),
        Err(MasterError::Diverged { .. }) => (None, f64::NAN),
        Err(e) => panic!("{e}"),
    }
}

/// On the linear oscillator the interface Jacobian is exact, so one
/// correction already solves the linearised conditions: a second one changes
/// the errors only at rounding level, and it cannot cure the instability of
/// index 2 and 3 with k = 1 (it is the scheme's, not an unconverged solve's).
#[test]
fn iterated_correction_against_one_correction() {
    for (name, method) in VARIANTS {
        for order in [0, 1] {
            let one = iterated(method, order, 1);
            let two = iterated(method, order, 2);
            let five = iterated(method, order, 5);
            eprintln!("{name} k = {order}: 1 {one:?}\n    2 {two:?}\n    5 {five:?}");
            match (one.0, two.0, five.0) {
                (Some(e1), Some(e2), Some(e5)) => {
                    for e in [e2, e5] {
                        let close = |a: f64, b: f64| (a - b).abs() <= 1e-3 * b;
                        assert!(close(e.x, e1.x) && close(e.v, e1.v), "{name} k = {order}");
                        assert!(close(e.lambda, e1.lambda), "{name} k = {order}");
                    }
                    assert_eq!(two.1, 2.0, "{name} k = {order}");
                    assert!((2.0..3.0).contains(&five.1), "{name} k = {order}: {five:?}");
                }
                (None, None, None) => {
                    let index1 = name.ends_with('1');
                    assert!(order == 1 && !index1, "{name} k = {order} diverged");
                }
                _ => panic!("{name} k = {order}: {one:?} {two:?} {five:?}"),
            }
        }
    }
}

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
            y = std::array::from_fn(|i| y[i] + dt / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]));
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

/// "The tolerance is honoured": the global error against the closed form
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
