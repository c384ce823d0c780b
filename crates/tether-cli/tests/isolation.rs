//! Isolated instances (`--isolate`, `isolation = "process"`; docs/reliability.md):
//! the `faults` test FMU (fmus/faults) replaces mass 2 of examples/oscillator.toml
//! and misbehaves inside `fmi2DoStep` at t = 0.5 in its host process: crashes,
//! exits, hangs past the call time-out, log floods, helper processes; isolated
//! runs equal in-process ones bit for bit and cost two round trips per instance
//! and macro step. Each test runs the real `tether` binary with its own `TMPDIR`,
//! and checks that no folder and no process is left.

mod fault_support;

use std::path::Path;

use fault_support::*;

/// An isolated run (`--isolate`) of the faults FMU in `mode` ends with the error
/// `instance 'mass2': <reason>`: exit code 1, every row up to t = 0.5 with the
/// trailer, no folder and no host process left. `keys` go into mass 2's table.
fn isolated_fault(mode: i32, extra: &str, keys: &str, flags: &[&str], reason: &str) {
    let s = Scratch::new();
    let mut args = vec!["--isolate", "--quiet"];
    args.extend_from_slice(flags);
    let sys = system(s.path(), mode, extra);
    let text = std::fs::read_to_string(&sys).unwrap();
    let mass2 = "name = \"mass2\"\n";
    assert!(text.contains(mass2));
    std::fs::write(&sys, text.replace(mass2, &format!("{mass2}{keys}"))).unwrap();
    let out = s.run(&sys, "out.csv", &args);
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    let reason = format!("instance 'mass2': {reason}");
    assert_eq!(
        text.lines().last().unwrap_or_default(),
        format!("error: run stopped; results up to t = 0.5 kept in out.csv (marked incomplete): {reason}")
    );
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
    assert_eq!(csv.rows.len(), 501, "t = 0 … 0.5");
    assert_eq!(last_time(&csv), 0.5);
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    assert!(processes_left(&s).is_empty(), "{:?}", processes_left(&s));
}

#[test]
fn isolated_segfault_is_an_error() {
    isolated_fault(
        1,
        "",
        "",
        &[],
        "its host process was killed by signal 11 (SIGSEGV) during fmi2DoStep at t=0.5",
    );
}

#[test]
fn isolated_abort_is_an_error() {
    isolated_fault(
        2,
        "",
        "",
        &[],
        "its host process was killed by signal 6 (SIGABRT) during fmi2DoStep at t=0.5",
    );
}

#[test]
fn isolated_exit_0_is_an_error() {
    isolated_fault(
        3,
        "",
        "",
        &[],
        "its host process exited with code 0 during fmi2DoStep at t=0.5",
    );
}

#[test]
fn isolated_exit_3_is_an_error() {
    isolated_fault(
        4,
        "",
        "",
        &[],
        "its host process exited with code 3 during fmi2DoStep at t=0.5",
    );
}

/// Times in messages read as the grid gives them: the step from the grid point
/// 9·H = 0.009000000000000001 is "t=0.009" in the error line and the trailer,
/// while the CSV's time column keeps the value itself.
#[test]
fn times_in_messages_read_as_the_grid_gives_them() {
    assert_eq!(format!("{}", 9.0 * 1e-3), "0.009000000000000001");
    let s = Scratch::new();
    let sys = system(s.path(), 4, ", at = 0.009");
    let out = s.run(&sys, "out.csv", &["--isolate", "--quiet"]);
    let reason =
        "instance 'mass2': its host process exited with code 3 during fmi2DoStep at t=0.009";
    assert_eq!(
        stderr(&out).lines().last().unwrap_or_default(),
        format!("error: run stopped; results up to t = 0.009 kept in out.csv (marked incomplete): {reason}")
    );
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
    assert_eq!(last_time(&csv), 9.0 * 1e-3);
}

/// An endless loop in `fmi2DoStep` with `--call-timeout`: the host is killed.
#[test]
fn isolated_endless_loop_is_ended_by_the_call_timeout() {
    isolated_fault(
        5,
        "",
        "",
        &["--call-timeout", "0.5"],
        "fmi2DoStep at t=0.5 did not return within the call time-out of 0.5 s; its host process was killed",
    );
}

