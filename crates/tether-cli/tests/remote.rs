//! Instances on a host over TCP (docs/remote.md): a real `tether host` on
//! 127.0.0.1 and real `tether run` masters. Remote results are those in
//! process, bit for bit; a wrong token, a token file others can read, a killed
//! host, a lost connection, a master that vanished and a call past its
//! time-out end as the docs say, with nothing left on either side.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tether() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_tether"));
    command.env_remove("TETHER_LOG");
    command
}

/// Writes a token file of mode `mode` in `dir`.
fn token(dir: &Path, name: &str, text: &str, mode: u32) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
    path
}

const TOKEN: &str = "3f9a6c1e0b7d4a2f8e5c9b1d7a3f6e2c\n";

/// A `tether host` on a free loopback port, with its own `TMPDIR`; killed
/// when dropped.
struct Host {
    child: Child,
    port: u16,
    stderr: Arc<Mutex<String>>,
    tmp: tempfile::TempDir,
}

impl Host {
    fn start(token_file: &Path) -> Host {
        Host::start_with(token_file, &[])
    }

    fn start_with(token_file: &Path, extra: &[&str]) -> Host {
        let tmp = tempfile::tempdir().unwrap();
        let mut child = tether()
            .args(["host", "--listen", "127.0.0.1:0", "--token-file"])
            .arg(token_file)
            .args(extra)
            .env("TMPDIR", tmp.path())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stderr.take().unwrap());
        let mut first = String::new();
        lines.read_line(&mut first).unwrap();
        assert!(
            first.starts_with("tether host: listening on 127.0.0.1:")
                && first.contains("(this machine only"),
            "{first}"
        );
        let port = first["tether host: listening on 127.0.0.1:".len()..]
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let stderr = Arc::new(Mutex::new(String::new()));
        let sink = Arc::clone(&stderr);
        std::thread::spawn(move || {
            let mut rest = String::new();
            for line in lines.lines() {
                let Ok(line) = line else { break };
                rest.push_str(&line);
                rest.push('\n');
                *sink.lock().unwrap() = rest.clone();
            }
        });
        Host {
            child,
            port,
            stderr,
            tmp,
        }
    }
    fn url(&self) -> String {
        format!("tcp://127.0.0.1:{}", self.port)
    }
    fn stderr(&self) -> String {
        self.stderr.lock().unwrap().clone()
    }
    /// The host processes serving connections now.
    fn serving(&self) -> Vec<u32> {
        children(self.child.id())
    }
    /// Waits until no connection is served and the host's `TMPDIR` is empty
    /// (the unpacked FMUs gone); panics after 30 s.
    fn wait_clean(&self) {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let left: Vec<_> = std::fs::read_dir(self.tmp.path())
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .collect();
            let serving = self.serving();
            if left.is_empty() && serving.is_empty() {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "left on the host: {left:?}, processes {serving:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    fn kill(&mut self) {
        // SAFETY: a signal to the child started by this test, not yet reaped.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGKILL) };
        let _ = self.child.wait();
    }
}

impl Drop for Host {
    fn drop(&mut self) {
        self.kill();
    }
}

/// The child processes of `pid`.
fn children(pid: u32) -> Vec<u32> {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Vec::new();
    };
    tasks
        .flat_map(|t| {
            std::fs::read_to_string(t.unwrap().path().join("children"))
                .unwrap_or_default()
                .split_whitespace()
                .map(|p| p.parse().unwrap())
                .collect::<Vec<u32>>()
        })
        .collect()
}

