//! OSP's quarter truck (third-party FMUs made by OSP's C++ FMU tooling,
//! vendored in tests/fixtures/third-party-fmus/osp-quarter-truck) run by
//! libcosim (through libcosimpy) and by Tether from the same SSD
//! (tests/fixtures/ssp/quarter_truck): `chassis.velocity → wheel.in_vel`,
//! `wheel.out_spring_damper_f → chassis.force`, Euler inside at 1e-5, both
//! with libcosim's fixed-step (Jacobi) algorithm, compared on every output
//! of both FMUs at every communication point.
//!
//! The masters differ in one thing: the time arguments of `fmi2DoStep`.
//! libcosim counts time in integer nanoseconds and passes t_n = n·H_ns/1e9
//! and h = t_{n+1} − t_n; Tether passes t_n = T_0 + n·H and h = H. At
//! H = 1e-4 (the macro step of OSP's annotation in the SSD) these differ in
//! the last bits for some n, and the FMUs' Euler steps carry the difference:
//! the outputs agree to 6.5e-12·max(1, |b|), not 1e-12, the first point
//! beyond 1e-12 at t = 0.0585. FMPy driving the FMUs with each master's
//! time arguments (tests/libcosim/quarter_truck_fmpy.py) reproduces each
//! master bit for bit, so the difference is the time arguments alone. At
//! H = 2^-9 s (1 953 125 ns, exact in both) the time arguments are the
//! same and so are the results: |a − b| ≤ 1e-12·max(1, |b|) (measured 0).
//!
//! Needs `libcosimpy` and `fmpy` in the test Python (as tests/libcosim_ssp.rs).

use std::path::{Path, PathBuf};
use std::process::Command;

use tether_tests::fmpy::workspace_root;

/// Every output of both FMUs (all Real).
const COLUMNS: [&str; 8] = [
    "chassis.acceleration",
    "chassis.position",
    "chassis.velocity",
    "wheel.acceleration",
    "wheel.out_spring_damper_f",
    "wheel.out_tire_f",
    "wheel.position",
    "wheel.velocity",
];

/// The macro step of OSP's annotation in the SSD.
const H: f64 = 1e-4;
const STOP: f64 = 1.0;

/// The SSD with the FMUs copied into `dir`, as libcosim reads an unpacked SSP.
fn unpacked(dir: &Path) -> Option<PathBuf> {
    let fmus = ["Chassis", "Wheel"].map(|m| {
        tether_fmu_build::fixture_fmu(&format!("third-party-fmus/osp-quarter-truck/{m}.fmu"))
    });
    let src = workspace_root().join("tests/fixtures/ssp/quarter_truck/SystemStructure.ssd");
    std::fs::create_dir(dir.join("resources")).unwrap();
    std::fs::copy(src, dir.join("SystemStructure.ssd")).unwrap();
    for (name, fmu) in ["Chassis", "Wheel"].iter().zip(fmus) {
        std::fs::copy(fmu?, dir.join(format!("resources/{name}.fmu"))).unwrap();
    }
    Some(dir.to_path_buf())
}

