//! The host process of an out-of-process FMU instance: reads requests of
//! [`tether_fmi::remote::protocol`] from its standard input, makes the FMI
//! calls on one instance and writes each reply to its standard output (both
//! pipes from the master; what the FMU itself prints to standard output goes
//! to standard error instead). The `tether-fmi-host` executable is this and
//! nothing else; the `tether` binary runs it too, as `tether __fmi-host`, so
//! the CLI needs no second file.
//!
//! The host ends when the master closes the request pipe, also while the FMU
//! is stuck inside a call (a thread watches for the hang-up), so a master that
//! dies leaves no host behind, nor any process the FMU started (the host kills
//! its process group). The pipes to the master are close-on-exec, and standard
//! input and output are /dev/null and standard error: the FMU's child processes
//! never hold them.

pub mod listen;

use std::fs::File;
use std::io::{BufReader, Write};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant};

use tether_fmi::remote::protocol::{self, op, In, Out};
use tether_fmi::{Error, Fmu, FmuInstance, Inputs, InstanceOptions, Interface, Placement};

/// The exit code of a host process that ended on an error of its own (a
/// request it refused, a broken connection), said on its standard error.
pub const GAVE_UP: u8 = 2;

/// Serves the master on standard input and output, then ends the process
/// ([`tether_fmi::exit_hook::leave`], after the instance is freed and its FMU
/// released): exit code 0 when the master closed the connection, 2 when
/// standard input and output are not pipes or a message could not be read.
pub fn serve_stdin() -> ! {
    let code = match serve_standard_streams() {
        Ok(()) => 0,
        Err(message) => {
            let _ = writeln!(std::io::stderr(), "error: tether-fmi-host: {message}");
            GAVE_UP
        }
    };
    tether_fmi::exit_hook::leave(code)
}

/// [`serve_stdin`] for hosts embedded in another program (the Python
/// package's `python -m tether._fmi_host`): `Ok` when the master closed the
/// connection, otherwise what went wrong.
pub fn serve_standard_streams() -> Result<(), String> {
    if !is_stream(0) || !is_stream(1) {
        return Err("it runs an FMU for Tether, which starts it with pipes as standard input and output; it is not meant to be started by hand".into());
    }
    tether_fmi::rate_limit_from_env();
    // SAFETY: fcntl, open and dup2 on the standard descriptors: the requests and
    // the replies keep the pipes to the master on descriptors of their own, both
    // close-on-exec; descriptor 0 then reads /dev/null and descriptor 1 refers to
    // standard error, so the FMU's printf cannot break a reply and the processes
    // an FMU starts (`system("helper &")`) hold neither pipe.
    let (requests, replies) = unsafe {
        let requests = libc::fcntl(0, libc::F_DUPFD_CLOEXEC, 3);
        if requests < 0 {
            return Err(std::io::Error::last_os_error().to_string());
        }
        let requests = File::from(OwnedFd::from_raw_fd(requests));
        let replies = libc::fcntl(1, libc::F_DUPFD_CLOEXEC, 3);
        if replies < 0 {
            return Err(std::io::Error::last_os_error().to_string());
        }
        let replies = File::from(OwnedFd::from_raw_fd(replies));
        let null = libc::open(c"/dev/null".as_ptr(), libc::O_RDONLY | libc::O_CLOEXEC);
        if null < 0 || libc::dup2(null, 0) < 0 || libc::dup2(2, 1) < 0 {
            return Err(std::io::Error::last_os_error().to_string());
        }
        libc::close(null);
        (requests, replies)
    };
    watch_hangup(&requests);
    serve(requests, replies).map_err(|e| e.to_string())
}

/// Whether descriptor `fd` is a pipe, or a socket (a connection that
/// `tether host` accepted).
fn is_stream(fd: i32) -> bool {
    // SAFETY: fstat writes into the zeroed stat value and reads nothing else.
    unsafe {
        let mut stat: libc::stat = std::mem::zeroed();
        libc::fstat(fd, &mut stat) == 0
            && matches!(stat.st_mode & libc::S_IFMT, libc::S_IFIFO | libc::S_IFSOCK)
    }
}

