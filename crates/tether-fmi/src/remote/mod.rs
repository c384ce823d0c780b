//! Out-of-process instances: [`RemoteInstance`] runs an FMU instance in a host
//! process of its own (`tether-fmi-host`), so that a crash, `exit()`, `abort()`
//! or endless loop inside the FMU ends that process, not the caller's; the
//! FMI calls cross a pair of pipes ([`protocol`]), FMU states included:
//! they live in the host, named by slots, and cross as bytes only through
//! [`RemoteInstance::serialize_state`].
//!
//! Through [`FmuInstance`](crate::FmuInstance) the calls that answer nothing
//! (set values, step, save, restore, free) wait and travel with the next call
//! that answers, and a batch of runs ([`FmuInstance::run_batch`](crate::FmuInstance::run_batch))
//! is one request: one round trip. The host makes the calls in order and
//! names the one that failed; it enforces `call_timeout` on each call itself.
//! The inherent methods (`do_step`, `save_state`, …) make one round trip each.
//!
//! An instance made for model exchange ([`crate::Interface::ModelExchange`])
//! is a [`MeInstance`](crate::MeInstance) in the host, which integrates it
//! there: its step is one call, as a co-simulation step is.
//!
//! The host executable is found by [`host_command`] (docs/reliability.md).

pub mod protocol;
pub mod tcp;

use std::ffi::OsString;
use std::fs::File;
use std::io::{self, BufReader};
use std::net::{Shutdown, TcpStream};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::time::Duration;

use crate::error::{Error, Result};
use crate::fmu::{Fmu, InstanceOptions, Interface};
use crate::interface::Int;
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
    /// The host process, if this process started it (not on another machine).
    child: Option<Child>,
    /// The connection to a host on another machine (`tether host`), and
    /// its address.
    socket: Option<(TcpStream, String)>,
    reader: BufReader<File>,
    /// `None` once closed (the host then ends).
    writer: Option<File>,
    /// The calls waiting to be sent, as one request.
    out: Out,
    /// A request sent whose reply is not read yet: the call it is blamed
    /// on, and the error if it could not be written.
    in_flight: Option<(Call, Option<io::Error>)>,
    /// What each waiting call is, for errors (its FMI function and time).
    calls: Vec<Call>,
    reply: Vec<u8>,
    name: crate::current::Name,
    fmu: Fmu,
    /// Made for model exchange: the host integrates it.
    model_exchange: bool,
    time: f64,
    fatal: bool,
    /// How the host process ended, once it did.
    ended: Option<String>,
    timeout: Option<Duration>,
    /// Requests sent and answered (or not): [`FmuInstance::round_trips`](crate::FmuInstance::round_trips).
    round_trips: u64,
    /// Readable once the host process has ended ([`watch_exit`]), also while a
    /// process it started still holds the reply pipe.
    exit_watch: Option<OwnedFd>,
}

/// The way to a host: its process and pipes, or a connection to another
/// machine.
struct Connection {
    child: Option<Child>,
    socket: Option<(TcpStream, String)>,
    reader: File,
    writer: File,
    exit_watch: Option<OwnedFd>,
    /// What to call the host in errors.
    program: String,
}

