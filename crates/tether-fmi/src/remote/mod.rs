//! Out-of-process instances: [`RemoteInstance`] runs an FMU instance in a host
//! process of its own (`tether-fmi-host`), so that a crash, `exit()`, `abort()`
//! or endless loop inside the FMU ends that process, not the caller's; every
//! FMI call crosses a pair of pipes ([`protocol`]), FMU states included:
//! they live in the host, named by slots, and cross as bytes only through
//! [`RemoteInstance::serialize_state`].
//!
//! The host executable is found by [`host_command`] (docs/reliability.md).

pub mod protocol;

use std::ffi::OsString;
use std::io::{self, BufReader};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::time::Duration;

use crate::error::{Error, Result};
use crate::fmu::{Fmu, InstanceOptions};
use crate::model_description::{ModelDescription, ValueReference};
use protocol::{op, In, Out};

/// The environment variable naming the host executable; it overrides every
/// other way of finding it.
pub const HOST_ENV: &str = "TETHER_FMI_HOST";

/// The host executable's file name.
pub const HOST_NAME: &str = "tether-fmi-host";

/// How to start a host process: the program and its first arguments.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostCommand {
    /// The executable.
    pub program: PathBuf,
    /// Arguments before any the library adds (none today).
    pub args: Vec<OsString>,
}

static CONFIGURED: Mutex<Option<HostCommand>> = Mutex::new(None);

/// Sets the host a program provides itself (the `tether` binary is its own
/// host: `tether __fmi-host`); [`HOST_ENV`] still takes precedence.
pub fn set_host(command: HostCommand) {
    *CONFIGURED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(command);
}

/// The host to start, searched in this order: the [`HOST_ENV`] variable; the
/// one set by [`set_host`]; `tether-fmi-host` next to the current executable
/// or in its parent directory (test binaries of cargo live in `deps/`); the
/// `PATH`.
pub fn host_command() -> std::result::Result<HostCommand, String> {
    let plain = |program: PathBuf| HostCommand {
        program,
        args: Vec::new(),
    };
    if let Some(path) = std::env::var_os(HOST_ENV).filter(|p| !p.is_empty()) {
        return Ok(plain(PathBuf::from(path)));
    }
    if let Some(command) = CONFIGURED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone()
    {
        return Ok(command);
    }
    let exe = std::env::current_exe().ok();
    let beside = exe.iter().flat_map(|exe| exe.ancestors().skip(1).take(2));
    let on_path = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .unwrap_or_default();
    beside
        .map(Path::to_path_buf)
        .chain(on_path)
        .map(|dir| dir.join(HOST_NAME))
        .find(|p| p.is_file())
        .map(plain)
        .ok_or_else(|| {
            format!(
                "no {HOST_NAME} executable next to this program nor on the PATH; set {HOST_ENV} to its path"
            )
        })
}

/// An FMU instance running in a host process of its own.
#[derive(Debug)]
pub struct RemoteInstance {
    child: Child,
    reader: BufReader<ChildStdout>,
    /// `None` once closed (the host then ends).
    writer: Option<ChildStdin>,
    out: Out,
    reply: Vec<u8>,
    name: crate::current::Name,
    fmu: Fmu,
    time: f64,
    fatal: bool,
    /// How the host process ended, once it did.
    ended: Option<String>,
    timeout: Option<Duration>,
    /// Readable once the host process has ended ([`watch_exit`]), also while a
    /// process it started still holds the reply pipe.
    exit_watch: Option<OwnedFd>,
}

/// `exited with code 3`, `was killed by signal 11 (SIGSEGV)`.
pub fn describe_exit(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exited with code {code}"),
        (None, Some(signal)) => {
            let name = match signal {
                1 => " (SIGHUP)",
                2 => " (SIGINT)",
                4 => " (SIGILL)",
                6 => " (SIGABRT)",
                7 => " (SIGBUS)",
                8 => " (SIGFPE)",
                9 => " (SIGKILL)",
                11 => " (SIGSEGV)",
                13 => " (SIGPIPE)",
                15 => " (SIGTERM)",
                _ => "",
            };
            format!("was killed by signal {signal}{name}")
        }
        _ => format!("ended ({status})"),
    }
}

