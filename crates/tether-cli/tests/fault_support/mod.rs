//! What the fault tests (faults.rs in process, isolation.rs isolated) share: the
//! oscillator example with mass 2 replaced by the faults FMU, a scratch folder
//! with its own `TMPDIR`, the results file's rows and trailer, and the
//! processes a run left.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The oscillator example with mass 2 replaced by the faults FMU in `mode`, with
/// `extra` parameters (`, delay = 0.001`), in `dir`.
pub fn system(dir: &Path, mode: i32, extra: &str) -> PathBuf {
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
pub struct Scratch {
    pub dir: tempfile::TempDir,
}

impl Scratch {
    pub fn new() -> Scratch {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("tmp")).unwrap();
        Scratch { dir }
    }
    pub fn path(&self) -> &Path {
        self.dir.path()
    }
    pub fn tmp(&self) -> PathBuf {
        self.dir.path().join("tmp")
    }
    /// What the runs left in their `TMPDIR`.
    pub fn leftovers(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(self.tmp())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
    pub fn command(&self, args: &[&str]) -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_tether"));
        command
            .args(args)
            .current_dir(self.path())
            .env("TMPDIR", self.tmp())
            .env_remove("TETHER_LOG");
        command
    }
    pub fn run(&self, system: &Path, out: &str, extra: &[&str]) -> Output {
        let mut args = vec!["run", system.to_str().unwrap(), "--out", out];
        args.extend_from_slice(extra);
        self.command(&args).output().expect("run tether")
    }
}

/// The rows and the trailer of a results file; every row must be complete.
pub struct Csv {
    pub rows: Vec<Vec<f64>>,
    pub trailer: Option<String>,
}

pub fn read_csv(path: &Path) -> Csv {
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

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The last row's time, if any.
pub fn last_time(csv: &Csv) -> f64 {
    csv.rows.last().map_or(f64::NAN, |r| r[0])
}

/// The processes (pid, command line) with this scratch's `TMPDIR` in their
/// environment: the runs' and their hosts'.
pub fn processes(s: &Scratch) -> Vec<(i32, String)> {
    let needle = format!("TMPDIR={}", s.tmp().display());
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Some(pid) = entry.file_name().to_str().and_then(|p| p.parse().ok()) else {
            continue;
        };
        let environ = std::fs::read(entry.path().join("environ")).unwrap_or_default();
        if environ.split(|b| *b == 0).any(|v| v == needle.as_bytes()) {
            let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
            found.push((pid, String::from_utf8_lossy(&cmdline).replace('\0', " ")));
        }
    }
    found
}

/// The processes still running (a host of an isolated instance left behind).
pub fn processes_left(s: &Scratch) -> Vec<String> {
    processes(s)
        .into_iter()
        .map(|(_, cmdline)| cmdline)
        .collect()
}

/// Waits until the row at t = 0.5 is on disk (rows reach it within the flush
/// interval, also while the run is stuck in the step after it).
pub fn wait_for_the_row_at_0_5(s: &Scratch) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !std::fs::read_to_string(s.path().join("out.csv"))
        .unwrap_or_default()
        .lines()
        .any(|l| l.starts_with("0.5,"))
    {
        assert!(std::time::Instant::now() < deadline, "no rows");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Runs `tether run` on `system` into out.csv with `flags`, standard error into
/// a file (not a pipe: a process the FMU left behind would hold a pipe open and
/// the wait would measure it, not the run); the exit status, the stderr text and
/// the wall time.
pub fn run_to_exit(
    s: &Scratch,
    system: &Path,
    flags: &[&str],
) -> (std::process::ExitStatus, String, std::time::Duration) {
    let log = s.path().join("stderr.txt");
    let mut args = vec!["run", system.to_str().unwrap(), "--out", "out.csv"];
    args.extend_from_slice(flags);
    let start = std::time::Instant::now();
    let status = s
        .command(&args)
        .stderr(std::fs::File::create(&log).unwrap())
        .status()
        .unwrap();
    let elapsed = start.elapsed();
    (status, std::fs::read_to_string(&log).unwrap(), elapsed)
}

/// The helper of mode 8 and the lingering child of mode 10 sleep 15 s: a run
/// that waited for them would take that long.
pub const NO_STALL: std::time::Duration = std::time::Duration::from_secs(12);

/// Kills the processes still running with this scratch's `TMPDIR` (what an
/// in-process FMU started outlives a crash of `tether`).
pub fn kill_leftover_processes(s: &Scratch) {
    for (pid, _) in processes(s) {
        // SAFETY: a signal to a process of this test's own scratch runs.
        unsafe { libc::kill(pid, libc::SIGKILL) };
    }
}

/// Waits for `child` up to `secs` seconds (killed and reaped after that, or
/// when the test fails) and returns its output.
pub fn wait_within(child: std::process::Child, secs: u64) -> Output {
    let pid = child.id() as i32;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(std::time::Duration::from_secs(secs)) {
        Ok(out) => out.unwrap(),
        Err(_) => {
            // SAFETY: a signal to the child this test started (not yet reaped:
            // the waiting thread has not returned).
            unsafe { libc::kill(pid, libc::SIGKILL) };
            panic!("tether did not end within {secs} s");
        }
    }
}

/// Starts a run of the faults FMU in mode 7 (from t = 0.5 every fmi2DoStep
/// sleeps 10 ms) writing `out`, and waits for the row at t = 0.5 in `watched`.
pub fn slow_run(s: &Scratch, out: &str) -> std::process::Child {
    let sys = system(s.path(), 7, ", pause = 0.01");
    let child = s
        .command(&["run", sys.to_str().unwrap(), "--out", out, "--quiet"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !std::fs::read_to_string(s.path().join(out))
        .unwrap_or_default()
        .lines()
        .any(|l| l.starts_with("0.5,"))
    {
        assert!(std::time::Instant::now() < deadline, "no rows");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child
}