/// `example` (examples/NAME.toml) with its FMUs' absolute paths, and with
/// `keys` after each `fmu = …` line.
fn system(dir: &Path, example: &str, keys: &str) -> PathBuf {
    // The FMUs are packaged, so the example runs.
    tether_fmu_build::workspace_fmu("oscillator").unwrap();
    tether_fmu_build::workspace_fmu("link").unwrap();
    tether_fmu_build::workspace_fmu("faults").unwrap();
    tether_fmu_build::workspace_fmu("body3d").unwrap();
    let fmus = root().join("target/fmus");
    let text = std::fs::read_to_string(root().join(format!("examples/{example}.toml"))).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("fmu = \"../target/fmus/") {
            let name = rest.trim_end_matches('"');
            out.push_str(&format!(
                "fmu = {:?}\n{keys}",
                fmus.join(name).display().to_string()
            ));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    let path = dir.join(format!("{example}.toml"));
    std::fs::write(&path, out).unwrap();
    path
}

fn run(dir: &Path, system: &Path, out: &str, extra: &[&str]) -> Output {
    tether()
        .arg("run")
        .arg(system)
        .args(["--out", out, "--quiet"])
        .args(extra)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Every instance of `example` on one host: the results are the same bytes
/// as in process; the host keeps nothing after the run.
fn same_as_in_process(example: &str, extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let keys = format!("host = {:?}\ntoken_file = \"token\"\n", host.url());
    let remote = system(dir.path(), example, &keys);
    let out = run(dir.path(), &remote, "remote.csv", extra);
    assert!(out.status.success(), "{}", stderr(&out));
    let local = system(dir.path(), example, "");
    let out = run(dir.path(), &local, "local.csv", extra);
    assert!(out.status.success(), "{}", stderr(&out));
    let a = std::fs::read(dir.path().join("remote.csv")).unwrap();
    let b = std::fs::read(dir.path().join("local.csv")).unwrap();
    assert!(a.len() > 1000 && a == b, "remote results differ");
    host.wait_clean();
    assert_eq!(host.stderr(), "", "the host complained");
}

#[test]
fn remote_oscillator_is_bit_for_bit_in_process() {
    same_as_in_process("oscillator", &[]);
}

#[test]
fn remote_oscillator_k1_is_bit_for_bit_in_process() {
    same_as_in_process("oscillator", &["--order", "1"]);
}

#[test]
fn remote_double_pendulum_is_bit_for_bit_in_process() {
    same_as_in_process("double_pendulum", &["--stop", "2"]);
}

#[test]
fn remote_3d_revolute_is_bit_for_bit_in_process() {
    same_as_in_process("3d_revolute", &["--stop", "0.2"]);
}

#[test]
fn remote_adaptive_steps_are_bit_for_bit_in_process() {
    same_as_in_process("oscillator", &["--step-rtol", "1e-4"]);
}

#[test]
fn remote_parallel_perturbed_runs_are_bit_for_bit_in_process() {
    same_as_in_process("double_pendulum", &["--stop", "0.5", "--parallel", "on"]);
}

/// `tether run --host --token-file` places every instance there.
#[test]
fn run_host_flag_places_every_instance() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let local = system(dir.path(), "oscillator", "");
    let flags = ["--host", &host.url(), "--token-file", "token"];
    let out = run(dir.path(), &local, "remote.csv", &flags);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = run(dir.path(), &local, "local.csv", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let a = std::fs::read(dir.path().join("remote.csv")).unwrap();
    let b = std::fs::read(dir.path().join("local.csv")).unwrap();
    assert!(a == b, "remote results differ");
    host.wait_clean();
}

/// The FMU unpacked on the host already (`fmu_on_host`): not sent.
#[test]
fn fmu_on_host_is_used_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let on_host = root().join("target/fmus/oscillator.fmu");
    let keys = format!(
        "host = {:?}\ntoken_file = \"token\"\nfmu_on_host = {:?}\n",
        host.url(),
        on_host.display().to_string()
    );
    let remote = system(dir.path(), "oscillator", &keys);
    let out = run(dir.path(), &remote, "remote.csv", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let local = system(dir.path(), "oscillator", "");
    let out = run(dir.path(), &local, "local.csv", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let a = std::fs::read(dir.path().join("remote.csv")).unwrap();
    let b = std::fs::read(dir.path().join("local.csv")).unwrap();
    assert!(a == b, "remote results differ");
    host.wait_clean();
}

/// The last line of stderr.
fn last_line(out: &Output) -> String {
    stderr(out).lines().last().unwrap_or_default().to_string()
}

/// Waits until `host`'s stderr has a line that `f` accepts; returns it.
fn wait_for_line(host: &Host, f: impl Fn(&str) -> bool) -> String {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if let Some(line) = host.stderr().lines().find(|l| f(l)) {
            return line.to_string();
        }
        assert!(Instant::now() < deadline, "host said: {}", host.stderr());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A master with another token: refused before any FMU is sent, one line on
/// each side.
#[test]
fn a_wrong_token_is_refused_on_both_sides() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    token(
        dir.path(),
        "other",
        "another token, 32 characters..\n",
        0o600,
    );
    let host = Host::start(&token_file);
    let keys = format!("host = {:?}\ntoken_file = \"other\"\n", host.url());
    let remote = system(dir.path(), "oscillator", &keys);
    let out = run(dir.path(), &remote, "out.csv", &[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(stderr(&out).lines().count(), 1, "{}", stderr(&out));
    let other = dir.path().join("other");
    assert_eq!(
        last_line(&out),
        format!(
            "error: cannot start the host process of instance 'mass1': host 127.0.0.1:{} did not prove it holds the token of {} (a different token, or not a Tether host)",
            host.port,
            other.display()
        )
    );
    let line = wait_for_line(&host, |l| l.contains("wrong token"));
    assert!(
        line.starts_with("tether host: 127.0.0.1:")
            && line.ends_with(": wrong token: the master holds another one (it says: the host did not prove the token)"),
        "{line}"
    );
    host.wait_clean();
}

/// A client that skips the check of the host's proof and sends a made-up
/// one is refused with one line; so is a client that is not a master.
#[test]
fn a_made_up_proof_and_a_stranger_are_refused() {
    use tether_fmi::remote::protocol::{Out, OK};
    use tether_fmi::remote::tcp;
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let mut stream = TcpStream::connect(("127.0.0.1", host.port)).unwrap();
    Out::default()
        .start(OK)
        .str(tcp::MAGIC)
        .u32(tether_fmi::remote::protocol::VERSION)
        .bytes(&[7; 32])
        .send(&mut stream)
        .unwrap();
    let mut frame = Vec::new();
    tcp::receive_at_most(&mut stream, &mut frame, 4096).unwrap();
    assert_eq!(frame[0], OK);
    Out::default()
        .start(OK)
        .bytes(&[0; 32])
        .send(&mut stream)
        .unwrap();
    tcp::receive_at_most(&mut stream, &mut frame, 4096).unwrap();
    let mut answer = tether_fmi::remote::protocol::In::new(&frame[1..]);
    assert_eq!(frame[0], tether_fmi::remote::protocol::ERR);
    assert_eq!(answer.str().unwrap(), "wrong token");
    wait_for_line(&host, |l| {
        l.ends_with("refused a master with a wrong token")
    });
    // A stranger: a huge frame length first; the host hangs up, allocating nothing.
    let mut stream = TcpStream::connect(("127.0.0.1", host.port)).unwrap();
    stream
        .write_all(b"\xff\xff\xff\x7fGET / HTTP/1.0\r\n\r\n")
        .unwrap();
    let mut rest = Vec::new();
    let _ = stream.read_to_end(&mut rest);
    assert!(rest.is_empty(), "{rest:?}");
    wait_for_line(&host, |l| l.contains("where at most 4096 are expected"));
    host.wait_clean();
}

/// A token file its group or others can read is refused by host and master.
#[test]
fn a_token_file_others_can_read_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o644);
    let out = tether()
        .args(["host", "--listen", "127.0.0.1:0", "--token-file"])
        .arg(&token_file)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        stderr(&out),
        format!(
            "error: token file {0} is accessible to others (mode 644); run chmod 600 {0}\n",
            token_file.display()
        )
    );
    let keys = "host = \"tcp://127.0.0.1:9\"\ntoken_file = \"token\"\n";
    let remote = system(dir.path(), "oscillator", keys);
    let out = run(dir.path(), &remote, "out.csv", &[]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        last_line(&out),
        format!(
            "error: cannot start the host process of instance 'mass1': token file {0} is accessible to others (mode 644); run chmod 600 {0}",
            token_file.display()
        )
    );
}

/// The rows of a results file and its trailer.
fn rows_and_trailer(path: &Path) -> (usize, Option<String>) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.ends_with('\n'), "a cut line");
    let rows = text.lines().skip(1).filter(|l| !l.starts_with('#')).count();
    (
        rows,
        text.lines()
            .last()
            .filter(|l| l.starts_with('#'))
            .map(str::to_string),
    )
}