impl RemoteInstance {
    /// Starts a host process and instantiates `fmu` in it as `name`: the host
    /// opens the FMU's unpacked directory in place (no second extraction).
    /// Each call waits at most `timeout` for its reply; after that the host is
    /// killed and the call fails with [`Error::CallTimeout`].
    pub fn new(
        fmu: &Fmu,
        name: &str,
        options: InstanceOptions,
        timeout: Option<Duration>,
    ) -> Result<RemoteInstance> {
        let start_error = |reason: String| Error::HostStart {
            instance: name.to_string(),
            reason,
        };
        let command = host_command().map_err(start_error)?;
        // Requests go to the host's standard input, replies come from its
        // standard output (the host moves what the FMU prints to stderr); its
        // own process group keeps a terminal's Ctrl-C away from it (the master
        // decides what to stop) and holds the processes its FMU starts, which
        // end with it ([`RemoteInstance::reap`]).
        let mut child = Command::new(&command.program)
            .args(&command.args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .env(
                crate::logger::RATE_LIMIT_ENV,
                crate::logger::rate_limit_text(),
            )
            .process_group(0)
            .spawn()
            .map_err(|e| start_error(format!("{}: {e}", command.program.display())))?;
        let (Some(writer), Some(reader)) = (child.stdin.take(), child.stdout.take()) else {
            unreachable!("both are piped")
        };
        let exit_watch = watch_exit(child.id());
        let mut remote = RemoteInstance {
            child,
            reader: BufReader::with_capacity(1 << 16, reader),
            writer: Some(writer),
            out: Out::default(),
            reply: Vec::new(),
            name: crate::current::Name::new(name),
            fmu: fmu.clone(),
            time: 0.0,
            fatal: false,
            ended: None,
            timeout,
            exit_watch,
        };
        // The host logs FMU messages itself, at the level they are wanted here.
        let target = format!("fmu::{name}");
        let fmu_level = [
            log::Level::Trace,
            log::Level::Debug,
            log::Level::Info,
            log::Level::Warn,
            log::Level::Error,
        ]
        .into_iter()
        .find(|l| log::log_enabled!(target: &target, *l))
        .map_or(0, |l| l as u8);
        remote
            .out
            .start(op::HELLO)
            .u32(protocol::VERSION)
            .u8(log::max_level() as u8)
            .u8(fmu_level);
        remote.call("fmi2Instantiate")?;
        let version = In::new(&remote.reply[1..])
            .u32()
            .map_err(|e| remote.protocol_error(e))?;
        if version != protocol::VERSION {
            return Err(start_error(format!(
                "{} speaks protocol version {version}, this library {}; use the host of the same Tether version",
                command.program.display(),
                protocol::VERSION
            )));
        }
        let dir = fmu.directory().to_str().ok_or_else(|| {
            start_error(format!(
                "the FMU directory {} is not UTF-8",
                fmu.directory().display()
            ))
        })?;
        remote
            .out
            .start(op::INSTANTIATE)
            .str(dir)
            .str(name)
            .bool(options.logging_on)
            .bool(options.visible);
        remote.call("fmi2Instantiate")?;
        Ok(remote)
    }

    /// Sends the request in `self.out`, waits for the reply in `self.reply`.
    fn call(&mut self, function: &'static str) -> Result<()> {
        if let Some(how) = &self.ended {
            return Err(Error::HostEnded {
                instance: self.name.to_string(),
                function,
                time: self.time,
                how: how.clone(),
            });
        }
        let entered = crate::current::Entered::new(function, &self.name, self.time);
        let received = match &mut self.writer {
            Some(writer) => self.out.send(writer).and_then(|()| {
                wait_readable(&self.reader, self.exit_watch.as_ref(), self.timeout)?;
                protocol::receive(&mut self.reader, &mut self.reply)
            }),
            None => Err(io::ErrorKind::BrokenPipe.into()),
        };
        drop(entered);
        match received {
            Ok(true) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                return Err(self.timed_out(function))
            }
            Ok(false) | Err(_) => return Err(self.host_ended(function)),
        }
        match self.reply.first() {
            Some(&protocol::OK) => Ok(()),
            Some(&protocol::ERR) => {
                let error = In::new(&self.reply[1..])
                    .error(self.name.as_str())
                    .map_err(|e| self.protocol_error(e))?;
                if matches!(error, Error::Fatal { .. }) {
                    self.fatal = true;
                }
                Err(error)
            }
            _ => Err(self.protocol_error(io::ErrorKind::InvalidData.into())),
        }
    }