/// A call of the request being built: its operation, its FMI function (of
/// the instance's FMI version) and the instance's time when it is made.
#[derive(Debug, Clone, Copy)]
struct Call {
    code: u8,
    function: &'static str,
    time: f64,
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
        let dir = fmu.directory().to_str().ok_or_else(|| {
            start_error(format!(
                "the FMU directory {} is not UTF-8",
                fmu.directory().display()
            ))
        })?;
        let connection = Connection {
            child: Some(child),
            socket: None,
            reader: File::from(OwnedFd::from(reader)),
            writer: File::from(OwnedFd::from(writer)),
            exit_watch,
            program: command.program.display().to_string(),
        };
        RemoteInstance::start(connection, fmu, name, options, timeout, dir)
    }

    /// Connects to the host `host` on another machine (`tether host`),
    /// hands it the FMU and instantiates it there as `name`.
    pub fn connect(
        fmu: &Fmu,
        name: &str,
        options: InstanceOptions,
        timeout: Option<Duration>,
        host: &tcp::RemoteHost,
    ) -> Result<RemoteInstance> {
        let start_error = |reason: String| Error::HostStart {
            instance: name.to_string(),
            reason,
        };
        let (socket, dir) = tcp::connect(host, fmu.path()).map_err(start_error)?;
        let clone = |s: &TcpStream| {
            s.try_clone()
                .map(|s| File::from(OwnedFd::from(s)))
                .map_err(|e| start_error(format!("host {}: {e}", host.address)))
        };
        let connection = Connection {
            child: None,
            reader: clone(&socket)?,
            writer: clone(&socket)?,
            socket: Some((socket, host.address.clone())),
            exit_watch: None,
            program: format!("host {}", host.address),
        };
        RemoteInstance::start(connection, fmu, name, options, timeout, &dir)
    }

    /// Says hello to the host on `connection` and instantiates the FMU
    /// unpacked in `dir` there.
    fn start(
        connection: Connection,
        fmu: &Fmu,
        name: &str,
        options: InstanceOptions,
        timeout: Option<Duration>,
        dir: &str,
    ) -> Result<RemoteInstance> {
        let start_error = |reason: String| Error::HostStart {
            instance: name.to_string(),
            reason,
        };
        let Connection {
            child,
            socket,
            reader,
            writer,
            exit_watch,
            program,
        } = connection;
        let mut remote = RemoteInstance {
            child,
            socket,
            reader: BufReader::with_capacity(1 << 16, reader),
            writer: Some(writer),
            out: Out::default(),
            calls: Vec::new(),
            in_flight: None,
            reply: Vec::new(),
            name: crate::current::Name::new(name),
            fmu: fmu.clone(),
            model_exchange: matches!(options.interface, Interface::ModelExchange(_)),
            time: 0.0,
            fatal: false,
            ended: None,
            timeout,
            round_trips: 0,
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
            .queue(op::HELLO)
            .u32(protocol::VERSION)
            .u8(log::max_level() as u8)
            .u8(fmu_level);
        remote.send()?;
        let version = In::new(&remote.reply[1..])
            .u32()
            .map_err(|e| remote.protocol_error(e))?;
        if version != protocol::VERSION {
            return Err(start_error(format!(
                "{program} speaks protocol version {version}, this library {}; use the host of the same Tether version",
                protocol::VERSION
            )));
        }
        // The process's FMU debug logging (`--fmu-log`) holds in the host too.
        let debug = crate::fmu::debug_logging();
        let categories = debug.clone().unwrap_or_default();
        let out = remote
            .queue(op::INSTANTIATE)
            .str(dir)
            .str(name)
            .bool(options.logging_on)
            .bool(options.visible)
            .bool(options.polynomial_inputs)
            .f64(timeout.map_or(0.0, |t| t.as_secs_f64()))
            .bool(debug.is_some())
            .u32(u32::try_from(categories.len()).unwrap_or(u32::MAX));
        for category in &categories {
            out.str(category);
        }
        out.interface(&options.interface);
        remote.send()?;
        Ok(remote)
    }

    /// One more call of the request: its operation `code`, whose arguments
    /// follow on the returned message.
    fn queue(&mut self, code: u8) -> &mut Out {
        let standard = self.fmu.model_description().standard;
        self.calls.push(Call {
            code,
            function: protocol::op_function_for(code, standard, self.model_exchange),
            time: self.time,
        });
        self.out.call(code)
    }

    /// The step from `t` over `h` (`fmi2DoStep`, `fmi3DoStep`), queued; the
    /// tracked time becomes `t + h`.
    fn queue_step(&mut self, t: f64, h: f64, no_set_fmu_state_prior: bool) {
        self.time = t;
        self.queue(op::DO_STEP)
            .f64(t)
            .f64(h)
            .bool(no_set_fmu_state_prior);
        self.time = t + h;
    }

    /// The coupled inputs, queued as one call: their values, then their
    /// derivatives ([`crate::interface::Inputs`]).
    fn queue_inputs(&mut self, inputs: &crate::interface::Inputs<'_>) {
        self.queue(op::SET_INPUTS)
            .u32s(inputs.vrs)
            .f64s(inputs.values)
            .u32s(inputs.derivative_vrs)
            .i32s(inputs.orders)
            .f64s(inputs.derivatives);
    }

    /// Sends the queued calls as one request and waits for the reply in
    /// `self.reply`. An error names the call that failed; a host that ended
    /// or timed out is blamed on the request's step if it has one (where an
    /// FMU spends its time), else on its last call.
    fn send(&mut self) -> Result<()> {
        self.transmit()?;
        self.await_reply()
    }

    /// Sends the queued calls as one request; [`await_reply`](Self::await_reply)
    /// waits for its reply.
    fn transmit(&mut self) -> Result<()> {
        let blamed = self
            .calls
            .iter()
            .find(|c| c.code == op::DO_STEP)
            .or(self.calls.last())
            .copied()
            .unwrap_or(Call {
                code: op::PING,
                function: "an FMI function",
                time: self.time,
            });
        if let Some(how) = &self.ended {
            let how = how.clone();
            self.out.clear();
            self.calls.clear();
            return Err(Error::HostEnded {
                instance: self.name.to_string(),
                function: blamed.function,
                time: blamed.time,
                how,
            });
        }
        let entered = crate::current::Entered::new(blamed.function, &self.name, blamed.time);
        self.round_trips += 1;
        let sent = match &mut self.writer {
            Some(writer) => self.out.send(writer),
            None => Err(io::ErrorKind::BrokenPipe.into()),
        };
        drop(entered);
        self.out.clear();
        self.in_flight = Some((blamed, sent.err()));
        Ok(())
    }

    /// Waits for the reply to the request [`transmit`](Self::transmit) sent,
    /// into `self.reply`.
    fn await_reply(&mut self) -> Result<()> {
        let (blamed, unsent) = self.in_flight.take().expect("await_reply follows transmit");
        let entered = crate::current::Entered::new(blamed.function, &self.name, blamed.time);
        // The host enforces the time-out on each call; this is the backstop
        // for a host that cannot (stopped, or its watch never scheduled).
        let calls = u32::try_from(self.calls.len()).unwrap_or(u32::MAX);
        let backstop = self.timeout.map(|t| {
            t.saturating_mul(calls)
                .saturating_add(Duration::from_secs(2))
        });
        let received = match unsent {
            Some(e) => Err(e),
            None => wait_readable(&self.reader, self.exit_watch.as_ref(), backstop)
                .and_then(|()| protocol::receive(&mut self.reader, &mut self.reply)),
        };
        drop(entered);
        let result = self.received(received, blamed);
        self.calls.clear();
        match result {
            Err((error, Some(call))) if call.code == op::DO_STEP => {
                // The step did not complete: the instance stays at its start.
                // (The host's `step` made a request to end the simulation
                // `Error::TerminationRequested` already.)
                self.time = call.time;
                Err(error)
            }
            Err((error, _)) => Err(error),
            Ok(()) => Ok(()),
        }
    }

    /// The outcome of a request: the error with the call it names, if one.
    fn received(
        &mut self,
        received: io::Result<bool>,
        blamed: Call,
    ) -> std::result::Result<(), (Error, Option<Call>)> {
        match received {
            Ok(true) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                return Err((self.timed_out(blamed.function, blamed.time), None))
            }
            Ok(false) | Err(_) => {
                return Err((self.host_ended(blamed.function, blamed.time), None))
            }
        }
        match self.reply.first() {
            Some(&protocol::OK) => Ok(()),
            Some(&protocol::ERR) => {
                let mut input = In::new(&self.reply[1..]);
                let read = input
                    .u32()
                    .and_then(|index| Ok((index, input.error(self.name.as_str())?)));
                let (index, error) = read.map_err(|e| (self.protocol_error(e), None))?;
                if let Error::CallTimeout { .. } = error {
                    // The host answered for the call past its time-out and ends.
                    self.kill_group();
                    let status = self.reap();
                    self.ended = Some(ended_after_timeout(status));
                    return Err((error, None));
                }
                if matches!(error, Error::Fatal { .. }) {
                    self.fatal = true;
                }
                let call = self.calls.get(index as usize).copied();
                Err((error, call))
            }
            Some(&protocol::ENDED) => {
                let how = In::new(&self.reply[1..]).str().map(str::to_string);
                match how {
                    Ok(how) => Err((self.host_ended_as(&how, blamed.function, blamed.time), None)),
                    Err(e) => Err((self.protocol_error(e), None)),
                }
            }
            _ => Err((self.protocol_error(io::ErrorKind::InvalidData.into()), None)),
        }
    }

    /// The listener of a remote host reported how its host process ended.
    #[cold]
    fn host_ended_as(&mut self, how: &str, function: &'static str, time: f64) -> Error {
        let how = match &self.socket {
            Some((_, address)) => format!("on {address} {how}"),
            None => how.to_string(),
        };
        self.ended = Some(how.clone());
        Error::HostEnded {
            instance: self.name.to_string(),
            function,
            time,
            how,
        }
    }

    /// The host did not answer in time: kill it.
    #[cold]
    fn timed_out(&mut self, function: &'static str, time: f64) -> Error {
        self.kill_group();
        let status = self.reap();
        self.ended = Some(ended_after_timeout(status));
        Error::CallTimeout {
            instance: self.name.to_string(),
            function,
            time,
            seconds: self.timeout.map_or(0.0, |t| t.as_secs_f64()),
        }
    }

    /// The connection broke: the host ended; say how.
    #[cold]
    fn host_ended(&mut self, function: &'static str, time: f64) -> Error {
        let reaped = self.reap();
        let how = match (&self.socket, reaped) {
            (Some((_, address)), _) => format!("lost the connection to {address}"),
            (None, Ok(status)) => describe_exit(status),
            (None, Err(e)) => format!("could not be waited for ({e})"),
        };
        self.ended = Some(how.clone());
        Error::HostEnded {
            instance: self.name.to_string(),
            function,
            time,
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

    /// Kills the host and every process of its group (those its FMU started);
    /// a host on another machine loses its connection, and ends with it.
    fn kill_group(&self) {
        if let Some((socket, _)) = &self.socket {
            let _ = socket.shutdown(Shutdown::Both);
        }
        let Some(child) = &self.child else { return };
        if let Ok(pid) = libc::pid_t::try_from(child.id()) {
            // SAFETY: a signal to the process group the host leads (started with
            // process_group(0)); the host is not reaped yet, so its id is not reused.
            unsafe { libc::killpg(pid, libc::SIGKILL) };
        }
    }

    /// Waits for the host to end, kills what is left of its process group (the
    /// processes its FMU started, which must not outlive it), then reaps it.
    fn reap(&mut self) -> io::Result<ExitStatus> {
        let Some(child) = &self.child else {
            return Err(io::Error::other("on another machine"));
        };
        let pid = child.id() as libc::id_t;
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
        match &mut self.child {
            Some(child) => child.wait(),
            None => Err(io::Error::other("on another machine")),
        }
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

    /// The host's process id (0 for a host on another machine).
    pub fn host_pid(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// A request without an FMI call and its reply: the transport's round trip.
    pub fn ping(&mut self) -> Result<()> {
        self.queue(op::PING);
        self.send()
    }

    /// `fmi2SetupExperiment`.
    pub fn setup_experiment(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<()> {
        self.queue(op::SETUP_EXPERIMENT)
            .bool(tolerance.is_some())
            .f64(tolerance.unwrap_or(0.0))
            .f64(start)
            .bool(stop.is_some())
            .f64(stop.unwrap_or(0.0));
        self.send()?;
        self.time = start;
        Ok(())
    }

    /// `fmi2EnterInitializationMode`.
    pub fn enter_initialization_mode(&mut self) -> Result<()> {
        self.queue(op::ENTER_INITIALIZATION_MODE);
        self.send()
    }

    /// `fmi2ExitInitializationMode`.
    pub fn exit_initialization_mode(&mut self) -> Result<()> {
        self.queue(op::EXIT_INITIALIZATION_MODE);
        self.send()
    }

    /// `fmi2Terminate`.
    pub fn terminate(&mut self) -> Result<()> {
        self.queue(op::TERMINATE);
        self.send()
    }

    /// `fmi2Reset`.
    pub fn reset(&mut self) -> Result<()> {
        self.queue(op::RESET);
        self.send()
    }

    /// `fmi2SetReal`.
    pub fn set_real(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        self.queue(op::SET_REAL).u32s(vrs).f64s(values);
        self.send()
    }

    /// `fmi2GetReal` into `out`.
    pub fn get_real(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        self.queue(op::GET_REAL).u32s(vrs).u32(count(out.len()));
        self.send()?;
        self.read_reals(out)
    }

    /// `fmi2GetInteger` into `out`.
    pub fn get_integer(&mut self, vrs: &[ValueReference], out: &mut [Int]) -> Result<()> {
        self.queue(op::GET_INTEGER).u32s(vrs).u32(count(out.len()));
        self.send()?;
        let mut values = Vec::with_capacity(out.len());
        let read = In::new(&self.reply[1..]).ints(&mut values);
        self.copy_reply(read, &values, out)
    }

    /// `fmi2GetBoolean` into `out`.
    pub fn get_boolean(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.queue(op::GET_BOOLEAN).u32s(vrs).u32(count(out.len()));
        self.send()?;
        let mut values = Vec::with_capacity(out.len());
        let read = In::new(&self.reply[1..]).bools(&mut values);
        self.copy_reply(read, &values, out)
    }

    /// `fmi2GetString` (FMI 3.0: `fmi3GetString`).
    pub fn get_string(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()> {
        self.queue(op::GET_STRING).u32s(vrs).u32(count(out.len()));
        self.send()?;
        let mut input = In::new(&self.reply[1..]);
        let read = (|| -> io::Result<()> {
            if input.u32()? as usize != out.len() {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    "wrong number of values",
                ));
            }
            for o in out.iter_mut() {
                let text = input.str()?;
                o.clear();
                o.push_str(text);
            }
            Ok(())
        })();
        read.map_err(|e| self.protocol_error(e))
    }

    /// `fmi2SetInteger`.
    pub fn set_integer(&mut self, vrs: &[ValueReference], values: &[Int]) -> Result<()> {
        self.queue(op::SET_INTEGER).u32s(vrs).ints(values);
        self.send()
    }

    /// `fmi2SetBoolean`.
    pub fn set_boolean(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.queue(op::SET_BOOLEAN).u32s(vrs).bools(values);
        self.send()
    }

    /// `fmi2SetString`.
    pub fn set_string(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        let out = self
            .queue(op::SET_STRING)
            .u32s(vrs)
            .u32(values.len() as u32);
        for v in values {
            out.str(v);
        }
        self.send()
    }

    /// `fmi2GetRealOutputDerivatives` into `out`.
    pub fn get_real_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        self.queue(op::GET_REAL_OUTPUT_DERIVATIVES)
            .u32s(vrs)
            .i32s(orders);
        self.send()?;
        self.read_reals(out)
    }

    /// `fmi2DoStep`; on success the tracked time becomes `t + h`.
    pub fn do_step(&mut self, t: f64, h: f64, no_set_fmu_state_prior: bool) -> Result<()> {
        self.queue_step(t, h, no_set_fmu_state_prior);
        self.send()
    }

    /// `fmi2GetFMUstate` into the host's state `slot` (reusing the state there).
    pub fn save_state(&mut self, slot: u32) -> Result<()> {
        self.queue(op::SAVE_STATE).u32(slot);
        self.send()
    }

    /// `fmi2SetFMUstate` from the host's state `slot`.
    pub fn restore_state(&mut self, slot: u32) -> Result<()> {
        self.queue(op::RESTORE_STATE).u32(slot);
        self.send()
    }

    /// `fmi2FreeFMUstate` of the host's state `slot`, if there is one.
    pub fn free_state(&mut self, slot: u32) -> Result<()> {
        self.queue(op::FREE_STATE).u32(slot);
        self.send()
    }

    /// `fmi2SerializeFMUstate` of the host's state `slot` into `out`.
    pub fn serialize_state(&mut self, slot: u32, out: &mut Vec<u8>) -> Result<()> {
        self.queue(op::SERIALIZE_STATE).u32(slot);
        self.send()?;
        let bytes = self.results().bytes().map(<[u8]>::to_vec);
        let bytes = bytes.map_err(|e| self.protocol_error(e))?;
        out.clear();
        out.extend_from_slice(&bytes);
        Ok(())
    }

    /// `fmi2DeSerializeFMUstate` of `bytes` into the host's state `slot`.
    pub fn deserialize_state(&mut self, slot: u32, bytes: &[u8]) -> Result<()> {
        self.queue(op::DESERIALIZE_STATE).u32(slot).bytes(bytes);
        self.send()
    }
}

/// How a host ended that was killed after the call time-out.
fn ended_after_timeout(status: io::Result<ExitStatus>) -> String {
    match status {
        Ok(status) => format!("{} after the call time-out", describe_exit(status)),
        Err(e) if e.kind() == io::ErrorKind::Other => "was stopped after the call time-out".into(),
        Err(e) => format!("could not be waited for ({e})"),
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
    reader: &BufReader<File>,
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
            self.queue(op::FREE_INSTANCE);
            let mut freed = self.send();
            if freed.is_err() && self.ended.is_none() {
                // A waiting call failed first: fmi2FreeInstance on its own.
                self.queue(op::FREE_INSTANCE);
                freed = self.send();
            }
            if freed.is_err() && self.ended.is_none() {
                self.kill_group();
            }
        }
        self.writer = None;
        if let Some((socket, _)) = &self.socket {
            let _ = socket.shutdown(Shutdown::Both);
        }
        if self.ended.is_none() && self.child.is_some() {
            let _ = self.reap();
        }
    }
}

impl crate::interface::FmuInstance for RemoteInstance {
    fn name(&self) -> &str {
        self.name.as_str()
    }
    /// What the instance in the host can do: it is made as in process.
    fn capabilities(&self) -> crate::interface::Capabilities {
        let md = self.model_description();
        if self.model_exchange {
            crate::interface::Capabilities::model_exchange(md)
        } else {
            crate::interface::Capabilities::co_simulation(md)
        }
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
        self.queue(op::SET_REAL).u32s(vrs).f64s(values);
        Ok(())
    }
    fn get_integers(&mut self, vrs: &[ValueReference], out: &mut [Int]) -> Result<()> {
        self.get_integer(vrs, out)
    }
    fn set_integers(&mut self, vrs: &[ValueReference], values: &[Int]) -> Result<()> {
        self.queue(op::SET_INTEGER).u32s(vrs).ints(values);
        Ok(())
    }
    fn get_booleans(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.get_boolean(vrs, out)
    }
    fn set_booleans(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.queue(op::SET_BOOLEAN).u32s(vrs).bools(values);
        Ok(())
    }
    fn get_strings(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()> {
        self.get_string(vrs, out)
    }
    fn set_strings(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        self.set_string(vrs, values)
    }
    fn set_inputs(&mut self, inputs: &crate::interface::Inputs<'_>) -> Result<()> {
        self.queue_inputs(inputs);
        Ok(())
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
        // The host's instance turns a request to end the simulation into
        // `Error::TerminationRequested` (the same `step` as in process),
        // which crosses as such.
        self.queue_step(t, h, true);
        Ok(())
    }
    fn save(&mut self, slot: crate::interface::Slot) -> Result<()> {
        self.queue(op::SAVE_STATE).u32(slot as u32);
        Ok(())
    }
    fn restore(&mut self, slot: crate::interface::Slot) -> Result<()> {
        self.queue(op::RESTORE_STATE).u32(slot as u32);
        Ok(())
    }
    fn free(&mut self, slot: crate::interface::Slot) -> Result<()> {
        self.queue(op::FREE_STATE).u32(slot as u32);
        Ok(())
    }
    fn serialize(&mut self, slot: crate::interface::Slot, out: &mut Vec<u8>) -> Result<()> {
        self.serialize_state(slot as u32, out)
    }
    fn deserialize(&mut self, slot: crate::interface::Slot, bytes: &[u8]) -> Result<()> {
        self.queue(op::DESERIALIZE_STATE)
            .u32(slot as u32)
            .bytes(bytes);
        Ok(())
    }
    fn reset(&mut self) -> Result<()> {
        RemoteInstance::reset(self)
    }
    fn is_remote(&self) -> bool {
        true
    }
    fn round_trips(&self) -> u64 {
        self.round_trips
    }
    fn run(&mut self, run: &crate::interface::RunRequest<'_>, out: &mut [f64]) -> Result<()> {
        self.run_batch(std::slice::from_ref(run), out)
    }
    fn run_batch(
        &mut self,
        runs: &[crate::interface::RunRequest<'_>],
        out: &mut [f64],
    ) -> Result<()> {
        match self.send_batch(runs)? {
            true => self.receive_batch(runs, out),
            false => Ok(()),
        }
    }
    fn send_batch(&mut self, runs: &[crate::interface::RunRequest<'_>]) -> Result<bool> {
        // Every call of every run, queued after those waiting; sent when
        // some run reads values.
        for run in runs {
            if let Some(slot) = run.restore {
                self.queue(op::RESTORE_STATE).u32(slot as u32);
            }
            if let Some(inputs) = &run.inputs {
                self.queue_inputs(inputs);
            }
            if let Some((t, h)) = run.step {
                self.queue_step(t, h, true);
            }
            if !run.outputs.is_empty() {
                self.queue(op::GET_REAL)
                    .u32s(run.outputs)
                    .u32(count(run.values_len()));
            }
            for &(vr, order) in run.output_derivatives {
                self.queue(op::GET_REAL_OUTPUT_DERIVATIVES)
                    .u32s(&[vr])
                    .i32s(&[order]);
            }
            if !run.recorded.is_empty() {
                self.queue(op::GET_REAL)
                    .u32s(run.recorded)
                    .u32(count(run.recorded_len()));
            }
            if let Some(slot) = run.save {
                self.queue(op::SAVE_STATE).u32(slot as u32);
            }
        }
        if runs.iter().all(|run| run.outputs_len() == 0) {
            return Ok(false);
        }
        self.transmit()?;
        Ok(true)
    }
    fn receive_batch(
        &mut self,
        runs: &[crate::interface::RunRequest<'_>],
        out: &mut [f64],
    ) -> Result<()> {
        self.await_reply()?;
        // The values, run after run, in the order they were asked for.
        let mut input = In::new(&self.reply[1..]);
        let mut rest = out;
        let mut read = || -> io::Result<()> {
            for run in runs {
                let parts = std::iter::once(run.values_len())
                    .chain(run.output_derivatives.iter().map(|_| 1))
                    .chain(std::iter::once(run.recorded_len()));
                for n in parts.filter(|&n| n > 0) {
                    if rest.len() < n {
                        return Err(io::ErrorKind::InvalidData.into());
                    }
                    let (part, tail) = std::mem::take(&mut rest).split_at_mut(n);
                    input.f64s_into(part)?;
                    rest = tail;
                }
            }
            Ok(())
        };
        let read = read();
        read.map_err(|e| self.protocol_error(e))
    }
    fn terminate(&mut self) -> Result<()> {
        RemoteInstance::terminate(self)
    }
}

/// A count of values for a request.
fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}