/// Waits until the row at t = 0.5 is in `path`.
fn wait_for_the_row_at_0_5(path: &Path) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .any(|l| l.starts_with("0.5,"))
    {
        assert!(Instant::now() < deadline, "no rows");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A slow oscillator pair (every step sleeps 2 ms) on `url` through `token`.
fn slow_system(dir: &Path, url: &str, extra: &str) -> PathBuf {
    let keys = format!("host = {url:?}\ntoken_file = \"token\"\n{extra}");
    let sys = system(dir, "oscillator", &keys);
    let faults = root().join("target/fmus/faults.fmu");
    let text = std::fs::read_to_string(&sys).unwrap().replace(
        "parameters = { m = 2.0",
        "parameters = { delay = 0.002, m = 2.0",
    );
    // mass 2 is the faults FMU, in mode 0 the oscillator.
    let text = text.replacen(
        &format!(
            "{:?}",
            root()
                .join("target/fmus/oscillator.fmu")
                .display()
                .to_string()
        ),
        "MASS1",
        1,
    );
    let text = text
        .replacen(
            &format!(
                "{:?}",
                root()
                    .join("target/fmus/oscillator.fmu")
                    .display()
                    .to_string()
            ),
            &format!("{:?}", faults.display().to_string()),
            1,
        )
        .replace(
            "MASS1",
            &format!(
                "{:?}",
                root()
                    .join("target/fmus/oscillator.fmu")
                    .display()
                    .to_string()
            ),
        );
    std::fs::write(&sys, text).unwrap();
    sys
}

/// A run that lost its host midway: exit 1, the rows so far and the trailer
/// naming the lost connection.
fn check_lost(out: &Output, csv: &Path) {
    let text = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    let line = last_line(out);
    assert!(
        line.starts_with("error: run stopped; results up to t = ")
            && line.contains("kept in out.csv (marked incomplete): instance 'mass")
            && line.contains("': its host process lost the connection to 127.0.0.1:"),
        "{line}"
    );
    let (rows, trailer) = rows_and_trailer(csv);
    assert!(rows >= 501, "{rows} rows");
    let trailer = trailer.expect("a trailer");
    assert!(
        trailer.starts_with("# incomplete: instance 'mass")
            && trailer.contains("lost the connection"),
        "{trailer}"
    );
}

/// The host killed during the run (and with it the processes serving it).
#[test]
fn a_killed_host_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let mut host = Host::start(&token_file);
    let sys = slow_system(dir.path(), &host.url(), "");
    let master = tether()
        .arg("run")
        .arg(&sys)
        .args(["--out", "out.csv", "--quiet"])
        .current_dir(dir.path())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_the_row_at_0_5(&dir.path().join("out.csv"));
    let serving = host.serving();
    assert_eq!(serving.len(), 2, "one host process per instance");
    host.kill();
    let out = master.wait_with_output().unwrap();
    check_lost(&out, &dir.path().join("out.csv"));
    // The processes that served the instances ended with the host.
    let deadline = Instant::now() + Duration::from_secs(30);
    while serving
        .iter()
        .any(|p| Path::new(&format!("/proc/{p}")).exists())
    {
        assert!(Instant::now() < deadline, "{serving:?} still running");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A proxy on loopback between master and host that cuts every connection
/// when told.
struct Proxy {
    port: u16,
    streams: Arc<Mutex<Vec<TcpStream>>>,
}

impl Proxy {
    fn start(to: u16) -> Proxy {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let streams = Arc::new(Mutex::new(Vec::new()));
        let kept = Arc::clone(&streams);
        std::thread::spawn(move || {
            for master in listener.incoming() {
                let master = master.unwrap();
                let host = TcpStream::connect(("127.0.0.1", to)).unwrap();
                kept.lock().unwrap().push(master.try_clone().unwrap());
                kept.lock().unwrap().push(host.try_clone().unwrap());
                for (mut from, mut to) in [
                    (master.try_clone().unwrap(), host.try_clone().unwrap()),
                    (host, master),
                ] {
                    std::thread::spawn(move || {
                        let _ = std::io::copy(&mut from, &mut to);
                        let _ = to.shutdown(Shutdown::Write);
                    });
                }
            }
        });
        Proxy { port, streams }
    }
    fn cut(&self) {
        for s in self.streams.lock().unwrap().iter() {
            let _ = s.shutdown(Shutdown::Both);
        }
    }
}

/// The connection cut during the run: the master ends as after a crash; the
/// host cleans up after the master it lost.
#[test]
fn a_lost_connection_ends_the_run_and_the_host_cleans_up() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let proxy = Proxy::start(host.port);
    let url = format!("tcp://127.0.0.1:{}", proxy.port);
    let sys = slow_system(dir.path(), &url, "");
    let master = tether()
        .arg("run")
        .arg(&sys)
        .args(["--out", "out.csv", "--quiet"])
        .current_dir(dir.path())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_the_row_at_0_5(&dir.path().join("out.csv"));
    proxy.cut();
    let out = master.wait_with_output().unwrap();
    check_lost(&out, &dir.path().join("out.csv"));
    host.wait_clean();
}

/// A master killed during the run: its host processes and unpacked FMUs go;
/// the host serves the next master.
#[test]
fn the_host_cleans_up_after_a_master_that_vanished() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let sys = slow_system(dir.path(), &host.url(), "");
    let mut master = tether()
        .arg("run")
        .arg(&sys)
        .args(["--out", "out.csv", "--quiet"])
        .current_dir(dir.path())
        .spawn()
        .unwrap();
    wait_for_the_row_at_0_5(&dir.path().join("out.csv"));
    assert_eq!(host.serving().len(), 2);
    master.kill().unwrap();
    master.wait().unwrap();
    host.wait_clean();
    // Two masters at once, each with its own instances.
    let local = system(dir.path(), "oscillator", "");
    let keys = format!("host = {:?}\ntoken_file = \"token\"\n", host.url());
    let remote = system(dir.path(), "oscillator", &keys);
    let masters: Vec<_> = ["a.csv", "b.csv"]
        .iter()
        .map(|out| {
            tether()
                .arg("run")
                .arg(&remote)
                .args(["--out", out, "--quiet"])
                .current_dir(dir.path())
                .spawn()
                .unwrap()
        })
        .collect();
    for mut m in masters {
        assert!(m.wait().unwrap().success());
    }
    let out = run(dir.path(), &local, "local.csv", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let local = std::fs::read(dir.path().join("local.csv")).unwrap();
    for f in ["a.csv", "b.csv"] {
        assert!(std::fs::read(dir.path().join(f)).unwrap() == local, "{f}");
    }
    host.wait_clean();
}

/// A call past the instance's `call_timeout` on the host: the run ends as an
/// isolated instance's does.
#[test]
fn a_call_past_its_time_out_ends_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let sys = slow_system(dir.path(), &host.url(), "call_timeout = 0.25\n");
    let text = std::fs::read_to_string(&sys)
        .unwrap()
        .replace("delay = 0.002,", "mode = 7, pause = 2.0,");
    std::fs::write(&sys, text).unwrap();
    let out = run(dir.path(), &sys, "out.csv", &[]);
    stopped_at_0_5(
        dir.path(),
        &out,
        "instance 'mass2': fmi2DoStep at t=0.5 did not return within the call time-out of 0.25 s; its host process was killed",
    );
    host.wait_clean();
}