/// Ends the process when the master closes the request pipe, even while the
/// FMU is busy, with every process the FMU started: the host runs in a process
/// group of its own (the master starts it so), which it kills.
fn watch_hangup(requests: &File) {
    let fd = requests.as_raw_fd();
    std::thread::spawn(move || loop {
        let mut poll = libc::pollfd {
            fd,
            // A socket's peer may close its side only (POLLRDHUP).
            events: libc::POLLRDHUP,
            revents: 0,
        };
        // SAFETY: one valid pollfd; `fd` stays open for the life of the
        // process (the serving loop owns it and ends the process on return).
        let n = unsafe { libc::poll(&mut poll, 1, -1) };
        if n > 0 && poll.revents & (libc::POLLHUP | libc::POLLERR | libc::POLLRDHUP) != 0 {
            // SAFETY: getpgrp and getpid cannot fail; kill(0, SIGKILL) ends this
            // process group, which is the host's own only if it leads it (never
            // the group of whoever started a host by other means); _exit ends the
            // process at once otherwise: the master is gone and nothing of ours
            // needs flushing.
            unsafe {
                if libc::getpgrp() == libc::getpid() {
                    libc::kill(0, libc::SIGKILL);
                }
                libc::_exit(0);
            }
        }
    });
}

/// The instance being served and what its calls need: the instance is made by
/// [`tether_fmi::instantiate`] in this process, an FMI 2.0 or FMI 3.0 one, for
/// co-simulation or for model exchange (integrated here), and keeps its FMU
/// states in its own slots.
#[derive(Default)]
struct Host {
    instance: Option<Box<dyn FmuInstance>>,
    vrs: Vec<u32>,
    derivative_vrs: Vec<u32>,
    /// Derivative orders.
    ints: Vec<i32>,
    /// Integer values.
    integers: Vec<tether_fmi::Int>,
    reals: Vec<f64>,
    derivatives: Vec<f64>,
    bools: Vec<bool>,
    bytes: Vec<u8>,
    /// `call_timeout` of the instance, sent with `INSTANTIATE`.
    timeout: Option<Duration>,
    /// The instance is made for model exchange (the integrator runs here).
    model_exchange: bool,
}

/// The environment variable by which `tether host` bounds the requests of a
/// master (`--max-frame-mib`), in bytes.
pub const MAX_REQUEST_ENV: &str = "TETHER_HOST_MAX_FRAME";

/// The largest request this host reads: [`MAX_REQUEST_ENV`], else the
/// protocol's own bound (a master on pipes is this host's parent).
fn max_request() -> usize {
    std::env::var(MAX_REQUEST_ENV)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(usize::MAX)
}

