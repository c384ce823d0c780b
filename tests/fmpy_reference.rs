//! Tether against the fmpy reference (`tools/fmpy_reference`): the same system
//! file run by `tether_master` and by an independent Python implementation of
//! the same equations with fmpy as the FMI host (docs/validation.md).

use std::fs::File;
use std::path::{Path, PathBuf};

use tether_master::{CsvRecorder, Method, Simulation, SystemSpec};
use tether_tests::fmpy::workspace_root;

/// A result file: column names (after `time`), times, rows.
struct Results {
    names: Vec<String>,
    times: Vec<f64>,
    rows: Vec<Vec<f64>>,
    incomplete: bool,
}

fn read(path: &Path) -> Results {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = split_header(lines.next().unwrap());
    assert_eq!(header[0], "time");
    let (mut times, mut rows) = (Vec::new(), Vec::new());
    for line in lines {
        let mut values: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        times.push(values.remove(0));
        rows.push(values);
    }
    Results {
        names: header[1..].to_vec(),
        times,
        rows,
        incomplete: text.contains("\n# incomplete:"),
    }
}

/// The header's names; names with commas (`link1.A.R[1,2]`) are quoted.
fn split_header(line: &str) -> Vec<String> {
    let (mut names, mut name, mut quoted) = (Vec::new(), String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                name.push('"');
                chars.next();
            }
            '"' => quoted = !quoted,
            ',' if !quoted => names.push(std::mem::take(&mut name)),
            _ => name.push(c),
        }
    }
    names.push(name);
    names
}

/// Run `system` (a path from the workspace root) with tether (library) and
/// with the fmpy reference, both with `flags` (and `stop`, if given); return
/// both results. `python` has fmpy.
fn both(
    python: &Path,
    system: &str,
    method: Method,
    order: usize,
    stop: Option<f64>,
    flags: &[&str],
) -> (Results, Results) {
    for fmu in ["oscillator", "link", "body3d"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the workspace FMUs");
    }
    let root = workspace_root();
    let file = root.join(system);
    let dir = tempfile::tempdir().unwrap();
    let ours: PathBuf = dir.path().join("tether.csv");
    let theirs: PathBuf = dir.path().join("fmpy.csv");

    let mut spec = SystemSpec::from_file(&file).unwrap();
    spec.method = method;
    spec.coupling.order = order;
    if let Some(stop) = stop {
        spec.experiment.stop = stop;
    }
    let mut sim = Simulation::new(&spec).unwrap();
    let mut csv = CsvRecorder::new(File::create(&ours).unwrap());
    let outcome = sim.run(&mut [&mut csv], &mut |_, _| {});
    drop(csv);

    // The reference's own temporary directory: it must be empty afterwards
    // (fmpy unpacks each FMU into a new directory and leaves it there).
    let scratch = tempfile::tempdir().unwrap();
    let output = std::process::Command::new(python)
        .env("TMPDIR", scratch.path())
        .arg(root.join("tools").join("fmpy_reference"))
        .arg(&file)
        .args(flags)
        .args(
            stop.map(|t| ["--stop".to_string(), t.to_string()])
                .iter()
                .flatten(),
        )
        .args(["--order", &order.to_string(), "--quiet", "--out"])
        .arg(&theirs)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(
        output.status.success(),
        outcome.is_ok(),
        "both hosts complete or both stop: tether {outcome:?}, fmpy reference: {stderr}"
    );
    let left: Vec<_> = std::fs::read_dir(scratch.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        left.is_empty(),
        "the fmpy reference removes the FMUs it unpacked: {left:?} left in its TMPDIR"
    );
    (read(&ours), read(&theirs))
}