    /// The host did not answer in time: kill it.
    #[cold]
    fn timed_out(&mut self, function: &'static str) -> Error {
        self.kill_group();
        let status = self.reap();
        self.ended = Some(match status {
            Ok(status) => format!("{} after the call time-out", describe_exit(status)),
            Err(e) => format!("could not be waited for ({e})"),
        });
        Error::CallTimeout {
            instance: self.name.to_string(),
            function,
            time: self.time,
            seconds: self.timeout.map_or(0.0, |t| t.as_secs_f64()),
        }
    }

    /// The connection broke: the host ended; say how.
    #[cold]
    fn host_ended(&mut self, function: &'static str) -> Error {
        let how = match self.reap() {
            Ok(status) => describe_exit(status),
            Err(e) => format!("could not be waited for ({e})"),
        };
        self.ended = Some(how.clone());
        Error::HostEnded {
            instance: self.name.to_string(),
            function,
            time: self.time,
            how,
        }
    }

    #[cold]
    fn protocol_error(&mut self, e: io::Error) -> Error {
        self.kill_group();
        let _ = self.reap();
        let how = format!("sent a malformed reply ({e}) and was stopped");
        self.ended = Some(how.clone());
        Error::Host {
            instance: self.name.to_string(),
            message: format!("instance '{}': its host process {how}", self.name),
        }
    }

    /// Kills the host and every process of its group (those its FMU started).
    fn kill_group(&self) {
        if let Ok(pid) = libc::pid_t::try_from(self.child.id()) {
            // SAFETY: a signal to the process group the host leads (started with
            // process_group(0)); the host is not reaped yet, so its id is not reused.
            unsafe { libc::killpg(pid, libc::SIGKILL) };
        }
    }

    /// Waits for the host to end, kills what is left of its process group (the
    /// processes its FMU started, which must not outlive it), then reaps it.
    fn reap(&mut self) -> io::Result<ExitStatus> {
        let pid = self.child.id() as libc::id_t;
        // SAFETY: waitid on the host, the child of this process, with a zeroed
        // siginfo to write into; WNOWAIT leaves it unreaped, so the process group
        // id stays its own until `wait` below.
        unsafe {
            let mut info: libc::siginfo_t = std::mem::zeroed();
            while libc::waitid(libc::P_PID, pid, &mut info, libc::WEXITED | libc::WNOWAIT) < 0
                && io::Error::last_os_error().kind() == io::ErrorKind::Interrupted
            {}
        }
        self.kill_group();
        self.child.wait()
    }