/// Answers requests until the master closes the connection: the calls of a
/// request one after the other, until one fails.
fn serve(requests: File, writer: File) -> std::io::Result<()> {
    let mut reader = BufReader::with_capacity(1 << 16, requests);
    let writer = Arc::new(Mutex::new(writer));
    let clock = Arc::new(CallClock::default());
    let mut request = Vec::new();
    let mut out = Out::default();
    let mut host = Host::default();
    let mut watching = false;
    let max = max_request();
    while protocol::receive_bounded(&mut reader, &mut request, max)? {
        let mut input = In::new(&request);
        out.start(protocol::OK);
        let mut index = 0u32;
        let mut freed = false;
        while !input.is_empty() {
            let code = input.u8()?;
            clock.enter(code, host.call_time(code, input));
            let result = host.handle(code, &mut input, &mut out);
            clock.leave();
            if let Err(e) = result? {
                out.start(protocol::ERR).u32(index).error(&e);
                break;
            }
            freed |= code == op::FREE_INSTANCE;
            index += 1;
        }
        if let (Some(timeout), Some(instance), false) = (host.timeout, &host.instance, watching) {
            let standard = instance.model_description().standard;
            let model_exchange = host.model_exchange;
            let function = move |code| protocol::op_function_for(code, standard, model_exchange);
            watch_calls(&clock, &writer, timeout, instance.name(), function);
            watching = true;
        }
        out.send(&mut *lock(&writer))?;
        if freed {
            break;
        }
    }
    Ok(())
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The FMI call in progress, for the watch of `call_timeout`: a sequence
/// number that is odd during a call, and the call's start, function and time.
#[derive(Default)]
struct CallClock {
    sequence: AtomicU64,
    /// Nanoseconds since `epoch` when the call began.
    started: AtomicU64,
    code: AtomicU8,
    time: AtomicU64,
    epoch: OnceLock<Instant>,
}

impl CallClock {
    fn now(&self) -> u64 {
        let epoch = self.epoch.get_or_init(Instant::now);
        u64::try_from(epoch.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }
    fn enter(&self, code: u8, time: f64) {
        self.code.store(code, Ordering::Relaxed);
        self.time.store(time.to_bits(), Ordering::Relaxed);
        self.started.store(self.now(), Ordering::Relaxed);
        self.sequence.fetch_add(1, Ordering::Release);
    }
    fn leave(&self) {
        self.sequence.fetch_add(1, Ordering::Release);
    }
}

/// Enforces `call_timeout` on every FMI call: a call still running past it is
/// answered with [`Error::CallTimeout`] naming it (`function` of its
/// operation: the instance's FMI standard and interface say which), and the
/// host ends with its process group (the FMU cannot be stopped otherwise).
/// The watch wakes about once per time-out, not per call.
fn watch_calls(
    clock: &Arc<CallClock>,
    writer: &Arc<Mutex<File>>,
    timeout: Duration,
    instance: &str,
    function: impl Fn(u8) -> &'static str + Send + 'static,
) {
    let (clock, writer) = (Arc::clone(clock), Arc::clone(writer));
    let instance = instance.to_string();
    let limit = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
    std::thread::spawn(move || loop {
        let sequence = clock.sequence.load(Ordering::Acquire);
        if sequence % 2 == 0 {
            std::thread::sleep(timeout);
            continue;
        }
        let deadline = clock.started.load(Ordering::Relaxed).saturating_add(limit);
        let now = clock.now();
        if now < deadline {
            std::thread::sleep(Duration::from_nanos(deadline - now));
            continue;
        }
        // The reply lock: the serving thread is not answering meanwhile.
        let mut writer = lock(&writer);
        if clock.sequence.load(Ordering::Acquire) != sequence {
            continue;
        }
        let error = Error::CallTimeout {
            function: function(clock.code.load(Ordering::Relaxed)),
            instance: instance.clone(),
            time: f64::from_bits(clock.time.load(Ordering::Relaxed)),
            seconds: timeout.as_secs_f64(),
        };
        let mut out = Out::default();
        let _ = out
            .start(protocol::ERR)
            .u32(u32::MAX)
            .error(&error)
            .send(&mut *writer);
        // SAFETY: as in watch_hangup: the host's own process group, or this
        // process alone.
        unsafe {
            if libc::getpgrp() == libc::getpid() {
                libc::kill(0, libc::SIGKILL);
            }
            libc::_exit(1);
        }
    });
}

/// The instance, or the error for a call before `INSTANTIATE`.
fn live(
    instance: &mut Option<Box<dyn FmuInstance>>,
) -> Result<&mut (dyn FmuInstance + 'static), Error> {
    instance.as_deref_mut().ok_or_else(|| Error::Host {
        instance: String::new(),
        message: "the host has no instance yet".into(),
    })
}

impl Host {
    /// The instance's time when call `code` begins: a step's own start time.
    fn call_time(&self, code: u8, mut input: In<'_>) -> f64 {
        match code {
            op::DO_STEP => input.f64().unwrap_or(0.0),
            _ => self.instance.as_deref().map_or(0.0, |i| i.time()),
        }
    }

    /// One request: `Ok(Err(e))` is an FMI error for the master, `Err` a
    /// message that does not parse.
    fn handle(
        &mut self,
        code: u8,
        input: &mut In<'_>,
        out: &mut Out,
    ) -> std::io::Result<Result<(), Error>> {
        Ok(match code {
            op::PING => Ok(()),
            op::HELLO => {
                let _version = input.u32()?;
                let max = level(input.u8()?);
                let fmu = level(input.u8()?);
                init_logger(max, fmu);
                out.u32(protocol::VERSION);
                Ok(())
            }
            op::INSTANTIATE => {
                let dir = input.str()?;
                let name = input.str()?;
                let mut options = InstanceOptions {
                    logging_on: input.bool()?,
                    visible: input.bool()?,
                    polynomial_inputs: input.bool()?,
                    ..InstanceOptions::default()
                };
                let timeout = input.f64()?;
                self.timeout = (timeout > 0.0).then(|| Duration::from_secs_f64(timeout));
                // The master's FMU debug logging (`--fmu-log`), for this process.
                let debug = input.bool()?;
                let mut categories = Vec::new();
                for _ in 0..input.u32()? {
                    categories.push(input.str()?.to_string());
                }
                tether_fmi::set_debug_logging(debug.then_some(categories));
                // The interface: model exchange is integrated here.
                options.interface = match input.interface() {
                    Ok(interface) => interface,
                    Err(e) => {
                        return Ok(Err(Error::Host {
                            instance: name.to_string(),
                            message: format!(
                                "instance '{name}': its host refused the instantiate request: {e}"
                            ),
                        }))
                    }
                };
                self.model_exchange = matches!(options.interface, Interface::ModelExchange(_));
                Fmu::open(dir)
                    .and_then(|fmu| {
                        tether_fmi::instantiate(&fmu, name, options, Placement::InProcess)
                    })
                    .map(|instance| self.instance = Some(instance))
            }
            op::FREE_INSTANCE => {
                self.instance = None;
                Ok(())
            }
            _ => self.call(code, input, out)?,
        })
    }

    /// A call on the instance.
    fn call(
        &mut self,
        code: u8,
        input: &mut In<'_>,
        out: &mut Out,
    ) -> std::io::Result<Result<(), Error>> {
        let i = match live(&mut self.instance) {
            Ok(i) => i,
            Err(e) => return Ok(Err(e)),
        };
        Ok(match code {
            op::SETUP_EXPERIMENT => {
                let tolerance = input.bool()?.then_some(input.f64()?);
                let start = input.f64()?;
                let has_stop = input.bool()?;
                let stop = input.f64()?;
                i.setup(tolerance, start, has_stop.then_some(stop))
            }
            op::ENTER_INITIALIZATION_MODE => i.enter_initialization(),
            op::EXIT_INITIALIZATION_MODE => i.exit_initialization(),
            op::TERMINATE => i.terminate(),
            op::RESET => i.reset(),
            op::SET_REAL => {
                input.u32s(&mut self.vrs)?;
                input.f64s(&mut self.reals)?;
                i.set_reals(&self.vrs, &self.reals)
            }
            op::GET_REAL => {
                input.u32s(&mut self.vrs)?;
                self.reals.clear();
                self.reals.resize(input.u32()? as usize, 0.0);
                i.get_reals(&self.vrs, &mut self.reals).map(|()| {
                    out.f64s(&self.reals);
                })
            }
            op::GET_INTEGER => {
                input.u32s(&mut self.vrs)?;
                self.integers.clear();
                self.integers.resize(input.u32()? as usize, 0);
                i.get_integers(&self.vrs, &mut self.integers).map(|()| {
                    out.ints(&self.integers);
                })
            }
            op::GET_BOOLEAN => {
                input.u32s(&mut self.vrs)?;
                self.bools.clear();
                self.bools.resize(input.u32()? as usize, false);
                i.get_booleans(&self.vrs, &mut self.bools).map(|()| {
                    out.bools(&self.bools);
                })
            }
            op::GET_STRING => {
                input.u32s(&mut self.vrs)?;
                let mut strings = vec![String::new(); input.u32()? as usize];
                i.get_strings(&self.vrs, &mut strings).map(|()| {
                    out.u32(strings.len() as u32);
                    for s in &strings {
                        out.str(s);
                    }
                })
            }
            op::SET_INTEGER => {
                input.u32s(&mut self.vrs)?;
                input.ints(&mut self.integers)?;
                i.set_integers(&self.vrs, &self.integers)
            }
            op::SET_BOOLEAN => {
                input.u32s(&mut self.vrs)?;
                input.bools(&mut self.bools)?;
                i.set_booleans(&self.vrs, &self.bools)
            }
            op::SET_STRING => {
                input.u32s(&mut self.vrs)?;
                let n = input.u32()?;
                let mut strings = Vec::new();
                for _ in 0..n {
                    strings.push(input.str()?);
                }
                i.set_strings(&self.vrs, &strings)
            }
            op::SET_INPUTS => {
                input.u32s(&mut self.vrs)?;
                input.f64s(&mut self.reals)?;
                input.u32s(&mut self.derivative_vrs)?;
                input.i32s(&mut self.ints)?;
                input.f64s(&mut self.derivatives)?;
                i.set_inputs(&Inputs {
                    vrs: &self.vrs,
                    values: &self.reals,
                    derivative_vrs: &self.derivative_vrs,
                    orders: &self.ints,
                    derivatives: &self.derivatives,
                })
            }
            op::GET_REAL_OUTPUT_DERIVATIVES => {
                input.u32s(&mut self.vrs)?;
                input.i32s(&mut self.ints)?;
                self.reals.clear();
                self.reals.resize(self.vrs.len(), 0.0);
                i.get_output_derivatives(&self.vrs, &self.ints, &mut self.reals)
                    .map(|()| {
                        out.f64s(&self.reals);
                    })
            }
            op::DO_STEP => {
                let t = input.f64()?;
                let h = input.f64()?;
                let _no_prior = input.bool()?;
                // A request to end the simulation comes back as
                // Error::TerminationRequested, which crosses as such.
                i.step(t, h)
            }
            op::SAVE_STATE => slot(input.u32()?, code, i).and_then(|s| i.save(s)),
            op::RESTORE_STATE => slot(input.u32()?, code, i).and_then(|s| i.restore(s)),
            op::FREE_STATE => slot(input.u32()?, code, i).and_then(|s| i.free(s)),
            op::SERIALIZE_STATE => slot(input.u32()?, code, i).and_then(|s| {
                i.serialize(s, &mut self.bytes).map(|()| {
                    out.bytes(&self.bytes);
                })
            }),
            op::DESERIALIZE_STATE => {
                let index = input.u32()?;
                let bytes = input.bytes()?;
                slot(index, code, i).and_then(|s| i.deserialize(s, bytes))
            }
            _ => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("unknown request {code}"),
                ))
            }
        })
    }
}

