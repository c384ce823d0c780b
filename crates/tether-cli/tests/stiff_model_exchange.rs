//! A stiff model for the built-in integrator: the Reference FMU VanDerPol
//! (third-party, vendored in `tests/fixtures/reference-fmus`), FMI 2.0 and
//! 3.0, with μ = 1000, from x = (2, 0) over [0, 800] s, the slow branch up to
//! just before the first fast jump (t ≈ 807), where the Jacobian's eigenvalue
//! −μ·(x0² − 1) is down to −3000 s⁻¹. Model-exchange instances stepped at 1 s
//! with rtol 1e-8 (the experiment's tolerance), each method:
//!
//! - `bdf` and `esdirk` agree with fmpy's model-exchange run (CVode at rtol
//!   1e-10) to the bounds in [`BOUNDS`] (max |Δ| / peak over both states on
//!   the grid, about three times the measured);
//! - `bdf` takes far fewer derivative evaluations than `rk45`, whose step is
//!   held to about 1.6e-3 s by stability (the ratio is asserted, both counts
//!   printed);
//! - the Jacobian comes from the FMU's directional derivatives (VanDerPol
//!   declares `providesDirectionalDerivative(s)`): counted; with the flag
//!   removed from its model description the same run takes finite
//!   differences (no directional derivative, more derivative evaluations)
//!   and agrees with the first to [`FD_BOUND`].
//!
//! Measured, FMI 2.0 and 3.0 alike (fmpy 0.3.32):
//!
//! | method | max \|Δ\| / peak vs fmpy | derivative evaluations | directional derivatives |
//! | --- | --- | --- | --- |
//! | bdf | 2.1e-5 | 19,808 | 1,602 |
//! | bdf, finite differences | 2.1e-5 (9.8e-16 from bdf) | 22,211 | 0 |
//! | esdirk | 9.8e-6 | 21,396 | 1,600 |
//! | rk45 | 2.9e-6 | 2,632,176 (133 × bdf) | 0 |
//!
//! The largest deviation is in x1 (peak 6.2e-3), held to atol = rtol = 1e-8
//! absolutely; x0 agrees to 1.6e-7 of its peak with bdf.
//!
//! On the same model as shipped (μ = 1, not stiff) at 0.01 s steps rk45
//! takes the fewest evaluations, bdf the most (the second test).
//!
//! The calls are counted from the trace log every FMI call goes through
//! (`tether_fmi::call`), per instance name.
//!
//! Without fmpy the test is skipped with the reason printed, unless `CI` is
//! set: then it fails. Run with
//! `CI=true TETHER_PYTHON=/tmp/ci-venv/bin/python cargo test -p tether-cli --test stiff_model_exchange -- --nocapture`
//! to see the figures.

mod common;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Mutex;

use common::fmpy_model_exchange;
use tether_fmi::{Fmu, FmuInstance, Integrator, MeInstance, Method};

const MU: f64 = 1000.0;
const STOP: f64 = 800.0;
const STEP: f64 = 1.0;
const TOLERANCE: f64 = 1e-8;

/// The largest deviation from fmpy asserted (max |Δ| / peak), per method.
const BOUNDS: &[(Method, f64)] = &[(Method::Bdf, 6e-5), (Method::Esdirk, 3e-5)];

/// rk45's derivative evaluations at least this many times bdf's (measured
/// 133).
const RATIO: f64 = 50.0;

/// The largest deviation (max |Δ| / peak) of the finite-difference run from
/// the directional-derivative run: the Newton iteration converges to the same
/// point with either Jacobian, up to its own tolerance, far inside the
/// integrator's (measured 9.8e-16).
const FD_BOUND: f64 = 1e-9;

/// Counts the FMI calls of each (function, instance) from the trace log.
struct Counter(Mutex<HashMap<(String, String), u64>>);

/// Takes "function(instance" from a call's log line and stops there.
#[derive(Default)]
struct Head(String);

impl std::fmt::Write for Head {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        match s.find(')') {
            Some(end) => {
                self.0.push_str(&s[..end]);
                Err(std::fmt::Error)
            }
            None => {
                self.0.push_str(s);
                Ok(())
            }
        }
    }
}

impl log::Log for Counter {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.target() == "tether_fmi::call"
    }
    fn log(&self, record: &log::Record) {
        if record.target() != "tether_fmi::call" {
            return;
        }
        let mut head = Head::default();
        let _ = head.write_fmt(*record.args());
        if let Some((function, instance)) = head.0.split_once('(') {
            let mut counts = self.0.lock().unwrap_or_else(|e| e.into_inner());
            *counts
                .entry((function.to_owned(), instance.to_owned()))
                .or_default() += 1;
        }
    }
    fn flush(&self) {}
}