/// The run ended with exit 1 and `error` after t = 0.5: the one error line,
/// every row up to 0.5 in out.csv and the trailer naming it.
fn stopped_at_0_5(dir: &Path, out: &Output, reason: &str) {
    assert_eq!(out.status.code(), Some(1), "{}", stderr(out));
    assert_eq!(
        last_line(out),
        format!("error: run stopped; results up to t = 0.5 kept in out.csv (marked incomplete): {reason}")
    );
    let (rows, trailer) = rows_and_trailer(&dir.join("out.csv"));
    assert_eq!(rows, 501);
    assert_eq!(trailer, Some(format!("# incomplete: {reason}")));
}

/// An FMU that crashes on the host: its host process ends, the listener tells
/// the master how, the run ends as after a crash in isolation, and the host
/// goes on serving.
#[test]
fn a_crashing_fmu_on_the_host_ends_the_run_naming_the_signal() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start(&token_file);
    let sys = slow_system(dir.path(), &host.url(), "");
    let text = std::fs::read_to_string(&sys)
        .unwrap()
        .replace("delay = 0.002,", "mode = 1,");
    std::fs::write(&sys, text).unwrap();
    let out = run(dir.path(), &sys, "out.csv", &[]);
    let reason = format!(
        "instance 'mass2': its host process on 127.0.0.1:{} was killed by signal 11 (SIGSEGV) during fmi2DoStep at t=0.5",
        host.port
    );
    stopped_at_0_5(dir.path(), &out, &reason);
    host.wait_clean();
    same_on(&host, dir.path());
}