/// Max over rows of |a − b| / (max over rows of |a|, |b|), per column (the
/// measure of `tether compare`), and the column where it is largest.
fn worst(a: &Results, b: &Results, skip: &str) -> (f64, String) {
    assert_eq!(a.names, b.names, "same columns");
    assert_eq!(a.times, b.times, "same times");
    assert_eq!(a.incomplete, b.incomplete);
    let mut worst = (0.0, String::new());
    for (j, name) in a.names.iter().enumerate() {
        if name.ends_with(skip) {
            continue;
        }
        let (mut dev, mut scale) = (0.0f64, 0.0f64);
        for (ra, rb) in a.rows.iter().zip(&b.rows) {
            dev = dev.max((ra[j] - rb[j]).abs());
            scale = scale.max(ra[j].abs()).max(rb[j].abs());
        }
        let rel = if dev == 0.0 { 0.0 } else { dev / scale };
        if rel >= worst.0 {
            worst = (rel, name.clone());
        }
    }
    worst
}

#[test]
fn oscillator_agrees_with_the_fmpy_reference() {
    let Some(python) = tether_tests::tools::fmpy() else {
        return;
    };
    let variants: [(&str, Method, usize, &[&str]); 5] = [
        (
            "Method 1 index 1",
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            0,
            &["--beta", "2e-3", "--gamma", "1e-6"],
        ),
        (
            "Method 2 index 2",
            Method::Weighted { a: 1.0, b: 0.0 },
            0,
            &["--method", "weighted", "--a", "1"],
        ),
        (
            "Method 2 index 1, k = 1",
            Method::Weighted { a: 1.0, b: 1.0 },
            1,
            &["--method", "weighted", "--a", "1", "--b", "1"],
        ),
        (
            "explicit",
            Method::Explicit { mu: 1e-2 },
            0,
            &["--method", "explicit", "--mu", "1e-2"],
        ),
        (
            "Method 1 index 3, k = 1 (diverges)",
            Method::Baumgarte {
                beta: 0.0,
                gamma: 0.0,
            },
            1,
            &[],
        ),
    ];
    for (label, method, order, flags) in variants {
        let (a, b) = both(
            &python,
            "tests/validation/oscillator.toml",
            method,
            order,
            None,
            flags,
        );
        let (rel, column) = worst(&a, &b, "\u{0}");
        eprintln!(
            "{label}: {} rows, max relative deviation {rel:e} ({column})",
            a.times.len()
        );
        assert!(a.times.len() > 10, "{label}");
        assert!(rel <= 1e-9, "{label}: {column} deviates by {rel:e}");
    }
}

/// Two multipliers coupled through a shared instance: a 2x2 Jacobian with
/// off-diagonal entries. Both hosts solve it in the same operation order, so
/// they agree to the last bit (docs/validation.md).
#[test]
fn chain_of_three_masses_agrees_with_the_fmpy_reference() {
    let Some(python) = tether_tests::tools::fmpy() else {
        return;
    };
    let (a, b) = both(
        &python,
        "tests/validation/chain.toml",
        Method::Baumgarte {
            beta: 2e-3,
            gamma: 0.0,
        },
        0,
        None,
        &[],
    );
    let (rel, column) = worst(&a, &b, "\u{0}");
    eprintln!("chain, Method 1 index 2: max relative deviation {rel:e} ({column})");
    assert!(rel <= 1e-9, "{column} deviates by {rel:e}");
}

/// Joints between marker ports (force-port unknowns, ownerless multiplier
/// columns, port rows not stabilised), planar and 3D, over a short time.
#[test]
fn joints_agree_with_the_fmpy_reference() {
    let Some(python) = tether_tests::tools::fmpy() else {
        return;
    };
    let variants: [(&str, Method, &[&str], f64); 3] = [
        (
            "examples/double_pendulum.toml",
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            &["--beta", "2e-3", "--gamma", "1e-6"],
            0.1,
        ),
        (
            "examples/slider_crank.toml",
            Method::Weighted { a: 1.0, b: 0.0 },
            &["--method", "weighted", "--a", "1"],
            0.1,
        ),
        (
            "examples/3d_revolute.toml",
            Method::Baumgarte {
                beta: 1e-3,
                gamma: 0.0,
            },
            &["--beta", "1e-3", "--gamma", "0"],
            0.05,
        ),
    ];
    for (system, method, flags, stop) in variants {
        let (a, b) = both(&python, system, method, 0, Some(stop), flags);
        let (rel, column) = worst(&a, &b, "\u{0}");
        eprintln!(
            "{system}: {} rows, {} columns, max relative deviation {rel:e} ({column})",
            a.times.len(),
            a.names.len()
        );
        assert!(a.times.len() > 10 && !a.incomplete, "{system}");
        assert!(
            a.names.iter().any(|n| n.ends_with(".F[1]")),
            "{system}: force ports"
        );
        assert!(rel <= 1e-9, "{system}: {column} deviates by {rel:e}");
    }
}