static COUNTER: std::sync::OnceLock<&'static Counter> = std::sync::OnceLock::new();

fn counter() -> &'static Counter {
    COUNTER.get_or_init(|| {
        let counter: &'static Counter = Box::leak(Box::new(Counter(Mutex::new(HashMap::new()))));
        log::set_logger(counter).expect("the only logger of this test binary");
        log::set_max_level(log::LevelFilter::Trace);
        counter
    })
}

/// The calls of `function` (either standard's name) on `instance`.
fn calls(instance: &str, functions: &[&str]) -> u64 {
    let counts = counter().0.lock().unwrap_or_else(|e| e.into_inner());
    functions
        .iter()
        .map(|f| {
            counts
                .get(&(f.to_string(), instance.to_owned()))
                .copied()
                .unwrap_or(0)
        })
        .sum()
}

const DERIVATIVES: &[&str] = &["fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives"];
const DIRECTIONAL: &[&str] = &[
    "fmi2GetDirectionalDerivative",
    "fmi3GetDirectionalDerivative",
];

/// One run of the stiff case: the grid (t, x0, x1).
fn run(fmu_path: &Path, name: &str, method: Method) -> Vec<[f64; 3]> {
    run_with(fmu_path, name, method, (MU, STOP, STEP))
}

/// One run with (μ, stop, step), instance `name`: the grid (t, x0, x1).
fn run_with(
    fmu_path: &Path,
    name: &str,
    method: Method,
    (mu_value, stop, step): (f64, f64, f64),
) -> Vec<[f64; 3]> {
    counter();
    let fmu = Fmu::open(fmu_path).unwrap();
    let md = fmu.model_description();
    let vr = |n: &str| md.value_reference(n).unwrap();
    let (x0, x1, mu) = (vr("x0"), vr("x1"), vr("mu"));
    let integrator = Integrator {
        method,
        ..Integrator::default()
    };
    let mut a = MeInstance::new(&fmu, name, Default::default(), integrator).unwrap();
    a.setup(Some(TOLERANCE), 0.0, Some(stop)).unwrap();
    a.enter_initialization().unwrap();
    a.set_reals(&[mu], &[mu_value]).unwrap();
    a.exit_initialization().unwrap();
    let steps = (stop / step).round() as u64;
    let mut rows = Vec::new();
    for n in 0..steps {
        a.step(n as f64 * step, step)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut out = [0.0; 2];
        a.get_reals(&[x0, x1], &mut out).unwrap();
        rows.push([(n + 1) as f64 * step, out[0], out[1]]);
    }
    a.terminate().unwrap();
    rows
}

/// max over the states of max |a − b| / peak |b| on the common grid.
fn deviation(ours: &[[f64; 3]], theirs: &[[f64; 3]]) -> f64 {
    let mut worst = 0.0f64;
    for column in 1..3 {
        let mut peak = 0.0f64;
        let mut largest = 0.0f64;
        let mut compared = 0;
        for a in ours {
            let Some(b) = theirs.iter().find(|b| (b[0] - a[0]).abs() <= 1e-9) else {
                continue;
            };
            compared += 1;
            peak = peak.max(b[column].abs());
            largest = largest.max((a[column] - b[column]).abs());
        }
        assert_eq!(compared, ours.len(), "every grid point compared");
        worst = worst.max(largest / peak);
    }
    worst
}

/// fmpy's model-exchange run (CVode, rtol 1e-10) on the same grid.
fn fmpy(fmu: &Path, dir: &Path, standard: &str) -> Vec<[f64; 3]> {
    let out_path = dir.join(format!("fmpy-{standard}.csv"));
    let mu = format!("mu={MU}");
    let (header, rows) = fmpy_model_exchange(fmu, &out_path, (0.0, STOP, STEP), &[&mu]);
    let column = |n: &str| header.iter().position(|h| h == n).unwrap();
    let (c0, c1) = (column("x0"), column("x1"));
    rows.iter().map(|r| [r[0], r[c0], r[c1]]).collect()
}

/// VanDerPol unpacked into `dir` with `providesDirectionalDerivative(s)`
/// taken out of its model description (its binary as shipped).
fn without_directional_derivatives(fmu: &Path, dir: &Path) -> std::path::PathBuf {
    let mut archive = zip::ZipArchive::new(std::fs::File::open(fmu).unwrap()).unwrap();
    archive.extract(dir).unwrap();
    let xml_path = dir.join("modelDescription.xml");
    let xml = std::fs::read_to_string(&xml_path).unwrap();
    let edited = xml
        .replace("providesDirectionalDerivatives=\"true\"", "")
        .replace("providesDirectionalDerivative=\"true\"", "");
    assert_ne!(xml, edited, "the flag was there");
    std::fs::write(&xml_path, edited).unwrap();
    dir.to_owned()
}