    /// The results of the last reply after the status byte.
    fn results(&self) -> In<'_> {
        In::new(&self.reply[1..])
    }

    /// Reals of the last reply into `out`.
    /// Values read from a reply into `out`, which must have their number.
    fn copy_reply<T: Copy>(
        &mut self,
        read: io::Result<()>,
        values: &[T],
        out: &mut [T],
    ) -> Result<()> {
        let read = read.and_then(|()| {
            if values.len() == out.len() {
                Ok(())
            } else {
                Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    "wrong number of values",
                ))
            }
        });
        read.map_err(|e| self.protocol_error(e))?;
        out.copy_from_slice(values);
        Ok(())
    }

    fn read_reals(&mut self, out: &mut [f64]) -> Result<()> {
        let read = In::new(&self.reply[1..]).f64s_into(out);
        read.map_err(|e| self.protocol_error(e))
    }

    /// The instance name.
    pub fn name(&self) -> &str {
        self.name.as_str()
    }

    /// The FMU's model description.
    pub fn model_description(&self) -> &ModelDescription {
        self.fmu.model_description()
    }

    /// The communication time as tracked here.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Whether the FMU returned `fmi2Fatal`.
    pub fn is_fatal(&self) -> bool {
        self.fatal
    }

    /// The host's process id.
    pub fn host_pid(&self) -> u32 {
        self.child.id()
    }

    /// A request without an FMI call and its reply: the transport's round trip.
    pub fn ping(&mut self) -> Result<()> {
        self.out.start(op::PING);
        self.call("an FMI function")
    }

    /// `fmi2SetupExperiment`.
    pub fn setup_experiment(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<()> {
        self.out
            .start(op::SETUP_EXPERIMENT)
            .bool(tolerance.is_some())
            .f64(tolerance.unwrap_or(0.0))
            .f64(start)
            .bool(stop.is_some())
            .f64(stop.unwrap_or(0.0));
        self.call("fmi2SetupExperiment")?;
        self.time = start;
        Ok(())
    }

    /// `fmi2EnterInitializationMode`.
    pub fn enter_initialization_mode(&mut self) -> Result<()> {
        self.out.start(op::ENTER_INITIALIZATION_MODE);
        self.call("fmi2EnterInitializationMode")
    }

    /// `fmi2ExitInitializationMode`.
    pub fn exit_initialization_mode(&mut self) -> Result<()> {
        self.out.start(op::EXIT_INITIALIZATION_MODE);
        self.call("fmi2ExitInitializationMode")
    }

    /// `fmi2Terminate`.
    pub fn terminate(&mut self) -> Result<()> {
        self.out.start(op::TERMINATE);
        self.call("fmi2Terminate")
    }

    /// `fmi2Reset`.
    pub fn reset(&mut self) -> Result<()> {
        self.out.start(op::RESET);
        self.call("fmi2Reset")
    }

    /// `fmi2SetReal`.
    pub fn set_real(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        self.out.start(op::SET_REAL).u32s(vrs).f64s(values);
        self.call("fmi2SetReal")
    }

    /// `fmi2GetReal` into `out`.
    pub fn get_real(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        self.out.start(op::GET_REAL).u32s(vrs).u32(count(out.len()));
        self.call("fmi2GetReal")?;
        self.read_reals(out)
    }

    /// `fmi2GetInteger` into `out`.
    pub fn get_integer(&mut self, vrs: &[ValueReference], out: &mut [i32]) -> Result<()> {
        self.out
            .start(op::GET_INTEGER)
            .u32s(vrs)
            .u32(count(out.len()));
        self.call("fmi2GetInteger")?;
        let mut values = Vec::with_capacity(out.len());
        let read = In::new(&self.reply[1..]).i32s(&mut values);
        self.copy_reply(read, &values, out)
    }

    /// `fmi2GetBoolean` into `out`.
    pub fn get_boolean(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.out
            .start(op::GET_BOOLEAN)
            .u32s(vrs)
            .u32(count(out.len()));
        self.call("fmi2GetBoolean")?;
        let mut values = Vec::with_capacity(out.len());
        let read = In::new(&self.reply[1..]).bools(&mut values);
        self.copy_reply(read, &values, out)
    }

    /// `fmi2SetInteger`.
    pub fn set_integer(&mut self, vrs: &[ValueReference], values: &[i32]) -> Result<()> {
        self.out.start(op::SET_INTEGER).u32s(vrs).i32s(values);
        self.call("fmi2SetInteger")
    }

    /// `fmi2SetBoolean`.
    pub fn set_boolean(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.out.start(op::SET_BOOLEAN).u32s(vrs).bools(values);
        self.call("fmi2SetBoolean")
    }

    /// `fmi2SetString`.
    pub fn set_string(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        let out = self
            .out
            .start(op::SET_STRING)
            .u32s(vrs)
            .u32(values.len() as u32);
        for v in values {
            out.str(v);
        }
        self.call("fmi2SetString")
    }

    /// The coupled inputs of a run in one request: their values, then their
    /// derivatives (FMI 2.0: `fmi2SetReal`, `fmi2SetRealInputDerivatives`).
    pub fn set_coupled_inputs(&mut self, inputs: &crate::interface::Inputs<'_>) -> Result<()> {
        self.out
            .start(op::SET_INPUTS)
            .u32s(inputs.vrs)
            .f64s(inputs.values)
            .u32s(inputs.derivative_vrs)
            .i32s(inputs.orders)
            .f64s(inputs.derivatives);
        self.call("fmi2SetReal")
    }

    /// `fmi2GetRealOutputDerivatives` into `out`.
    pub fn get_real_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        self.out
            .start(op::GET_REAL_OUTPUT_DERIVATIVES)
            .u32s(vrs)
            .i32s(orders);
        self.call("fmi2GetRealOutputDerivatives")?;
        self.read_reals(out)
    }

    /// `fmi2DoStep`; on success the tracked time becomes `t + h`.
    pub fn do_step(&mut self, t: f64, h: f64, no_set_fmu_state_prior: bool) -> Result<()> {
        self.time = t;
        self.out
            .start(op::DO_STEP)
            .f64(t)
            .f64(h)
            .bool(no_set_fmu_state_prior);
        self.call("fmi2DoStep")?;
        self.time = t + h;
        Ok(())
    }

    /// `fmi2GetFMUstate` into the host's state `slot` (reusing the state there).
    pub fn save_state(&mut self, slot: u32) -> Result<()> {
        self.out.start(op::SAVE_STATE).u32(slot);
        self.call("fmi2GetFMUstate")
    }

    /// `fmi2SetFMUstate` from the host's state `slot`.
    pub fn restore_state(&mut self, slot: u32) -> Result<()> {
        self.out.start(op::RESTORE_STATE).u32(slot);
        self.call("fmi2SetFMUstate")
    }

    /// `fmi2FreeFMUstate` of the host's state `slot`, if there is one.
    pub fn free_state(&mut self, slot: u32) -> Result<()> {
        self.out.start(op::FREE_STATE).u32(slot);
        self.call("fmi2FreeFMUstate")
    }

    /// `fmi2SerializeFMUstate` of the host's state `slot` into `out`.
    pub fn serialize_state(&mut self, slot: u32, out: &mut Vec<u8>) -> Result<()> {
        self.out.start(op::SERIALIZE_STATE).u32(slot);
        self.call("fmi2SerializeFMUstate")?;
        let bytes = self.results().bytes().map(<[u8]>::to_vec);
        let bytes = bytes.map_err(|e| self.protocol_error(e))?;
        out.clear();
        out.extend_from_slice(&bytes);
        Ok(())
    }

    /// `fmi2DeSerializeFMUstate` of `bytes` into the host's state `slot`.
    pub fn deserialize_state(&mut self, slot: u32, bytes: &[u8]) -> Result<()> {
        self.out.start(op::DESERIALIZE_STATE).u32(slot).bytes(bytes);
        self.call("fmi2DeSerializeFMUstate")
    }
}