/// The reference reads `[method]` (with or without `index`) into the same
/// weights as tether, and refuses the same contradictions with the same
/// words. Only the system-file reader runs: no fmpy needed.
#[test]
fn the_reference_reads_the_method_index_as_tether_does() {
    let reader = workspace_root().join("tools").join("fmpy_reference");
    let script = "import sys, tomllib; sys.path.insert(0, sys.argv[1]); import system\n\
                  from errors import RunError\n\
                  try:\n    m = system._method(tomllib.loads(sys.argv[2])['method'])\n    \
                  w = (m.beta, m.gamma) if m.kind == 'baumgarte' else (m.a, m.b)\n    \
                  print(repr(w[0]), repr(w[1]))\n\
                  except RunError as e:\n    print('error:', e)";
    let python = std::env::var_os("TETHER_PYTHON").unwrap_or_else(|| "python3".into());
    for table in [
        "kind = 'baumgarte'\nbeta = 2e-3",
        "kind = 'baumgarte'\nindex = 1",
        "kind = 'baumgarte'\nindex = 2",
        "kind = 'baumgarte'\nindex = 2\nbeta = 0.5",
        "kind = 'baumgarte'\nindex = 3",
        "kind = 'weighted'\nindex = 1",
        "kind = 'weighted'\nindex = 2",
        "kind = 'weighted'\nindex = 1\nb = 0.25",
        "kind = 'baumgarte'\nindex = 2\ngamma = 1e-6",
        "kind = 'weighted'\nindex = 3\na = 1.0",
        "kind = 'weighted'\nindex = 1\nb = 0.0",
        "kind = 'baumgarte'\nindex = 4",
    ] {
        let text = format!("[method]\n{table}\n");
        let ours = match toml::from_str::<toml::Table>(&text)
            .unwrap()
            .remove("method")
            .unwrap()
            .try_into::<Method>()
        {
            Ok(Method::Baumgarte { beta, gamma }) => format!("{beta:?} {gamma:?}"),
            Ok(Method::Weighted { a, b }) => format!("{a:?} {b:?}"),
            Ok(other) => panic!("{other}"),
            Err(e) => format!("error: {}", e.message()),
        };
        let out = std::process::Command::new(&python)
            .args(["-c", script])
            .arg(&reader)
            .arg(&text)
            .output()
            .expect("run python3");
        let theirs = String::from_utf8_lossy(&out.stdout).trim().to_string();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let numbers =
            |s: &str| -> Option<Vec<f64>> { s.split(' ').map(|w| w.parse().ok()).collect() };
        match (numbers(&ours), numbers(&theirs)) {
            (Some(a), Some(b)) => assert_eq!(a, b, "{table}"),
            _ => assert_eq!(ours, theirs, "{table}"),
        }
    }
}