#[test]
fn bdf_and_esdirk_integrate_a_stiff_van_der_pol() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for standard in ["fmi2", "fmi3"] {
        let Some(fmu) =
            tether_fmu_build::fixture_fmu(&format!("reference-fmus/{standard}/VanDerPol.fmu"))
        else {
            return;
        };
        let theirs = fmpy(&fmu, dir.path(), standard);

        let mut evaluations = Vec::new();
        for method in [Method::Bdf, Method::Esdirk, Method::Rk45] {
            let name = format!("vdp-{standard}-{}", method.name());
            let ours = run(&fmu, &name, method);
            let worst = deviation(&ours, &theirs);
            let (n_f, n_j) = (calls(&name, DERIVATIVES), calls(&name, DIRECTIONAL));
            eprintln!(
                "{standard} {}: max |Δ|/peak = {worst:.1e} against fmpy, {n_f} derivative evaluations, {n_j} directional derivatives",
                method.name()
            );
            if let Some(&(_, bound)) = BOUNDS.iter().find(|(m, _)| *m == method) {
                assert!(
                    worst <= bound,
                    "{standard} {}: deviation {worst:e} > {bound:e}",
                    method.name()
                );
                assert!(
                    n_j > 0,
                    "{standard} {}: directional derivatives",
                    method.name()
                );
            }
            evaluations.push((n_f, ours));
        }
        let [(bdf, bdf_rows), _, (rk45, _)] = &evaluations[..] else {
            unreachable!("three methods run");
        };
        let ratio = *rk45 as f64 / *bdf as f64;
        eprintln!("{standard}: rk45 takes {ratio:.0} times bdf's derivative evaluations");
        assert!(ratio >= RATIO, "{standard}: rk45 {rk45} vs bdf {bdf}");

        // Finite differences where the FMU provides no directional derivatives.
        let unpacked = tempfile::tempdir().unwrap();
        let fd_fmu = without_directional_derivatives(&fmu, unpacked.path());
        let name = format!("vdp-{standard}-bdf-fd");
        let fd_rows = run(&fd_fmu, &name, Method::Bdf);
        let (n_f, n_j) = (calls(&name, DERIVATIVES), calls(&name, DIRECTIONAL));
        let worst = deviation(&fd_rows, bdf_rows);
        eprintln!(
            "{standard} bdf, finite differences: {n_f} derivative evaluations, {n_j} directional derivatives, max |Δ|/peak = {worst:.1e} against the directional derivatives' run, {:.1e} against fmpy",
            deviation(&fd_rows, &theirs)
        );
        assert_eq!(
            n_j, 0,
            "{standard}: no directional derivative without the flag"
        );
        assert!(
            n_f > *bdf,
            "{standard}: differences cost evaluations: {n_f} vs {bdf}"
        );
        assert!(
            fd_rows != *bdf_rows,
            "{standard}: another Jacobian, other bits"
        );
        assert!(worst <= FD_BOUND, "{standard}: {worst:e}");
    }
}

/// The other side of the trade: VanDerPol as shipped (μ = 1, not stiff) over
/// [0, 20] s in 2,000 steps of 0.01 s at rtol 1e-8. Each step restarts the
/// integrator, bdf at order 1 with a fresh Jacobian, so here rk45 takes the
/// fewest derivative evaluations (measured, FMI 3.0: bdf 58,606, esdirk
/// 32,979, each with 4,000 directional derivatives, rk45 25,362).
#[test]
fn rk45_takes_fewer_evaluations_on_a_non_stiff_van_der_pol() {
    let Some(fmu) = tether_fmu_build::fixture_fmu("reference-fmus/fmi3/VanDerPol.fmu") else {
        return;
    };
    let mut counts = Vec::new();
    for method in [Method::Bdf, Method::Esdirk, Method::Rk45] {
        let name = format!("vdp-non-stiff-{}", method.name());
        run_with(&fmu, &name, method, (1.0, 20.0, 0.01));
        let (n_f, n_j) = (calls(&name, DERIVATIVES), calls(&name, DIRECTIONAL));
        eprintln!(
            "non-stiff {}: {n_f} derivative evaluations, {n_j} directional derivatives",
            method.name()
        );
        counts.push(n_f);
    }
    let [bdf, esdirk, rk45] = counts[..] else {
        unreachable!("three methods run");
    };
    assert!(rk45 < esdirk && esdirk < bdf, "{counts:?}");
}