/// A descriptor that becomes readable when process `pid` ends (Linux's pidfd),
/// or `None` where there is none (the pipe's end is then the only sign).
fn watch_exit(pid: u32) -> Option<OwnedFd> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: pidfd_open on the host just started (not reaped); the
        // descriptor it returns (close-on-exec) is owned from here on.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
        let fd = libc::c_int::try_from(fd).ok().filter(|fd| *fd >= 0)?;
        // SAFETY: a new descriptor nobody else owns.
        Some(unsafe { OwnedFd::from_raw_fd(fd) })
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = pid;
        None
    }
}

/// Waits until the reply pipe has data (or was closed) for at most `timeout`
/// (`TimedOut` after it), or until the host ends (`UnexpectedEof`): a process
/// the FMU started without `exec` holds a copy of the pipe, which then stays
/// open. Without a time-out nor an exit watch the read itself waits.
fn wait_readable(
    reader: &BufReader<ChildStdout>,
    exit_watch: Option<&OwnedFd>,
    timeout: Option<Duration>,
) -> io::Result<()> {
    if !reader.buffer().is_empty() || (timeout.is_none() && exit_watch.is_none()) {
        return Ok(());
    }
    let deadline = timeout.map(|t| std::time::Instant::now() + t);
    loop {
        let ms = deadline.map_or(-1, |deadline| {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            libc::c_int::try_from(left.as_millis().max(1)).unwrap_or(libc::c_int::MAX)
        });
        let mut polls = [
            libc::pollfd {
                fd: reader.get_ref().as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            },
            libc::pollfd {
                fd: exit_watch.map_or(-1, AsRawFd::as_raw_fd), // -1: ignored
                events: libc::POLLIN,
                revents: 0,
            },
        ];
        // SAFETY: two valid pollfds on descriptors owned by the caller, alive here.
        let n = unsafe { libc::poll(polls.as_mut_ptr(), 2, ms) };
        if n > 0 && polls[0].revents != 0 {
            return Ok(()); // data, or the host closed its end (the read says which)
        }
        if n > 0 {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the host process ended",
            ));
        }
        if n < 0 && io::Error::last_os_error().kind() != io::ErrorKind::Interrupted {
            return Err(io::Error::last_os_error());
        }
        if n == 0 && deadline.is_some_and(|d| std::time::Instant::now() >= d) {
            return Err(io::ErrorKind::TimedOut.into());
        }
    }
}

