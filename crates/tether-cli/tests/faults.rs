//! FMUs that crash, exit, hang or flood the log, in-process (docs/reliability.md):
//! the `faults` test FMU (fmus/faults) replaces mass 2 of examples/oscillator.toml
//! and misbehaves inside `fmi2DoStep` at t = 0.5. Each test runs the real `tether`
//! binary with its own `TMPDIR` inside a temporary directory, so nothing is left in
//! the real one.

mod fault_support;

use std::path::Path;
use std::process::{Command, Output};

use fault_support::*;

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

/// An FMU library that stays loaded and aborts in its destructor at process
/// exit (mode 15, as pythonfmu3's runtime may after a finished run): the run
/// and its host processes end once every instance is freed and every file
/// written, without the libraries' teardown, so a finished run exits 0 with the
/// same results as mode 0; in process and isolated.
#[test]
fn an_fmu_that_aborts_at_process_exit_does_not_fail_a_finished_run() {
    let s = Scratch::new();
    let clean = s.run(&system(s.path(), 0, ""), "clean.csv", &["--quiet"]);
    assert!(clean.status.success(), "{}", stderr(&clean));
    for isolate in [false, true] {
        let sys = system(s.path(), 15, "");
        let flags: &[&str] = if isolate {
            &["--quiet", "--isolate"]
        } else {
            &["--quiet"]
        };
        let out = s.run(&sys, "out.csv", flags);
        assert_eq!(
            out.status.code(),
            Some(0),
            "isolate {isolate}: {}",
            stderr(&out)
        );
        assert_eq!(stderr(&out), "", "isolate {isolate}");
        let a = std::fs::read(s.path().join("out.csv")).unwrap();
        let b = std::fs::read(s.path().join("clean.csv")).unwrap();
        assert!(a == b, "isolate {isolate}: mode 15 changes the results");
    }
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
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

/// A full disk (here: a file size limit, `ulimit -f`; `tether` ignores
/// SIGXFSZ, so writes fail with EFBIG as they would with ENOSPC, one of them
/// halfway): the run stops with an error naming the file, which is cut back to
/// its last whole row and, where the trailer still fits, ends with it. In a
/// plain shell (SIGXFSZ at its default, which kills) and in one that ignores it.
#[test]
fn a_full_disk_leaves_only_whole_rows() {
    for shell in [
        "ulimit -f 16 && exec \"$0\" \"$@\"",
        "ulimit -f 16 && trap '' XFSZ && exec \"$0\" \"$@\"",
    ] {
        full_disk(shell);
    }
}

fn full_disk(shell: &str) {
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
        .arg(shell)
        .arg(env!("CARGO_BIN_EXE_tether"))
        .args(["run", sys.to_str().unwrap(), "--out", "out.csv"])
        .current_dir(s.path())
        .env("TMPDIR", s.tmp())
        .output()
        .unwrap();
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{shell}: {out:?}");
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

/// The one-line error of a run that an FMU ended from inside `fmi2DoStep` at
/// t = 0.5, and its results: every row up to t = 0.5 and the trailer naming the
/// instance, the call and what it called; the extraction folders are removed.
fn ended_inside_the_fmu(s: &Scratch, out: &Output, called: &str) {
    let text = stderr(out);
    assert!(!text.contains("panicked"), "{text}");
    let reason = format!("FMU instance 'mass2' called {called} inside fmi2DoStep at t=0.5");
    let last = text.lines().last().unwrap_or_default();
    assert_eq!(
        last,
        format!("error: run stopped; results so far kept in out.csv (marked incomplete): {reason}")
    );
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
    assert_eq!(csv.rows.len(), 501, "t = 0 … 0.5");
    assert_eq!(last_time(&csv), 0.5);
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}

/// `exit(0)` inside an FMU is an error, not a success with an empty CSV.
#[test]
fn exit_0_inside_an_fmu_is_an_error() {
    let s = Scratch::new();
    let out = s.run(&system(s.path(), 3, ""), "out.csv", &["--quiet"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    ended_inside_the_fmu(&s, &out, "exit(0)");
}

#[test]
fn exit_3_inside_an_fmu_is_an_error() {
    let s = Scratch::new();
    let out = s.run(&system(s.path(), 4, ""), "out.csv", &[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    ended_inside_the_fmu(&s, &out, "exit(3)");
}

/// `abort()`: the file is marked, then the process ends by SIGABRT as before.
#[test]
fn abort_inside_an_fmu_is_an_error() {
    use std::os::unix::process::ExitStatusExt;
    let s = Scratch::new();
    let out = s.run(&system(s.path(), 2, ""), "out.csv", &[]);
    assert_eq!(out.status.signal(), Some(6), "{}", stderr(&out));
    ended_inside_the_fmu(&s, &out, "abort()");
}

/// `tether simulate` of the faults FMU alone is guarded the same way.
#[test]
fn exit_inside_a_simulated_fmu_is_an_error() {
    let s = Scratch::new();
    let fmu = tether_fmu_build::workspace_fmu("faults").unwrap();
    let out = s
        .command(&[
            "simulate",
            fmu.to_str().unwrap(),
            "--set",
            "mode=3",
            "--out",
            "out.csv",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(
        csv.trailer.as_deref(),
        Some("# incomplete: FMU instance 'faults' called exit(0) inside fmi2DoStep at t=0.5")
    );
    assert_eq!(last_time(&csv), 0.5);
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}

/// A child process killed (SIGKILL) and reaped when dropped, also when a test fails.
struct Killed(std::process::Child);

impl Killed {
    fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for Killed {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Extraction folders are private (0700) and locked while in use; those of a
/// run that died (here: SIGKILL while an FMU sleeps in `fmi2DoStep`) are swept
/// by the next run, while the folder of a run still going is left alone.
#[test]
fn folders_of_killed_runs_are_swept_by_the_next_run() {
    use std::os::unix::fs::PermissionsExt;
    let s = Scratch::new();
    // Mode 7: from t = 0.5 every fmi2DoStep sleeps 1 s: the runs stay alive.
    let slow = system(s.path(), 7, "");
    let start = |out: &str| {
        Killed(
            s.command(&["run", slow.to_str().unwrap(), "--out", out])
                .stderr(std::process::Stdio::null())
                .spawn()
                .unwrap(),
        )
    };
    // Folders set up: locked and marked (`.tether-lock`). A run killed between
    // creating a folder and marking it leaves a folder the sweep cannot tell
    // from one still being set up, which it leaves alone.
    let marked = || {
        s.leftovers()
            .iter()
            .filter(|name| s.tmp().join(name).join(".tether-lock").exists())
            .count()
    };
    let wait_for = |count: usize| {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        while marked() < count {
            assert!(std::time::Instant::now() < deadline, "{:?}", s.leftovers());
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    };
    let mut killed = start("killed.csv");
    wait_for(2); // oscillator and faults
    let folders = s.leftovers();
    for name in &folders {
        let mode = std::fs::metadata(s.tmp().join(name))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o700, "{name}");
    }
    killed.kill();
    assert_eq!(s.leftovers(), folders, "SIGKILL leaves the folders");
    let mut alive = start("alive.csv");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let swept = |now: &[String]| now.len() == 2 && !now.iter().any(|f| folders.contains(f));
    while !swept(&s.leftovers()) {
        assert!(
            std::time::Instant::now() < deadline,
            "not swept: {:?}",
            s.leftovers()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // A third run sweeps nothing of the live one's.
    let out = s.run(&system(s.path(), 0, ""), "third.csv", &["-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(s.leftovers().len(), 2, "{:?}", s.leftovers());
    alive.kill();
}

/// A log flood (2000 warnings per `fmi2DoStep` from t = 0.5, about three million
/// in all): 20 messages a second per instance and category are shown and the
/// rest counted, without being formatted; `--quiet` silences FMU warnings.
#[test]
fn a_log_flood_is_rate_limited() {
    let s = Scratch::new();
    let timed = |sys: &Path, extra: &[&str]| {
        let start = std::time::Instant::now();
        let out = s.run(sys, "out.csv", extra);
        assert!(out.status.success(), "{}", stderr(&out));
        (out, start.elapsed())
    };
    let (_, normal) = timed(&system(s.path(), 0, ""), &[]);
    let flood = system(s.path(), 6, "");
    let (out, flooded) = timed(&flood, &[]);
    let text = stderr(&out);
    assert!(text.len() < 16 << 10, "{} bytes on stderr", text.len());
    assert!(text.contains("[WARN  fmu::mass2] [logStatusWarning] flood message 0 at t = 0.5"));
    assert!(
        text.contains("more messages suppressed (more than 20 in 1 s; --fmu-log-limit)"),
        "{text}"
    );
    // Loose (a loaded machine): the flood must not multiply the run time.
    assert!(
        flooded < normal * 10 + std::time::Duration::from_secs(10),
        "{flooded:?} against {normal:?}"
    );
    let (out, _) = timed(&flood, &["--quiet"]);
    assert_eq!(stderr(&out), "", "--quiet");
    assert_eq!(read_csv(&s.path().join("out.csv")).rows.len(), 1001);
}

/// FMU log lines written on a worker thread are whole and name their
/// instance: mass 2 logs 5 warnings per `fmi2DoStep` from t = 0.5 on the one
/// worker (mass 1 marked `parallel = false` stays on the main thread), every
/// one shown.
#[test]
fn log_lines_from_a_worker_thread_are_whole_and_named() {
    let s = Scratch::new();
    let sys = system(s.path(), 6, ", flood = 5");
    let text = std::fs::read_to_string(&sys).unwrap();
    let marked = text.replacen("name = \"mass1\"", "name = \"mass1\"\nparallel = false", 1);
    std::fs::write(&sys, marked).unwrap();
    let args = [
        "--parallel",
        "on",
        "--threads",
        "2",
        "--fmu-log-limit",
        "off",
        "--stop",
        "0.6",
    ];
    let out = s.run(&sys, "out.csv", &args);
    let text = stderr(&out);
    assert!(out.status.success(), "{text}");
    let floods: Vec<&str> = text.lines().filter(|l| l.contains("flood")).collect();
    // 100 steps from t = 0.5, each with its predictor, perturbed and
    // corrector runs: at least 5 lines for each of them.
    assert!(
        floods.len() >= 5 * 100 * 3,
        "{} lines: {text}",
        floods.len()
    );
    for line in floods {
        let (head, rest) = line
            .split_once(" flood message ")
            .unwrap_or_else(|| panic!("a cut line: {line:?}"));
        assert_eq!(head, "[WARN  fmu::mass2] [logStatusWarning]", "{line:?}");
        let (n, t) = rest.split_once(" at t = ").expect("the time");
        assert!(n.parse::<u32>().is_ok_and(|n| n < 5), "{line:?}");
        assert!(
            t.parse::<f64>().is_ok_and(|t| (0.5..0.6).contains(&t)),
            "{line:?}"
        );
    }
}

/// `--fmu-log-limit N` sets the messages shown per instance, category and
/// second, in process and in an isolated instance's host; `off` shows every
/// one; anything else is refused by name.
#[test]
fn the_log_rate_limit_is_switchable() {
    let s = Scratch::new();
    // 3 warnings per fmi2DoStep from t = 0.5: 500 macro steps, each with a
    // predictor, a perturbed and a corrector run, and the two steps of the
    // periodic rollback check at t = 0.5, 0.6, 0.7, 0.8 and 0.9.
    let flood = system(s.path(), 6, ", flood = 3");
    let shown = |extra: &[&str]| {
        let out = s.run(&flood, "out.csv", extra);
        let text = stderr(&out);
        assert!(out.status.success(), "{text}");
        let count = text.matches("] flood message ").count();
        (count, text)
    };
    for isolate in [&[][..], &["--isolate"][..]] {
        let with = |limit: &[&'static str]| -> Vec<&'static str> { [limit, isolate].concat() };
        let (count, text) = shown(&with(&["--fmu-log-limit", "5"]));
        assert!(
            text.contains("more messages suppressed (more than 5 in 1 s; --fmu-log-limit)"),
            "{text}"
        );
        // 5 a second: a run of a few seconds shows a few tens at most.
        assert!((5..500).contains(&count), "{count} shown, {isolate:?}");
        let (count, text) = shown(&with(&["--fmu-log-limit", "off"]));
        assert_eq!(
            count,
            3 * (3 * 500 + 2 * 5),
            "every message with off, {isolate:?}"
        );
        assert!(!text.contains("suppressed"), "{isolate:?}");
    }
    let out = s.run(&flood, "out.csv", &["--fmu-log-limit", "many"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(
            "'many' is not a rate limit: expected a number of messages per second, or off"
        ),
        "{}",
        stderr(&out)
    );
}

/// Asserts a failed run: exit code 1, no panic, the last stderr line holding `what`.
fn refused(out: &Output, what: &str) {
    let text = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    let last = text.lines().last().unwrap_or_default();
    assert!(last.starts_with("error: ") && last.contains(what), "{last}");
}

/// Two runs writing one results file: the second is refused (the first holds
/// the file's advisory lock) and the first one's rows are untouched.
#[test]
fn a_second_run_writing_the_same_results_file_is_refused() {
    let s = Scratch::new();
    let slow = system(s.path(), 7, "");
    let first = Killed(
        s.command(&["run", slow.to_str().unwrap(), "--out", "out.csv"])
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let path = s.path().join("out.csv");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    // Row t = 0.5 is written before mode 7's first 1 s sleep ends.
    while !std::fs::read_to_string(&path).is_ok_and(|t| t.contains("\n0.5,")) {
        assert!(
            std::time::Instant::now() < deadline,
            "the first run is not writing"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let before = std::fs::read_to_string(&path).unwrap();
    let second = s.run(&system(s.path(), 0, ""), "out.csv", &[]);
    refused(&second, "cannot write out.csv: another run is writing it");
    let after = std::fs::read_to_string(&path).unwrap();
    assert!(
        after.starts_with(&before),
        "the second run changed the file"
    );
    drop(first);
}

/// An `--out` that is one of the run's inputs is refused before anything is
/// written: `tether run self.toml --out self.toml` keeps the system file.
#[test]
fn an_output_that_is_an_input_is_refused() {
    let s = Scratch::new();
    let sys = system(s.path(), 0, "");
    let text = std::fs::read_to_string(&sys).unwrap();
    let name = sys.file_name().unwrap().to_str().unwrap();
    for out in [name.to_string(), format!("./tmp/../{name}")] {
        let run = s.run(&sys, &out, &[]);
        refused(&run, "it is the run's input");
        assert_eq!(std::fs::read_to_string(&sys).unwrap(), text);
    }
    // An FMU, through a copy the system names, by `run` and by `simulate`.
    let fmu = s.path().join("faults.fmu");
    std::fs::copy(tether_fmu_build::workspace_fmu("faults").unwrap(), &fmu).unwrap();
    let bytes = std::fs::read(&fmu).unwrap();
    let copy = s.path().join("copy.toml");
    let faults = tether_fmu_build::workspace_fmu("faults").unwrap();
    std::fs::write(
        &copy,
        text.replace(
            &format!("{:?}", faults.display().to_string()),
            "\"faults.fmu\"",
        ),
    )
    .unwrap();
    refused(
        &s.run(&copy, "faults.fmu", &[]),
        "faults.fmu: it is the run's input",
    );
    let simulate = s
        .command(&["simulate", "faults.fmu", "--out", "faults.fmu"])
        .output()
        .unwrap();
    refused(&simulate, "faults.fmu: it is the run's input faults.fmu");
    assert!(std::fs::read(&fmu).unwrap() == bytes, "the FMU was changed");
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}

/// A closed or full stderr (`2>/dev/full`) and a closed stdout (`| true`) never
/// make `tether` panic (exit code 101 before): a run still succeeds or fails as
/// it would, and a command whose output is lost fails with exit code 1.
#[test]
fn a_full_stderr_or_a_broken_pipe_is_no_panic() {
    use std::process::Stdio;
    let s = Scratch::new();
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap()
    };
    for (mode, code) in [(0, 0), (6, 0), (3, 1)] {
        let sys = system(s.path(), mode, "");
        let out = s
            .command(&["run", sys.to_str().unwrap(), "--out", "out.csv"])
            .stderr(full())
            .status()
            .unwrap();
        assert_eq!(out.code(), Some(code), "mode {mode}");
    }
    let fmu = tether_fmu_build::workspace_fmu("faults").unwrap();
    let fmu = fmu.to_str().unwrap();
    let out = s.command(&["info", fmu]).stdout(full()).output().unwrap();
    refused(&out, "cannot write to stdout");
    // A pipe whose reader is gone (closed before tether gets to write).
    let mut child = s
        .command(&["info", fmu])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let text = stderr(&out);
    assert!(!text.contains("panicked"), "{text}");
    assert!(matches!(out.status.code(), Some(0 | 1)), "{text}");
    if out.status.code() == Some(1) {
        assert!(
            text.contains("cannot write to stdout: Broken pipe"),
            "{text}"
        );
    }
}

/// In-process, an endless loop cannot be stopped: with `--call-timeout` the
/// watchdog ends the run, keeping every accepted row with the trailer naming
/// the instance, the call and the time, and removing the folders. The same on
/// a worker thread: with mass 1 marked `parallel = false` (it stays on the
/// main thread), mass 2's runs go to the one worker with `--parallel on`.
#[test]
fn in_process_endless_loop_is_ended_by_the_watchdog() {
    for on_a_worker in [false, true] {
        let s = Scratch::new();
        let sys = system(s.path(), 5, "");
        let mut args = vec!["--call-timeout", "0.5"];
        if on_a_worker {
            let text = std::fs::read_to_string(&sys).unwrap();
            let marked = text.replacen("name = \"mass1\"", "name = \"mass1\"\nparallel = false", 1);
            assert_ne!(text, marked, "mass1 marked");
            std::fs::write(&sys, marked).unwrap();
            args.extend(["--parallel", "on", "--threads", "2"]);
        }
        let out = s.run(&sys, "out.csv", &args);
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{text}");
        let reason = "instance 'mass2': fmi2DoStep at t=0.5 did not return within the call time-out of 0.5 s (the FMU runs in-process and cannot be stopped: the run ends)";
        assert_eq!(
            text.lines().last().unwrap_or_default(),
            format!(
                "error: run stopped; results so far kept in out.csv (marked incomplete): {reason}"
            )
        );
        let csv = read_csv(&s.path().join("out.csv"));
        assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
        assert_eq!(csv.rows.len(), 501, "t = 0 … 0.5");
        assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    }
}

/// Ctrl-C during an endless loop, in-process and isolated: the first one names
/// the call the run waits for, the second ends the run at once with exit code
/// 130, the trailer and no folder (nor host process) left.
#[test]
fn ctrl_c_during_a_stuck_call_names_it_and_the_second_ends_the_run() {
    use std::io::BufRead;
    for isolate in [false, true] {
        let s = Scratch::new();
        let sys = system(s.path(), 5, "");
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "out.csv"];
        if isolate {
            args.push("--isolate");
        }
        let mut child = s
            .command(&args)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        let stderr = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines() {
                let _ = tx.send(line.unwrap_or_default());
            }
        });
        wait_for_the_row_at_0_5(&s);
        let pid = child.id() as i32;
        // SAFETY: a signal to the child this test started and has not reaped.
        unsafe { libc::kill(pid, libc::SIGINT) };
        let waiting = rx
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("a line after the first Ctrl-C");
        assert_eq!(
            waiting,
            "waiting for fmi2DoStep of instance 'mass2' at t=0.5 to return; Ctrl-C again stops at once (the results so far are kept)"
        );
        // SAFETY: as above.
        unsafe { libc::kill(pid, libc::SIGINT) };
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(130), "isolate = {isolate}");
        let csv = read_csv(&s.path().join("out.csv"));
        assert_eq!(
            csv.trailer.as_deref(),
            Some("# incomplete: interrupted by a second Ctrl-C or termination signal (exited at once)")
        );
        assert_eq!(csv.rows.len(), 501);
        assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while !processes_left(&s).is_empty() {
            assert!(
                std::time::Instant::now() < deadline,
                "{:?}",
                processes_left(&s)
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
}

/// In-process, the same FMU kills `tether` by SIGSEGV: seen at once, with the
/// rows up to the last flush, as any segfault. The helper is a child of the
/// FMU in `tether`'s own process: nothing can end it after the crash (isolate
/// FMUs that start processes); the test ends it.
#[test]
fn in_process_crash_after_starting_a_helper_is_seen_at_once() {
    use std::os::unix::process::ExitStatusExt;
    let s = Scratch::new();
    let (status, text, elapsed) = run_to_exit(&s, &system(s.path(), 8, ", delay = 0.001"), &[]);
    kill_leftover_processes(&s);
    assert_eq!(status.signal(), Some(11), "SIGSEGV; {text}");
    assert!(elapsed < NO_STALL, "{elapsed:?}");
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(csv.trailer, None);
    let t = last_time(&csv);
    assert!((0.3..0.5).contains(&t), "last row at t = {t}");
}

/// An FMU that forks at t = 0.5, whose child calls `exit(0)` (the parent goes
/// on): in-process the child inherits Tether's exit hook, which acts only in the
/// process that installed it, so the child neither reports a false error nor
/// removes the run's extraction folders; isolated the child is the host's. The
/// run ends normally, every row written, nothing left behind.
#[test]
fn a_forked_child_calling_exit_is_not_the_runs_end() {
    for isolate in [false, true] {
        let s = Scratch::new();
        // Slowed (2 ms per step) so that the folders can be seen after t = 0.5.
        let sys = system(s.path(), 9, ", delay = 0.002");
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "out.csv"];
        if isolate {
            args.push("--isolate");
        }
        let log = s.path().join("stderr.txt");
        let mut child = Killed(
            s.command(&args)
                .stderr(std::fs::File::create(&log).unwrap())
                .spawn()
                .unwrap(),
        );
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
        while !std::fs::read_to_string(s.path().join("out.csv"))
            .unwrap_or_default()
            .lines()
            .any(|l| l.starts_with("0.6,"))
        {
            assert!(std::time::Instant::now() < deadline, "no rows");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        assert_eq!(
            s.leftovers().len(),
            2,
            "isolate = {isolate}: the folders are in use"
        );
        let status = child.0.wait().unwrap();
        let text = std::fs::read_to_string(&log).unwrap();
        assert!(status.success(), "isolate = {isolate}: {text}");
        assert!(!text.contains("error"), "isolate = {isolate}: {text}");
        let csv = read_csv(&s.path().join("out.csv"));
        assert_eq!((csv.rows.len(), csv.trailer), (1001, None));
        assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
        assert!(processes_left(&s).is_empty(), "{:?}", processes_left(&s));
    }
}

/// The results folder removed during a run: the run stops with an error
/// naming the file (exit code 1), not `results: vdir/out.csv` and success.
#[test]
fn an_output_removed_during_the_run_is_an_error() {
    let s = Scratch::new();
    std::fs::create_dir(s.path().join("vdir")).unwrap();
    let child = slow_run(&s, "vdir/out.csv");
    std::fs::remove_dir_all(s.path().join("vdir")).unwrap();
    let out = wait_within(child, 60);
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    let last = text.lines().last().unwrap_or_default();
    assert!(last.starts_with("error: run stopped at t = "), "{last}");
    assert!(
        last.ends_with("cannot write vdir/out.csv: recording results: vdir/out.csv was removed or renamed during the run"),
        "{last}"
    );
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}

/// The results file replaced during a run (renamed, another file put in its
/// place): an error naming it; the file the run wrote, under its new name,
/// keeps every row written with the trailer, and the new file is untouched.
#[test]
fn an_output_replaced_during_the_run_is_an_error() {
    let s = Scratch::new();
    let child = slow_run(&s, "out.csv");
    std::fs::rename(s.path().join("out.csv"), s.path().join("moved.csv")).unwrap();
    std::fs::write(s.path().join("out.csv"), "another file\n").unwrap();
    let out = wait_within(child, 60);
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    let reason = "out.csv was replaced by another file during the run";
    let last = text.lines().last().unwrap_or_default();
    assert!(last.starts_with("error: run stopped at t = "), "{last}");
    assert!(last.ends_with(reason), "{last}");
    assert_eq!(
        std::fs::read_to_string(s.path().join("out.csv")).unwrap(),
        "another file\n"
    );
    let csv = read_csv(&s.path().join("moved.csv"));
    assert_eq!(
        csv.trailer,
        Some(format!("# incomplete: cannot write the results: {reason}"))
    );
    assert!(last_time(&csv) >= 0.5, "{}", last_time(&csv));
    assert_eq!(
        csv.rows.len() as f64 - 1.0,
        (last_time(&csv) * 1000.0).round()
    );
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
}

/// A FIFO as `fmu =` is refused before it is opened (opening it would wait
/// for a writer for ever), in process and isolated: one line naming the
/// instance and the path, exit code 1, no results file, nothing left.
#[test]
fn a_fifo_as_an_fmu_is_refused() {
    let s = Scratch::new();
    let fifo = s.path().join("mass2.fmu");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a NUL-terminated path; creates a FIFO in the test's folder.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let faults = tether_fmu_build::workspace_fmu("faults").unwrap();
    let text = std::fs::read_to_string(system(s.path(), 0, "")).unwrap();
    let sys = s.path().join("fifo.toml");
    std::fs::write(
        &sys,
        text.replace(
            &format!("{:?}", faults.display().to_string()),
            &format!("{:?}", fifo.display().to_string()),
        ),
    )
    .unwrap();
    for extra in [&[][..], &["--isolate"][..]] {
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "out.csv"];
        args.extend_from_slice(extra);
        let child = s
            .command(&args)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let out = wait_within(child, 60);
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{text}");
        assert_eq!(
            text,
            format!(
                "error: instance 'mass2': '{}' is a FIFO, not an FMU archive (a regular file) nor an unpacked FMU folder\n",
                fifo.display()
            ),
            "{extra:?}"
        );
        assert!(!s.path().join("out.csv").exists());
        assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    }
}

/// A signal while the inputs are being opened (here the opening of a remote
/// instance on a host that accepts the connection and never answers: the
/// master waits up to its 30 s opening time-out) ends the process at once with
/// exit code 130 and one line, for SIGINT and SIGTERM alike.
#[test]
fn a_signal_during_the_open_ends_the_run() {
    use std::os::unix::fs::PermissionsExt;
    let s = Scratch::new();
    let sys = system(s.path(), 0, "");
    let token = s.path().join("host.token");
    std::fs::write(&token, "3f9a6c1e0b7d4a2f8e5c9b1d7a3f6e2c\n").unwrap();
    std::fs::set_permissions(&token, std::fs::Permissions::from_mode(0o600)).unwrap();
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let host = format!("tcp://{}", silent.local_addr().unwrap());
    let held = std::thread::spawn(move || silent.incoming().take(2).collect::<Vec<_>>());
    for signal in [libc::SIGINT, libc::SIGTERM] {
        let child = s
            .command(&["run", sys.to_str().unwrap(), "--out", "out.csv"])
            .args(["--host", &host, "--token-file", "host.token"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // The handler is installed first thing; give the process time to block.
        std::thread::sleep(std::time::Duration::from_secs(1));
        // SAFETY: a signal to the child this test started and has not reaped.
        unsafe { libc::kill(child.id() as i32, signal) };
        let out = wait_within(child, 20);
        assert_eq!(
            out.status.code(),
            Some(130),
            "signal {signal}: {}",
            stderr(&out)
        );
        assert_eq!(
            stderr(&out),
            "error: interrupted by Ctrl-C or a termination signal before the run started (nothing was written)\n"
        );
        assert!(!s.path().join("out.csv").exists());
        assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    }
    drop(held);
}

/// A FIFO (or another special file) as the system file or the SSP is refused
/// at once, by `run` and `ssp import`: opening it would wait for a writer that
/// may never come.
#[test]
fn a_fifo_as_the_system_file_is_refused_at_once() {
    let s = Scratch::new();
    for name in ["system.toml", "system.ssp"] {
        let fifo = s.path().join(name);
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a NUL-terminated path; creates a FIFO in the test's folder.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let what = if name.ends_with(".ssp") {
            format!("error: {name}: is a FIFO, not an SSP archive, an SSD file or a folder\n")
        } else {
            format!("error: system file {name}: is a FIFO, not a regular file\n")
        };
        for args in [
            &["run", name, "--out", "out.csv"][..],
            &["ssp", "import", name, "--out", "imported.toml"][..],
        ] {
            if args[0] == "ssp" && !name.ends_with(".ssp") {
                continue;
            }
            let child = s
                .command(args)
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap();
            let out = wait_within(child, 20);
            assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
            assert_eq!(stderr(&out), what, "{args:?}");
        }
    }
    assert!(!s.path().join("out.csv").exists());
}

/// A run of the faults FMU in `mode` with `extra` parameters and `coupling`
/// keys added to `[coupling]`, quiet, with its summary in `summary.json`, in
/// process or isolated: the process, the results and the summary.
fn broken_rollback_run(
    (mode, extra): (i32, &str),
    coupling: &str,
    isolate: bool,
) -> (Scratch, Output, Csv, serde_json::Value) {
    broken_rollback_run_with((mode, extra), coupling, isolate, &[])
}

/// [`broken_rollback_run`] with more command-line `flags`.
fn broken_rollback_run_with(
    (mode, extra): (i32, &str),
    coupling: &str,
    isolate: bool,
    more: &[&str],
) -> (Scratch, Output, Csv, serde_json::Value) {
    let s = Scratch::new();
    let sys = system(s.path(), mode, extra);
    let text = std::fs::read_to_string(&sys).unwrap();
    assert!(text.contains("[coupling]\n"), "example changed");
    let text = text.replace("[coupling]\n", &format!("[coupling]\n{coupling}\n"));
    std::fs::write(&sys, text).unwrap();
    let mut flags = vec!["--quiet", "--summary-json", "summary.json"];
    if isolate {
        flags.push("--isolate");
    }
    flags.extend_from_slice(more);
    let out = s.run(&sys, "out.csv", &flags);
    let csv = read_csv(&s.path().join("out.csv"));
    let summary = std::fs::read_to_string(s.path().join("summary.json")).unwrap();
    let summary = serde_json::from_str(&summary).unwrap();
    (s, out, csv, summary)
}

/// The one error line of a failed quiet run: exit code 1, the line names
/// where the results are and ends with the trailer's reason; every row up to
/// `until` is kept, one per macro step; nothing is left in TMPDIR.
fn failed_with(s: &Scratch, out: &Output, csv: &Csv, until: f64) -> String {
    let text = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert_eq!(text.lines().count(), 1, "one line: {text}");
    let prefix = format!(
        "error: run stopped; results up to t = {until} kept in out.csv (marked incomplete): "
    );
    let reason = text
        .trim_end()
        .strip_prefix(&prefix)
        .unwrap_or_else(|| panic!("{text}"));
    assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
    assert_eq!(last_time(csv), until);
    assert_eq!(
        csv.rows.len() as f64 - 1.0,
        (until * 1000.0).round(),
        "every row"
    );
    for (n, row) in csv.rows.iter().enumerate() {
        assert_eq!(row[0], n as f64 * 1e-3, "row {n}");
    }
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    reason.to_string()
}

/// The faults FMU's rollback breaks at t = 0.5, after the setup check: from
/// then on `fmi2SetFMUstate` does nothing (mode 12), or restores the outputs
/// but leaves an offset the next step adds (mode 13, not caught by reading
/// the outputs back). The default check, repeated every 100 macro steps,
/// repeats the step from T = 0.5 after a restore and stops the run there:
/// exit code 1, one line with `-q`, every row up to t = 0.5, the trailer, and
/// `completed: false` with the failure in the summary; in process and isolated.
#[test]
fn a_rollback_that_breaks_mid_run_fails_the_run() {
    let cases = [
        (
            12,
            "after fmi2SetFMUstate back to t = 0.5, output 'x' reads ",
        ),
        (
            13,
            "the step from t = 0.5 to 0.501 repeated after fmi2SetFMUstate with the same \
             inputs gives output 'x' = ",
        ),
    ];
    for (mode, what) in cases {
        for isolate in [false, true] {
            let (s, out, csv, summary) = broken_rollback_run((mode, ""), "", isolate);
            let reason = failed_with(&s, &out, &csv, 0.5);
            let head = format!("rollback self-check failed for instance 'mass2': {what}");
            assert!(reason.starts_with(&head), "mode {mode}: {reason}");
            assert_eq!(summary["completed"], false);
            assert_eq!(summary["stop_reason"], reason.as_str());
            let failure = &summary["failure"];
            assert_eq!(failure["kind"], "rollback_check", "{failure}");
            assert_eq!(failure["instance"], "mass2");
            assert_eq!(failure["variable"], "x");
            assert_eq!(failure["message"], reason.as_str());
            assert_eq!(summary["end_time"], 0.5);
        }
    }
}

/// The rollback breaks at t = 0.55, between two periodic checks: the check at
/// t = 0.6 fails, and the rows written since the one that passed (t = 0.5)
/// were computed with broken restores (the residual limit, off here, would
/// catch this drift itself at t = 0.584). They stay in the CSV, and the
/// trailer, the error line and the summary's `failure.unverified_after` name
/// them; the rows up to t = 0.5 are those of a clean run, bit for bit. In
/// process and isolated.
#[test]
fn rows_written_before_a_failed_rollback_check_are_named() {
    let s = Scratch::new();
    let clean = system(s.path(), 0, "");
    assert!(s.run(&clean, "clean.csv", &["--quiet"]).status.success());
    let clean = read_csv(&s.path().join("clean.csv"));
    for isolate in [false, true] {
        let off = "residual_limit = \"off\"";
        let (s, out, csv, summary) = broken_rollback_run((12, ", at = 0.55"), off, isolate);
        let reason = failed_with(&s, &out, &csv, 0.6);
        assert!(
            reason.ends_with(
                "; the rows after t = 0.5 were written before this check failed and are not \
                 verified"
            ),
            "{reason}"
        );
        let failure = &summary["failure"];
        assert_eq!(failure["kind"], "rollback_check", "{failure}");
        assert_eq!(failure["unverified_after"], 0.5);
        assert_eq!(failure["message"], reason.as_str());
        assert_eq!(csv.rows[..=500], clean.rows[..=500], "verified rows");
        // The rows after it are wrong: the link drifts with the broken restores.
        let g = csv.rows[0].len() - 1;
        let drift = csv.rows[501..]
            .iter()
            .map(|r| r[g].abs())
            .fold(0.0, f64::max);
        let clean_g = clean.rows[501..=600]
            .iter()
            .map(|r| r[g].abs())
            .fold(0.0, f64::max);
        assert!(drift > 10.0 * clean_g, "{drift} against {clean_g}");
    }
}

/// Outputs that change from one read to the next with no step between them
/// (mode 14, from t = 0.5) are named as such by the periodic check, not blamed
/// on the restore; in process and isolated.
#[test]
fn outputs_that_change_without_a_step_are_named() {
    for isolate in [false, true] {
        let off = "residual_limit = \"off\"";
        let (s, out, csv, summary) = broken_rollback_run((14, ", noise = 1e-9"), off, isolate);
        let reason = failed_with(&s, &out, &csv, 0.5);
        let head = "rollback self-check failed for instance 'mass2': output 'x' changes without \
                    a step: read twice at t = 0.5 with no fmi2DoStep between, it gives ";
        assert!(reason.starts_with(head), "{reason}");
        assert!(!reason.contains("not restored"), "{reason}");
        assert_eq!(summary["failure"]["variable"], "x");
    }
}

/// With the check only at setup (`check_rollback = "setup"`), the same broken
/// rollbacks break the link: the residual limit stops the run at the first
/// accepted point whose |link.g| exceeds it, naming the condition, its value
/// and the limit, in the trailer, the error line and the summary; in process
/// and isolated. The default limit (1) catches both; mode 13 with an offset of
/// up to 0.2 (with the default 0.01 the link drifts by up to 0.77: broken, but
/// within the limit, which is a bound, not an accuracy; the periodic check
/// catches that one).
#[test]
fn a_broken_constraint_fails_the_run_with_check_rollback_setup() {
    for (mode, extra) in [(12, ""), (13, ", noise = 0.2")] {
        let mut ends = Vec::new();
        for isolate in [false, true] {
            let setup = "check_rollback = \"setup\"";
            let (s, out, csv, summary) = broken_rollback_run((mode, extra), setup, isolate);
            let until = summary["end_time"].as_f64().expect("rows");
            assert!(
                until >= 0.5,
                "mode {mode}: the link held up to t = 0.5: {until}"
            );
            let reason = failed_with(&s, &out, &csv, until);
            let failure = &summary["failure"];
            assert_eq!(failure["kind"], "residual_limit", "{failure}");
            assert_eq!(failure["column"], "link.g");
            assert_eq!(failure["limit"], 1.0);
            assert_eq!(summary["residual_limit"], 1.0);
            let time = failure["time"].as_f64().unwrap();
            let value = failure["value"].as_f64().unwrap();
            assert!(
                value > 1.0 && (time - until - 1e-3).abs() < 1e-12,
                "{failure}"
            );
            assert_eq!(
                reason,
                format!(
                    "constraint broken at t = {time}: |link.g| = {value:e} exceeds \
                     residual_limit = 1e0 (in the condition's units); the coupling does not \
                     hold it: a smaller step, another index or method \
                     (docs/paper-reproduction.md), check_rollback = \"every_step\" to test \
                     the FMUs' rollback at every restore, or residual_limit = \"off\" to run \
                     anyway"
                )
            );
            // Every row kept is within the limit.
            let g = csv.rows[0].len() - 1;
            assert!(csv.rows.iter().all(|r| r[g].abs() <= 1.0));
            assert_eq!(summary["completed"], false);
            ends.push(std::fs::read(s.path().join("out.csv")).unwrap());
        }
        assert!(ends[0] == ends[1], "mode {mode}: isolated results differ");
    }
}

/// `residual_limit = "off"` runs the broken rollback to the end (exit code 0):
/// the limit, not something else, stopped the runs above.
#[test]
fn residual_limit_off_runs_a_broken_constraint_anyway() {
    let keys = "check_rollback = \"setup\"\nresidual_limit = \"off\"";
    let (_s, out, csv, summary) = broken_rollback_run((12, ""), keys, false);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!((csv.rows.len(), csv.trailer), (1001, None));
    assert_eq!(summary["completed"], true);
    assert_eq!(summary["residual_limit"], serde_json::Value::Null);
    assert_eq!(summary["failure"], serde_json::Value::Null);
    let g = summary["max_abs_g"]["link.g"].as_f64().unwrap();
    assert!(g > 1.0, "max |link.g| = {g}");
}

/// Adaptive steps: a rejected step rolls every instance back, and the check
/// runs from there before the smaller step. With the residual limit off and
/// fewer than 100 accepted steps before the fault, that check, not the
/// periodic one nor the limit, stops the run at the rejected step's start,
/// just before t = 0.5; in process and isolated.
#[test]
fn a_rollback_that_breaks_mid_run_is_caught_after_a_rejected_step() {
    for isolate in [false, true] {
        let off = "residual_limit = \"off\"";
        let adaptive = ["--step-rtol", "1e-3"];
        let (s, out, csv, summary) = broken_rollback_run_with((12, ""), off, isolate, &adaptive);
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{text}");
        assert_eq!(text.lines().count(), 1, "one line: {text}");
        let failure = &summary["failure"];
        assert_eq!(failure["kind"], "rollback_check", "{failure}");
        assert_eq!(failure["instance"], "mass2");
        let accepted = summary["adaptive"]["accepted"].as_u64().unwrap();
        assert!(summary["adaptive"]["rejected"].as_u64().unwrap() > 0);
        assert!(
            accepted % 100 != 0,
            "not the periodic check: {accepted} steps"
        );
        let end = summary["end_time"].as_f64().unwrap();
        assert!((0.45..0.5).contains(&end), "{end}");
        assert_eq!(last_time(&csv), end);
        assert_eq!(csv.rows.len() as u64, accepted + 1, "every row");
        let reason = failure["message"].as_str().unwrap();
        assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
        assert!(
            reason.contains(&format!(
                "after fmi2SetFMUstate back to t = {end}, output 'x'"
            )),
            "{reason}"
        );
        assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    }
}