/// Slow calls (2 s each from t = 0.5) against the instance's own `call_timeout`
/// in the system file, which `--call-timeout` does not override.
#[test]
fn isolated_slow_call_exceeds_the_instances_call_timeout() {
    isolated_fault(
        7,
        ", pause = 2.0",
        "call_timeout = 0.25\n",
        &["--call-timeout", "100"],
        "fmi2DoStep at t=0.5 did not return within the call time-out of 0.25 s; its host process was killed",
    );
}

/// A log flood from an isolated instance is rate-limited by its host as
/// in-process, and `--quiet` silences it.
#[test]
fn isolated_log_flood_is_rate_limited() {
    let s = Scratch::new();
    let flood = system(s.path(), 6, "");
    let out = s.run(&flood, "out.csv", &["--isolate"]);
    let text = stderr(&out);
    assert!(out.status.success(), "{text}");
    assert!(text.len() < 16 << 10, "{} bytes on stderr", text.len());
    assert!(text.contains("[WARN  fmu::mass2] [logStatusWarning] flood message 0 at t = 0.5"));
    assert!(text.contains("more messages suppressed (more than 20 in 1 s; --fmu-log-limit)"));
    let out = s.run(&flood, "out.csv", &["--isolate", "--quiet"]);
    assert_eq!(stderr(&out), "", "--quiet");
    assert_eq!(read_csv(&s.path().join("out.csv")).rows.len(), 1001);
    assert!(s.leftovers().is_empty() && processes_left(&s).is_empty());
}

/// Isolated instances give the in-process results bit for bit: every FMI call
/// crosses with its numbers unchanged, FMU states included (the oscillator
/// with k = 1 and parallel runs too).
#[test]
fn isolated_runs_equal_in_process_runs_bit_for_bit() {
    let s = Scratch::new();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    // The examples name the packaged FMUs in target/fmus.
    for fmu in ["oscillator", "link", "body3d"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the example's FMUs");
    }
    for (example, flags) in [
        ("oscillator", &[][..]),
        ("oscillator", &["--order", "1", "--parallel", "on"][..]),
        ("double_pendulum", &[][..]),
        ("3d_revolute", &[][..]),
    ] {
        let system = root.join("examples").join(format!("{example}.toml"));
        let results = |isolate: bool| {
            let mut args = vec!["--quiet"];
            args.extend_from_slice(flags);
            if isolate {
                args.push("--isolate");
            }
            let out = s.run(&system, "out.csv", &args);
            assert!(out.status.success(), "{example}: {}", stderr(&out));
            std::fs::read(s.path().join("out.csv")).unwrap()
        };
        let (in_process, isolated) = (results(false), results(true));
        assert!(in_process.len() > 1000, "{example}");
        assert!(
            in_process == isolated,
            "{example} {flags:?} differs when isolated"
        );
    }
    assert!(s.leftovers().is_empty() && processes_left(&s).is_empty());
}

/// An isolated instance's macro step is two messages to its host: the save,
/// the predictor and the perturbed runs in one, the corrector with the reads
/// of the accepted point in the other; with k = 1, adaptive steps and
/// Jacobian reuse too (`round_trips` of the run summary, counted between two
/// stop times so that the setup cancels out).
#[test]
fn an_isolated_macro_step_costs_two_round_trips_per_instance() {
    let s = Scratch::new();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    for fmu in ["oscillator", "link"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the example's FMUs");
    }
    for (example, flags) in [
        ("oscillator", &[][..]),
        ("oscillator", &["--order", "1"][..]),
        ("oscillator", &["--step-rtol", "1e-4"][..]),
        ("double_pendulum", &["--jacobian", "reuse"][..]),
    ] {
        let system = root.join("examples").join(format!("{example}.toml"));
        let summary = |stop: &str| {
            let mut args = vec!["--quiet", "--isolate", "--parallel", "off", "--stop", stop];
            args.extend_from_slice(&["--summary-json", "summary.json"]);
            args.extend_from_slice(flags);
            let out = s.run(&system, "out.csv", &args);
            assert!(out.status.success(), "{example}: {}", stderr(&out));
            let text = std::fs::read_to_string(s.path().join("summary.json")).unwrap();
            serde_json::from_str::<serde_json::Value>(&text).unwrap()
        };
        let (short, long) = (summary("0.2"), summary("0.4"));
        let tries = |v: &serde_json::Value| match v["adaptive"].as_object() {
            Some(a) => a["accepted"].as_u64().unwrap() + a["rejected"].as_u64().unwrap(),
            None => v["macro_steps"].as_u64().unwrap(),
        };
        let steps = tries(&long) - tries(&short);
        assert!(steps >= 100, "{example} {flags:?}: {steps} steps");
        let instances = long["instances"].as_object().unwrap();
        for (name, calls) in instances {
            let trips = calls["round_trips"].as_u64().unwrap()
                - short["instances"][name]["round_trips"].as_u64().unwrap();
            // Jacobian reuse remakes a mispredicting Jacobian: then the
            // perturbed runs and the correction go again (a few steps).
            let most = if flags.contains(&"reuse") {
                2 * steps + steps / 10
            } else {
                2 * steps
            };
            assert!(
                trips <= most && trips >= 2 * steps,
                "{example} {flags:?} {name}: {trips} round trips in {steps} steps"
            );
        }
    }
    assert!(s.leftovers().is_empty() && processes_left(&s).is_empty());
}