impl Drop for RemoteInstance {
    fn drop(&mut self) {
        if self.ended.is_none() {
            // fmi2FreeInstance in the host, then it ends on the closed request pipe;
            // a host that does not answer within the time-out (or 10 s) is killed.
            self.timeout = Some(self.timeout.unwrap_or(Duration::from_secs(10)));
            self.out.start(op::FREE_INSTANCE);
            if self.call("fmi2FreeInstance").is_err() && self.ended.is_none() {
                self.kill_group();
            }
        }
        self.writer = None;
        if self.ended.is_none() {
            let _ = self.reap();
        }
    }
}

impl crate::interface::FmuInstance for RemoteInstance {
    fn name(&self) -> &str {
        self.name.as_str()
    }
    fn model_description(&self) -> &ModelDescription {
        self.fmu.model_description()
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn is_fatal(&self) -> bool {
        self.fatal
    }
    fn set_debug_logging(&mut self, _on: bool, _categories: &[&str]) -> Result<()> {
        // The host sets the FMU's logging itself, from the levels the master
        // sent at its start.
        Ok(())
    }
    fn setup(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Result<()> {
        self.setup_experiment(tolerance, start, stop)
    }
    fn enter_initialization(&mut self) -> Result<()> {
        self.enter_initialization_mode()
    }
    fn exit_initialization(&mut self) -> Result<()> {
        self.exit_initialization_mode()
    }
    fn get_reals(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        self.get_real(vrs, out)
    }
    fn set_reals(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        self.set_real(vrs, values)
    }
    fn get_integers(&mut self, vrs: &[ValueReference], out: &mut [i32]) -> Result<()> {
        self.get_integer(vrs, out)
    }
    fn set_integers(&mut self, vrs: &[ValueReference], values: &[i32]) -> Result<()> {
        self.set_integer(vrs, values)
    }
    fn get_booleans(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.get_boolean(vrs, out)
    }
    fn set_booleans(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.set_boolean(vrs, values)
    }
    fn get_strings(&mut self, _vrs: &[ValueReference], _out: &mut [String]) -> Result<()> {
        Err(Error::InvalidArgument {
            function: "fmi2GetString",
            instance: self.name.to_string(),
            message: "String values are not read from isolated instances".into(),
        })
    }
    fn set_strings(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        self.set_string(vrs, values)
    }
    fn set_inputs(&mut self, inputs: &crate::interface::Inputs<'_>) -> Result<()> {
        self.set_coupled_inputs(inputs)
    }
    fn get_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        self.get_real_output_derivatives(vrs, orders, out)
    }
    fn step(&mut self, t: f64, h: f64) -> Result<()> {
        // The host's instance turned a request to end the simulation into
        // `Error::TerminationRequested` already (the same `step` as in process).
        self.do_step(t, h, true)
    }
    fn save(&mut self, slot: crate::interface::Slot) -> Result<()> {
        self.save_state(slot as u32)
    }
    fn restore(&mut self, slot: crate::interface::Slot) -> Result<()> {
        self.restore_state(slot as u32)
    }
    fn free(&mut self, slot: crate::interface::Slot) -> Result<()> {
        self.free_state(slot as u32)
    }
    fn serialize(&mut self, slot: crate::interface::Slot, out: &mut Vec<u8>) -> Result<()> {
        self.serialize_state(slot as u32, out)
    }
    fn deserialize(&mut self, slot: crate::interface::Slot, bytes: &[u8]) -> Result<()> {
        self.deserialize_state(slot as u32, bytes)
    }
    fn reset(&mut self) -> Result<()> {
        RemoteInstance::reset(self)
    }
    fn terminate(&mut self) -> Result<()> {
        RemoteInstance::terminate(self)
    }
}

/// A count of values for a request.
fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}
