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

/// The last row's time, if any.
fn last_time(csv: &Csv) -> f64 {
    csv.rows.last().map_or(f64::NAN, |r| r[0])
}

/// A segmentation fault inside `fmi2DoStep` at t = 0.5 kills the process (no
/// handler can save it in-process), but the header and the rows accepted up to
/// the last flush (FLUSH_INTERVAL, 0.2 s) are on disk: with each macro step
/// slowed to several milliseconds the 500 rows up to t = 0.5 take seconds, far
/// less than a block of rows (~740 for this width), so only the flushes by time
/// put them there. The bound is loose: rows up to t = 0.3 at least.
#[test]
fn a_segfault_keeps_the_rows_up_to_the_flush_interval() {
    use std::os::unix::process::ExitStatusExt;
    let s = Scratch::new();
    let sys = system(s.path(), 1, ", delay = 0.001");
    let out = s.run(&sys, "out.csv", &[]);
    assert_eq!(out.status.signal(), Some(11), "SIGSEGV; {}", stderr(&out));
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(csv.trailer, None);
    let t = last_time(&csv);
    assert!((0.3..0.5).contains(&t), "last row at t = {t}");
    assert_eq!(csv.rows.len() as f64 - 1.0, (t * 1000.0).round());
}

/// A full disk (here: a file size limit, `ulimit -f`, with SIGXFSZ ignored, so
/// writes fail with EFBIG as they would with ENOSPC, one of them halfway): the
/// run stops with an error naming the file, which is cut back to its last whole
/// row and, where the trailer still fits, ends with it.
#[test]
fn a_full_disk_leaves_only_whole_rows() {
    let s = Scratch::new();
    // The limit applies to every file, so the FMUs are unpacked beforehand.
    let text = std::fs::read_to_string(system(s.path(), 0, "")).unwrap();
    let mut unpacked = text.clone();
    for name in ["oscillator", "faults"] {
        let fmu = tether_fmu_build::workspace_fmu(name).unwrap();
        let dir = s.path().join(name);
        zip::ZipArchive::new(std::fs::File::open(&fmu).unwrap())
            .unwrap()
            .extract(&dir)
            .unwrap();
        unpacked = unpacked.replace(
            &format!("{:?}", fmu.display().to_string()),
            &format!("{:?}", dir.display().to_string()),
        );
    }
    assert_ne!(unpacked, text);
    let sys = s.path().join("unpacked.toml");
    std::fs::write(&sys, unpacked).unwrap();
    let out = Command::new("sh")
        .arg("-c")
        .arg("ulimit -f 16 && trap '' XFSZ && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_tether"))
        .args(["run", sys.to_str().unwrap(), "--out", "out.csv"])
        .current_dir(s.path())
        .env("TMPDIR", s.tmp())
        .output()
        .unwrap();
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    let last = text.lines().last().unwrap();
    assert!(last.starts_with("error: run stopped at t = "), "{last}");
    assert!(last.contains("cannot write out.csv"), "{last}");
    let csv = read_csv(&s.path().join("out.csv"));
    assert!(!csv.rows.is_empty());
    if let Some(trailer) = &csv.trailer {
        assert!(
            trailer.starts_with("# incomplete: cannot write the results: "),
            "{trailer}"
        );
    }
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}