/// A host killed from outside (SIGKILL, as the OOM killer does) while its FMU
/// sleeps in `fmi2DoStep` is an error of the run naming the instance and the
/// signal, with every row kept. The FMUs' code runs in the hosts only.
#[test]
fn an_isolated_host_killed_from_outside_is_an_error() {
    let s = Scratch::new();
    let sys = system(s.path(), 7, ", pause = 30.0");
    let child = s
        .command(&[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "out.csv",
            "--isolate",
            // One host per instance: "auto" may give workers their own copies
            // (and hosts) when the isolated runs look expensive.
            "--parallel",
            "off",
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // From t = 0.5 mass 2's first fmi2DoStep sleeps 30 s; its host was started
    // second (the hosts' pids grow with the instances' order).
    wait_for_the_row_at_0_5(&s);
    std::thread::sleep(std::time::Duration::from_millis(200));
    let mut hosts: Vec<i32> = processes(&s)
        .into_iter()
        .filter(|(_, cmdline)| cmdline.contains("__fmi-host"))
        .map(|(pid, _)| pid)
        .collect();
    hosts.sort();
    assert_eq!(hosts.len(), 2, "two hosts");
    // The FMUs' libraries are loaded in the hosts only, never in the master.
    let maps = |pid: i32| std::fs::read_to_string(format!("/proc/{pid}/maps")).unwrap();
    assert!(!maps(child.id() as i32).contains("/binaries/linux64/"));
    assert!(maps(hosts[1]).contains("/binaries/linux64/faults.so"));
    // SAFETY: a signal to a host process of the run this test started.
    unsafe { libc::kill(hosts[1], libc::SIGKILL) };
    let out = child.wait_with_output().unwrap();
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    let reason = "instance 'mass2': its host process was killed by signal 9 (SIGKILL) during fmi2DoStep at t=0.5";
    assert!(text.trim_end().ends_with(reason), "{text}");
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!(csv.trailer, Some(format!("# incomplete: {reason}")));
    assert_eq!(csv.rows.len(), 501);
    assert!(s.leftovers().is_empty() && processes_left(&s).is_empty());
}

/// An isolated FMU that starts a helper process (`system("sleep 15 &")`) and
/// then crashes: the crash is seen at once as the host's SIGSEGV (not as a 15 s
/// hang, nor as the call time-out: the helper holds no pipe of the host, whose
/// descriptors are close-on-exec), and the helper ends with the host (its
/// process group is killed): nothing is left.
#[test]
fn isolated_crash_after_starting_a_helper_is_seen_at_once() {
    let start = std::time::Instant::now();
    isolated_fault(
        8,
        "",
        "",
        &["--call-timeout", "30"],
        "its host process was killed by signal 11 (SIGSEGV) during fmi2DoStep at t=0.5",
    );
    assert!(start.elapsed() < NO_STALL, "{:?}", start.elapsed());
}

/// An isolated FMU whose forked child (no `exec`: it holds a copy of every
/// descriptor of the host, the reply pipe included) lingers while the host
/// crashes: the master sees the host's exit, not only the pipe's end, and the
/// child ends with the host's process group.
#[test]
fn isolated_crash_seen_by_the_hosts_exit_while_a_child_holds_its_pipe() {
    let start = std::time::Instant::now();
    isolated_fault(
        10,
        "",
        "",
        &[],
        "its host process was killed by signal 11 (SIGSEGV) during fmi2DoStep at t=0.5",
    );
    assert!(start.elapsed() < NO_STALL, "{:?}", start.elapsed());
}

/// An isolated FMU that starts a helper process (`system("sleep 15 &")`) and
/// goes on: the run ends normally, and the helper with the instance (its host's
/// process group is killed once the host has exited), so nothing is left and
/// nothing holds the run's standard error for the helper's 15 s.
#[test]
fn isolated_helper_ends_with_the_instance() {
    let s = Scratch::new();
    let start = std::time::Instant::now();
    let out = s.run(&system(s.path(), 11, ""), "out.csv", &["--isolate"]);
    let elapsed = start.elapsed();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(elapsed < NO_STALL, "{elapsed:?}");
    let csv = read_csv(&s.path().join("out.csv"));
    assert_eq!((csv.rows.len(), csv.trailer), (1001, None));
    assert!(s.leftovers().is_empty(), "{:?}", s.leftovers());
    assert!(processes_left(&s).is_empty(), "{:?}", processes_left(&s));
}

/// The oscillator example with both masses the faults FMU in `mode` (mass 2
/// with `extra` parameters, mass 1 with `mass1`).
fn both_faults(s: &Scratch, mode: i32, extra: &str, mass1: &str) -> std::path::PathBuf {
    let sys = system(s.path(), mode, extra);
    let oscillator = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let faults = tether_fmu_build::workspace_fmu("faults").unwrap();
    let text = std::fs::read_to_string(&sys).unwrap();
    let was = format!(
        "fmu = {:?}\nparameters = {{ m = 1.0",
        oscillator.display().to_string()
    );
    assert!(text.contains(&was));
    let now = format!(
        "fmu = {:?}\nparameters = {{ mode = {mode}{mass1}, m = 1.0",
        faults.display().to_string()
    );
    std::fs::write(&sys, text.replace(&was, &now)).unwrap();
    sys
}

/// The requests of a phase go to every host process before any reply is
/// awaited, whatever `parallel` says: two isolated instances of the faults
/// FMU in mode 16 must both be inside the step at t = 0.01 for either to
/// finish it (each waits up to 5 s for the other, then ends its process).
/// With `--parallel off` the isolated run meets there and completes; the same
/// run in process, one instance stepped after the other on one thread, cannot.
#[test]
fn isolated_instances_step_at_once_without_threads() {
    let s = Scratch::new();
    let sys = both_faults(&s, 16, ", at = 0.01", ", at = 0.01");
    for (isolate, met) in [(true, true), (false, false)] {
        let barrier = tempfile::tempdir().unwrap();
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "out.csv"];
        args.extend(["--stop", "0.05", "--parallel", "off", "--quiet"]);
        if isolate {
            args.push("--isolate");
        }
        let out = s
            .command(&args)
            .env("TETHER_FAULTS_BARRIER", barrier.path())
            .output()
            .expect("run tether");
        let text = stderr(&out);
        if met {
            assert_eq!(out.status.code(), Some(0), "{text}");
            let csv = read_csv(&s.path().join("out.csv"));
            assert_eq!(csv.trailer, None);
            assert_eq!(last_time(&csv), 0.05);
        } else {
            assert_eq!(out.status.code(), Some(1), "{text}");
            assert!(text.contains("exit"), "{text}");
        }
    }
}

/// Both isolated instances end their host in the same step (`exit(3)` at
/// t = 0.5), their requests out at once: the run ends with the first in file
/// order, mass 1, every row to t = 0.5 kept.
#[test]
fn of_two_hosts_failing_in_one_step_the_first_in_file_order_is_reported() {
    let s = Scratch::new();
    let sys = both_faults(&s, 4, "", "");
    let out = s.run(&sys, "out.csv", &["--isolate", "--quiet"]);
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    let reason = "instance 'mass1': its host process exited with code 3 during fmi2DoStep at t=0.5";
    assert_eq!(
        text.lines().last().unwrap_or_default(),
        format!("error: run stopped; results up to t = 0.5 kept in out.csv (marked incomplete): {reason}")
    );
    assert_eq!(read_csv(&s.path().join("out.csv")).rows.len(), 501);
}