/// Rows of `time` and `COLUMNS` after every step, from a script's CSV.
fn rows(out: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(out).unwrap();
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

fn python(python: &Path, script: &str, args: &[String]) {
    let output = Command::new(python)
        .arg(workspace_root().join("tests/libcosim").join(script))
        .args(args)
        .args(COLUMNS)
        .output()
        .expect("run python");
    assert!(
        output.status.success(),
        "{script} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// libcosim's rows after every step: `step` is its step argument (`ssp:H`
/// leaves it to the SSD's OSP annotation).
fn libcosim(py: &Path, ssp_dir: &Path, step: &str) -> Vec<Vec<f64>> {
    let out = ssp_dir.join("libcosim.csv");
    let args = [
        ssp_dir.display().to_string(),
        step.into(),
        STOP.to_string(),
        out.display().to_string(),
    ];
    python(py, "run_ssp.py", &args);
    rows(&out)
}

/// FMPy's rows, with the `fmi2DoStep` time arguments of `times`
/// (`libcosim` or `tether`).
fn fmpy(py: &Path, ssp_dir: &Path, h: f64, times: &str) -> Vec<Vec<f64>> {
    let out = ssp_dir.join(format!("fmpy-{times}.csv"));
    let args = [
        ssp_dir.join("resources").display().to_string(),
        h.to_string(),
        STOP.to_string(),
        times.into(),
        out.display().to_string(),
    ];
    python(py, "quarter_truck_fmpy.py", &args);
    rows(&out)
}

/// Tether's rows after every step, from the SSD (`step` overriding its
/// annotation's).
fn tether(ssp_dir: &Path, step: Option<f64>) -> Vec<Vec<f64>> {
    let read = tether_ssp::read(ssp_dir, step, None).unwrap();
    tether_tests::tools::tether_rows(&read.spec, &COLUMNS)
}

/// The largest |a − b| / max(1, |b|) over every output and point, the
/// communication times checked equal (within 1e-12 s), and the first point
/// where it exceeds 1e-12.
fn compare(ours: &[Vec<f64>], theirs: &[Vec<f64>]) -> (f64, Option<f64>) {
    assert_eq!(ours.len(), theirs.len(), "communication points");
    let (mut worst, mut first): (f64, Option<f64>) = (0.0, None);
    let mut largest: f64 = 0.0;
    for (a, b) in ours.iter().zip(theirs) {
        assert!((a[0] - b[0]).abs() <= 1e-12, "time {} vs {}", a[0], b[0]);
        for (x, y) in a[1..].iter().zip(&b[1..]) {
            let rel = (x - y).abs() / y.abs().max(1.0);
            assert!(rel.is_finite(), "t = {}: {x} vs {y}", a[0]);
            if rel > 1e-12 && first.is_none() {
                first = Some(a[0]);
            }
            worst = worst.max(rel);
            largest = largest.max(y.abs());
        }
    }
    // Not a trivial run: the truck moves.
    assert!(largest > 1.0, "largest |output| {largest}");
    (worst, first)
}

fn same_bits(a: &[Vec<f64>], b: &[Vec<f64>]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x[1..]
                .iter()
                .zip(&y[1..])
                .all(|(p, q)| p.to_bits() == q.to_bits())
        })
}

/// H = 1e-4 from the SSD's OSP annotation (no step given to either master).
#[test]
fn libcosim_and_tether_agree_on_the_quarter_truck() {
    let Some(py) = tether_tests::tools::libcosimpy() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let Some(ssp) = unpacked(dir.path()) else {
        return;
    };
    let theirs = libcosim(&py, &ssp, &format!("ssp:{H}"));
    assert_eq!(
        tether_ssp::read(&ssp, None, None)
            .unwrap()
            .spec
            .experiment
            .step,
        H,
        "the macro step of OSP's annotation"
    );
    let ours = tether(&ssp, None);
    assert_eq!(theirs.len(), 10_000);
    let (worst, first) = compare(&ours, &theirs);
    println!(
        "quarter truck, H = 1e-4, 10000 points, 8 outputs: largest |a - b| / max(1, |b|) = {worst:.1e}, \
         first above 1e-12 at t = {first:?}"
    );
    assert!(worst <= 1e-11, "{worst:e}");
    // The difference is the fmi2DoStep time arguments alone: FMPy with each
    // master's reproduces that master bit for bit.
    assert!(same_bits(&fmpy(&py, &ssp, H, "libcosim"), &theirs));
    assert!(same_bits(&fmpy(&py, &ssp, H, "tether"), &ours));
}

/// H = 2^-9 s: the same time arguments in both masters, the same results.
#[test]
fn at_a_step_exact_in_both_masters_libcosim_and_tether_agree_to_1e_12() {
    let Some(py) = tether_tests::tools::libcosimpy() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let Some(ssp) = unpacked(dir.path()) else {
        return;
    };
    let h = 1.0 / 512.0;
    let theirs = libcosim(&py, &ssp, &h.to_string());
    let ours = tether(&ssp, Some(h));
    assert_eq!(theirs.len(), 512);
    let (worst, first) = compare(&ours, &theirs);
    println!("quarter truck, H = 2^-9, 512 points, 8 outputs: largest |a - b| / max(1, |b|) = {worst:.1e}");
    assert!(
        worst <= 1e-12 && first.is_none(),
        "{worst:e} first at {first:?}"
    );
}

/// Per-instance steps against libcosim's decimation: the wheel with OSP's
/// `StepSizeHint` of n·H (n = 2 and 3; H = 2^-9 s, the same time arguments
/// in both masters) steps every n-th macro step in both, its inputs taken
/// at its own communication points and its outputs held for the chassis in
/// between: the same results (docs/system-file.md "Per-instance steps").
#[test]
fn the_wheel_at_its_own_step_agrees_with_libcosims_decimation() {
    let Some(py) = tether_tests::tools::libcosimpy() else {
        return;
    };
    let h = 1.0 / 512.0;
    for n in [2u32, 3] {
        let dir = tempfile::tempdir().unwrap();
        let Some(ssp) = unpacked(dir.path()) else {
            return;
        };
        let ssd = ssp.join("SystemStructure.ssd");
        let hint = f64::from(n) * h;
        let text = std::fs::read_to_string(&ssd).unwrap().replacen(
            r#"</ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>"#,
            &format!(
                r#"</ssd:ParameterBindings>
        <ssd:Annotations>
          <ssc:Annotation type="com.opensimulationplatform">
            <osp:StepSizeHint value="{hint:?}"/>
          </ssc:Annotation>
        </ssd:Annotations>
      </ssd:Component>
    </ssd:Elements>"#
            ),
            1,
        );
        std::fs::write(&ssd, text).unwrap();
        let read = tether_ssp::read(&ssp, Some(h), None).unwrap();
        let wheel = read
            .spec
            .instances
            .iter()
            .find(|i| i.name == "wheel")
            .unwrap();
        assert_eq!(wheel.step, Some(hint));
        let theirs = libcosim(&py, &ssp, &h.to_string());
        let ours = tether(&ssp, Some(h));
        let (worst, first) = compare(&ours, &theirs);
        println!(
            "quarter truck, wheel at {n}·H, H = 2^-9: largest |a - b| / max(1, |b|) = {worst:.1e}"
        );
        assert!(
            worst <= 1e-12 && first.is_none(),
            "n = {n}: {worst:e} first at {first:?}"
        );
        // Held between its communication points: the wheel's outputs change
        // only at multiples of n·H.
        let column = 1 + COLUMNS.iter().position(|c| *c == "wheel.position").unwrap();
        for (j, pair) in ours.windows(2).enumerate() {
            let step = j as u32 + 2; // the second row's index on the grid
            if !step.is_multiple_of(n) {
                assert_eq!(pair[0][column], pair[1][column], "row {step}");
            }
        }
    }
}
