//! Every workspace FMU passes `fmpy validate` (the FMI 2.0 and 3.0 builds;
//! those of oscillator, link, body3d and lti with their model-exchange interface
//! beside co-simulation), and fmpy can simulate the oscillator (the reference
//! importer accepts what the kit exports; its model-exchange simulation:
//! crates/tether-cli/tests/kit_model_exchange.rs).

use std::ffi::OsStr;
use std::fs;

use tether_tests::fmpy::run_script;

#[test]
fn every_workspace_fmu_passes_fmpy_validate() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let fmus = tether_fmu_build::workspace_fmus().expect("packaging the workspace FMUs");
    assert!(!fmus.is_empty(), "no FMU under fmus/");
    let args: Vec<&OsStr> = fmus.iter().map(|p| p.as_os_str()).collect();
    let output = run_script("validate.py", &args).expect("running tests/fmpy/validate.py");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "fmpy validate failed:\n{stdout}\n{stderr}"
    );
    for fmu in &fmus {
        assert!(
            stdout.contains(&format!("{}: no problems found", fmu.display())),
            "{stdout}"
        );
    }
}

/// Damped free vibration from x = 0, v = v0: the closed form of m ẍ + d ẋ + c x = 0.
fn closed_form_position(t: f64) -> f64 {
    let (m, c, d, v0) = (1.0_f64, 1000.0_f64, 10.0_f64, 100.0_f64);
    let zeta_omega = d / (2.0 * m);
    let omega_d = (c / m - zeta_omega * zeta_omega).sqrt();
    (-zeta_omega * t).exp() * v0 / omega_d * (omega_d * t).sin()
}

fn simulate_oscillator(extra: &[&str]) -> Vec<(f64, f64)> {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("packaging the oscillator");
    simulate(&fmu, extra)
}

fn simulate(fmu: &std::path::Path, extra: &[&str]) -> Vec<(f64, f64)> {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("out.csv");
    let mut args: Vec<&OsStr> = vec![fmu.as_os_str(), csv.as_os_str()];
    let fixed = ["--stop", "1", "--step", "0.01"];
    args.extend(fixed.iter().chain(extra).map(OsStr::new));
    let output = run_script("simulate.py", &args).expect("running tests/fmpy/simulate.py");
    assert!(
        output.status.success(),
        "fmpy simulate failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("time,x,v,a"));
    lines
        .map(|line| {
            let cols: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
            (cols[0], cols[1])
        })
        .collect()
}

#[test]
fn fmpy_simulates_the_oscillator_on_its_closed_form() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    for mode in [&[][..], &["--set", "exact=true"][..]] {
        let rows = simulate_oscillator(mode);
        assert_eq!(rows.len(), 101, "{mode:?}");
        for (t, x) in rows {
            let error = (x - closed_form_position(t)).abs();
            assert!(
                error < 1e-8,
                "{mode:?}: x({t}) = {x}, closed form {}",
                closed_form_position(t)
            );
        }
    }
}

/// fmpy drives the FMI 3.0 build of the oscillator (its fmi3 functions, the same
/// model) to the values of the FMI 2.0 build, bit for bit, in both modes.
#[test]
fn fmpy_simulates_the_fmi3_oscillator_as_the_fmi2_one_bit_for_bit() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let fmu3 = tether_fmu_build::workspace_fmu3("oscillator").expect("packaging the oscillator");
    for mode in [&[][..], &["--set", "exact=true"][..]] {
        let fmi2 = simulate_oscillator(mode);
        let fmi3 = simulate(&fmu3, mode);
        assert_eq!(fmi2.len(), 101, "{mode:?}");
        assert_eq!(fmi2, fmi3, "{mode:?}");
    }
}