/// The oscillator on `host` gives the in-process results (the host still serves).
fn same_on(host: &Host, dir: &Path) {
    let keys = format!("host = {:?}\ntoken_file = \"token\"\n", host.url());
    let remote = system(dir, "oscillator", &keys);
    let out = run(dir, &remote, "again.csv", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let local = system(dir, "oscillator", "");
    let out = run(dir, &local, "local.csv", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        std::fs::read(dir.join("again.csv")).unwrap()
            == std::fs::read(dir.join("local.csv")).unwrap()
    );
}

/// Bad remote keys and an unreachable host: one line naming the instance and
/// the key, exit code 1.
#[test]
fn bad_remote_keys_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    token(dir.path(), "token", TOKEN, 0o600);
    // A port nobody listens on: bound, then closed.
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let sys = dir.path().join("oscillator.toml");
    for (keys, error) in [
        (
            "host = \"http://127.0.0.1:1\"\ntoken_file = \"token\"\n".to_string(),
            "instance 'mass1': host: 'http://127.0.0.1:1' is not a host address: expected tcp://ADDR:PORT".to_string(),
        ),
        (
            "host = \"tcp://127.0.0.1:1\"\n".into(),
            "instance 'mass1': host: needs token_file, the file holding the host's token".into(),
        ),
        (
            "token_file = \"token\"\n".into(),
            "instance 'mass1': token_file: given without host".into(),
        ),
        (
            "host = \"tcp://127.0.0.1:1\"\ntoken_file = \"token\"\nfmu_on_host = \"fmus/x.fmu\"\n".into(),
            "instance 'mass1': fmu_on_host: 'fmus/x.fmu' is not an absolute path on the host".into(),
        ),
        (
            format!("host = \"tcp://127.0.0.1:{port}\"\ntoken_file = \"token\"\n"),
            format!("error: cannot start the host process of instance 'mass1': cannot connect to host 127.0.0.1:{port}: Connection refused (os error 111)"),
        ),
    ] {
        system(dir.path(), "oscillator", &keys);
        let out = run(dir.path(), &sys, "out.csv", &[]);
        assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
        assert_eq!(stderr(&out).lines().count(), 1, "{}", stderr(&out));
        let line = last_line(&out);
        assert!(line.starts_with("error: ") && line.ends_with(&error), "{line}");
    }
}

