//! FMUs that crash, exit, hang or flood the log, in-process (docs/reliability.md):
//! the `faults` test FMU (fmus/faults) replaces mass 2 of examples/oscillator.toml
//! and misbehaves inside `fmi2DoStep` at t = 0.5. Each test runs the real `tether`
//! binary with its own `TMPDIR` inside a temporary directory, so nothing is left in
//! the real one.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The oscillator example with mass 2 replaced by the faults FMU in `mode`, with
/// `extra` parameters (`, delay = 0.001`), in `dir`.
fn system(dir: &Path, mode: i32, extra: &str) -> PathBuf {
    let oscillator = tether_fmu_build::workspace_fmu("oscillator").expect("oscillator FMU");
    let faults = tether_fmu_build::workspace_fmu("faults").expect("faults FMU");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("examples/oscillator.toml")).unwrap();
    let mass1 = "fmu = \"../target/fmus/oscillator.fmu\"\nparameters = { m = 1.0";
    let mass2 = "fmu = \"../target/fmus/oscillator.fmu\"\nparameters = { m = 2.0";
    assert!(
        text.contains(mass1) && text.contains(mass2),
        "example changed"
    );
    let text = text
        .replace(
            mass1,
            &format!(
                "fmu = {:?}\nparameters = {{ m = 1.0",
                oscillator.display().to_string()
            ),
        )
        .replace(
            mass2,
            &format!(
                "fmu = {:?}\nparameters = {{ mode = {mode}{extra}, m = 2.0",
                faults.display().to_string()
            ),
        );
    let path = dir.join(format!("faults{mode}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// A scratch directory for one test, with an empty `tmp/` for the runs' `TMPDIR`.
struct Scratch {
    dir: tempfile::TempDir,
}

impl Scratch {
    fn new() -> Scratch {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("tmp")).unwrap();
        Scratch { dir }
    }
    fn path(&self) -> &Path {
        self.dir.path()
    }
    fn tmp(&self) -> PathBuf {
        self.dir.path().join("tmp")
    }
    /// What the runs left in their `TMPDIR`.
    fn leftovers(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(self.tmp())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
    fn command(&self, args: &[&str]) -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_tether"));
        command
            .args(args)
            .current_dir(self.path())
            .env("TMPDIR", self.tmp())
            .env_remove("TETHER_LOG");
        command
    }
    fn run(&self, system: &Path, out: &str, extra: &[&str]) -> Output {
        let mut args = vec!["run", system.to_str().unwrap(), "--out", out];
        args.extend_from_slice(extra);
        self.command(&args).output().expect("run tether")
    }
}

/// The rows and the trailer of a results file; every row must be complete.
struct Csv {
    rows: Vec<Vec<f64>>,
    trailer: Option<String>,
}

fn read_csv(path: &Path) -> Csv {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "a cut line: {text:?}"
    );
    let mut lines = text.lines();
    let header = lines.next().expect("a header");
    assert!(header.starts_with("time,"), "{header}");
    let width = header.split(',').count();
    let mut rows = Vec::new();
    let mut trailer = None;
    for l in lines {
        assert!(trailer.is_none(), "a line after the trailer: {l}");
        if l.starts_with('#') {
            trailer = Some(l.to_string());
        } else {
            let row: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            assert_eq!(row.len(), width, "complete row {l}");
            rows.push(row);
        }
    }
    Csv { rows, trailer }
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// In mode 0 the faults FMU is the oscillator: the results are the same bytes.
#[test]
fn without_a_fault_the_results_are_the_oscillators() {
    let s = Scratch::new();
    let sys = system(s.path(), 0, "");
    let out = s.run(&sys, "faults.csv", &["--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let reference = s.command(&[
        "run",
        root.join("examples/oscillator.toml").to_str().unwrap(),
        "--out",
        "oscillator.csv",
        "--quiet",
    ]);
    let out = { reference }.output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let a = std::fs::read(s.path().join("faults.csv")).unwrap();
    let b = std::fs::read(s.path().join("oscillator.csv")).unwrap();
    assert!(a == b, "the faults FMU in mode 0 changes the results");
    let csv = read_csv(&s.path().join("faults.csv"));
    assert_eq!((csv.rows.len(), csv.trailer), (1001, None));
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}