/// FMI 3.0 FMUs (the workspace FMUs built as FMI 3.0, alone and mixed with FMI 2.0
/// in one system): the reference drives them through fmpy's FMU3Slave, and both
/// hosts agree to the last bit (validate.sh's `fmi3-*` variants), at k = 1 too,
/// where both hand the polynomial to the FMU through the intermediate update
/// callback.
#[test]
fn fmi3_builds_alone_and_mixed_with_fmi2_agree_with_the_fmpy_reference_exactly() {
    let Some(python) = tether_tests::tools::fmpy() else {
        return;
    };
    for fmu in ["oscillator", "link"] {
        tether_fmu_build::workspace_fmu3(fmu).expect("package the FMI 3.0 builds");
    }
    let index1 = Method::Baumgarte {
        beta: 2e-3,
        gamma: 1e-6,
    };
    for (system, stop, k) in [
        ("tests/validation/oscillator_fmi3.toml", None, 0),
        ("tests/validation/mixed_fmi3.toml", None, 0),
        ("tests/validation/double_pendulum_fmi3.toml", Some(0.05), 0),
        ("tests/validation/oscillator_fmi3.toml", None, 1),
        ("tests/validation/mixed_fmi3.toml", None, 1),
    ] {
        let flags = [
            "--method",
            "baumgarte",
            "--beta",
            "2e-3",
            "--gamma",
            "1e-6",
            "--order",
            if k == 0 { "0" } else { "1" },
        ];
        let (a, b) = both(&python, system, index1, k, stop, &flags);
        let (rel, column) = worst(&a, &b, "\u{0}");
        eprintln!(
            "{system} at k = {k}: {} rows, max relative deviation {rel:e} ({column})",
            a.times.len()
        );
        assert!(a.times.len() > 10, "{system}");
        assert!(rel == 0.0, "{system}: {column} deviates by {rel:e}");
    }
}

/// Model-exchange instances (`tests/validation/oscillator_me.toml`): Tether
/// integrates them with its rk45, the reference with fmpy's SUNDIALS CVode, both
/// at rtol 1e-12 and restarted at every step. Not bit for bit: within the
/// tolerances docs/validation.md ("Model-exchange instances") derives from the
/// two integrators' errors, the largest at index 3, the smallest for the
/// explicit method (no finite-difference Jacobian through the steps). The
/// residual `link.g` is bounded absolutely (metres), its own scale being
/// integration noise.
#[test]
fn model_exchange_instances_agree_with_the_fmpy_reference_within_the_integrators_tolerances() {
    let Some(python) = tether_tests::tools::fmpy() else {
        return;
    };
    let variants: [(&str, Method, usize, &[&str], f64); 4] = [
        (
            "Method 1 index 1",
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            0,
            &["--beta", "2e-3", "--gamma", "1e-6"],
            1e-5,
        ),
        (
            "Method 2 index 3",
            Method::Weighted { a: 0.0, b: 0.0 },
            0,
            &["--method", "weighted", "--a", "0", "--b", "0"],
            1e-4,
        ),
        (
            "Method 1 index 1, k = 1",
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            1,
            &["--beta", "2e-3", "--gamma", "1e-6"],
            1e-6,
        ),
        (
            "explicit",
            Method::Explicit { mu: 1e-2 },
            0,
            &["--method", "explicit", "--mu", "1e-2"],
            1e-8,
        ),
    ];
    for (label, method, order, flags, rtol) in variants {
        let (a, b) = both(
            &python,
            "tests/validation/oscillator_me.toml",
            method,
            order,
            None,
            flags,
        );
        let (rel, column) = worst(&a, &b, ".g");
        let g = a.names.iter().position(|n| n == "link.g").unwrap();
        let g_dev = a
            .rows
            .iter()
            .zip(&b.rows)
            .map(|(ra, rb)| (ra[g] - rb[g]).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "model exchange, {label}: {} rows, max relative deviation {rel:e} ({column}), \
             link.g within {g_dev:e}",
            a.times.len()
        );
        assert!(a.times.len() == 1001 && !a.incomplete, "{label}");
        // Two integrators: never the same bits.
        assert!(rel > 0.0, "{label}: the two integrators gave the same bits");
        assert!(
            rel <= rtol,
            "{label}: {column} deviates by {rel:e} (rtol {rtol:e})"
        );
        assert!(g_dev <= 1e-8, "{label}: link.g deviates by {g_dev:e}");
    }
}