/// State slot `index` of request `code`, or the error for a slot the
/// instance does not have.
fn slot(index: u32, code: u8, i: &dyn FmuInstance) -> Result<tether_fmi::Slot, Error> {
    let index = index as usize;
    if index < tether_fmi::SLOTS {
        Ok(index)
    } else {
        Err(Error::InvalidArgument {
            function: protocol::op_function(code, i.model_description().standard),
            instance: i.name().to_string(),
            message: format!(
                "no state slot {index} (an instance has {})",
                tether_fmi::SLOTS
            ),
        })
    }
}

/// A log level sent as `log::LevelFilter as u8`.
fn level(code: u8) -> log::LevelFilter {
    log::LevelFilter::iter()
        .find(|l| *l as u8 == code)
        .unwrap_or(log::LevelFilter::Warn)
}

/// One log record as a line for people, in `tether` and its host processes
/// alike: Tether's own as `warning: …` (`error:`, `info:`, `debug:`,
/// `trace:`), without a Rust module path; an FMU's messages (target
/// `fmu::<instance>`) as `[WARN  fmu::mass1] …`, naming the instance.
pub fn log_line(
    buf: &mut env_logger::fmt::Formatter,
    record: &log::Record<'_>,
) -> std::io::Result<()> {
    use std::io::Write as _;
    if record.target().starts_with("fmu::") {
        return writeln!(
            buf,
            "[{:<5} {}] {}",
            record.level(),
            record.target(),
            record.args()
        );
    }
    let word = match record.level() {
        log::Level::Error => "error",
        log::Level::Warn => "warning",
        log::Level::Info => "info",
        log::Level::Debug => "debug",
        log::Level::Trace => "trace",
    };
    writeln!(buf, "{word}: {}", record.args())
}

/// Logs like the `tether` binary: FMU messages at the master's level for
/// them, as `[WARN  fmu::<instance>] …`; its own as `warning: …`, without a
/// Rust module path. A model description's quirks are the master's to say
/// (it opened the FMU first), once.
fn init_logger(max: log::LevelFilter, fmu: log::LevelFilter) {
    let _ = env_logger::Builder::new()
        .filter_level(max)
        .filter_module("fmu", fmu)
        .filter_module(tether_fmi::QUIRKS_TARGET, log::LevelFilter::Off)
        .format(log_line)
        .try_init();
}