/// A host that accepts the connection and never answers: after the opening
/// time-out (30 s) one line names the host and the time-out, exit code 1.
#[test]
fn a_silent_host_ends_with_its_time_out_named() {
    let dir = tempfile::tempdir().unwrap();
    token(dir.path(), "token", TOKEN, 0o600);
    let silent = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = silent.local_addr().unwrap();
    let held = std::thread::spawn(move || silent.incoming().take(1).collect::<Vec<_>>());
    let keys = format!("host = \"tcp://{address}\"\ntoken_file = \"token\"\n");
    let sys = system(dir.path(), "oscillator", &keys);
    let start = Instant::now();
    let out = run(dir.path(), &sys, "out.csv", &[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(stderr(&out).lines().count(), 1, "{}", stderr(&out));
    let line = last_line(&out);
    assert!(
        line.ends_with(&format!(
            "no answer from host {address} within 30 s (read time-out)"
        )),
        "{line}"
    );
    assert!(start.elapsed() >= Duration::from_secs(30));
    drop(held);
}

/// `resources` (placement on Dask workers from Python): `tether run` runs the
/// instances here, bit for bit as without the key, and says so in one note;
/// a value that is not a table of positive numbers is one line naming it.
#[test]
fn resources_are_noted_by_the_cli_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let sys = dir.path().join("oscillator.toml");
    system(
        dir.path(),
        "oscillator",
        "resources = { licence = 1, gpu = 0.5 }\n",
    );
    let out = tether()
        .arg("run")
        .arg(&sys)
        .args(["--out", "placed.csv", "--stop", "0.1"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let notes: Vec<_> = stderr(&out)
        .lines()
        .filter(|l| l.starts_with("note: resources"))
        .map(str::to_string)
        .collect();
    assert_eq!(
        notes,
        ["note: resources of mass1, mass2 place instances on Dask workers from Python (tether.run(system, client=…)); tether run runs them on this machine"]
    );
    system(dir.path(), "oscillator", "");
    let out = run(dir.path(), &sys, "plain.csv", &["--stop", "0.1"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        std::fs::read(dir.path().join("placed.csv")).unwrap()
            == std::fs::read(dir.path().join("plain.csv")).unwrap()
    );
    for (value, error) in [
        (
            "{ licence = \"yes\" }",
            "invalid type: string \"yes\", expected a number of units of a Dask worker resource, e.g. { licence = 1 }",
        ),
        (
            "\"licence\"",
            "invalid type: string \"licence\", expected a table of Dask worker resources, e.g. { licence = 1 }",
        ),
        (
            "{ licence = 0 }",
            "instance 'mass1': resources: licence = 0: expected a finite number of units > 0",
        ),
        (
            "{ licence = -2.5 }",
            "instance 'mass1': resources: licence = -2.5: expected a finite number of units > 0",
        ),
    ] {
        system(dir.path(), "oscillator", &format!("resources = {value}\n"));
        let out = run(dir.path(), &sys, "out.csv", &[]);
        assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
        assert_eq!(stderr(&out).lines().count(), 1, "{}", stderr(&out));
        let line = last_line(&out);
        assert!(line.starts_with("error: system file ") && line.ends_with(error), "{line}");
    }
}

/// Once its FMU is ready a master's requests are bounded by --max-frame-mib:
/// an authenticated master that announces a larger frame is refused before
/// the host allocates anything for it, and the host serves on.
#[test]
fn a_request_above_the_frame_limit_is_refused() {
    use tether_fmi::remote::protocol::{In, Out, OK, VERSION};
    use tether_fmi::remote::tcp;
    let dir = tempfile::tempdir().unwrap();
    let token_file = token(dir.path(), "token", TOKEN, 0o600);
    let host = Host::start_with(&token_file, &["--max-frame-mib", "1"]);
    let fmu = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let mut stream = TcpStream::connect(("127.0.0.1", host.port)).unwrap();
    let master = [7u8; 32];
    Out::default()
        .start(OK)
        .str(tcp::MAGIC)
        .u32(VERSION)
        .bytes(&master)
        .send(&mut stream)
        .unwrap();
    let mut frame = Vec::new();
    tcp::receive_at_most(&mut stream, &mut frame, 4096).unwrap();
    assert_eq!(frame[0], OK);
    let mut hello = In::new(&frame[1..]);
    hello.u32().unwrap();
    let nonce = hello.bytes().unwrap().to_vec();
    let proof = tcp::proof(TOKEN.trim().as_bytes(), "master", &master, &nonce);
    Out::default()
        .start(OK)
        .bytes(&proof)
        .send(&mut stream)
        .unwrap();
    tcp::receive_at_most(&mut stream, &mut frame, 4096).unwrap();
    assert_eq!(frame[0], OK, "the proof was refused");
    Out::default()
        .start(tcp::FMU_PATH)
        .str(fmu.to_str().unwrap())
        .send(&mut stream)
        .unwrap();
    tcp::receive_at_most(&mut stream, &mut frame, 4096).unwrap();
    assert_eq!(frame[0], OK, "the FMU was refused");
    // Served by a host process now: a request of 512 MiB announced.
    stream.write_all(&(512u32 << 20).to_le_bytes()).unwrap();
    let _ = stream.write_all(&[0; 64]);
    let mut rest = Vec::new();
    let _ = stream.read_to_end(&mut rest);
    assert!(rest.is_empty(), "{rest:?}");
    wait_for_line(&host, |l| {
        l.ends_with("a frame of 536870912 bytes where at most 1048576 are expected")
    });
    host.wait_clean();
    same_on(&host, dir.path());
}
