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

use std::fs::File;
use std::io::{BufReader, Write};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::process::ExitCode;

use tether_fmi::remote::protocol::{self, op, In, Out};
use tether_fmi::{Error, Fmu, FmuInstance, Inputs, InstanceOptions, Placement};

/// Serves the master on standard input and output; the exit code is 0 when
/// the master closed the connection, 2 when standard input and output are not
/// pipes or a message could not be read.
pub fn serve_stdin() -> ExitCode {
    match serve_standard_streams() {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            let _ = writeln!(std::io::stderr(), "error: tether-fmi-host: {message}");
            ExitCode::from(2)
        }
    }
}

/// [`serve_stdin`] for hosts embedded in another program (the Python
/// package's `python -m tether._fmi_host`): `Ok` when the master closed the
/// connection, otherwise what went wrong.
pub fn serve_standard_streams() -> Result<(), String> {
    if !is_pipe(0) || !is_pipe(1) {
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

/// Whether descriptor `fd` is a pipe.
fn is_pipe(fd: i32) -> bool {
    // SAFETY: fstat writes into the zeroed stat value and reads nothing else.
    unsafe {
        let mut stat: libc::stat = std::mem::zeroed();
        libc::fstat(fd, &mut stat) == 0 && stat.st_mode & libc::S_IFMT == libc::S_IFIFO
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
            events: 0,
            revents: 0,
        };
        // SAFETY: one valid pollfd; `fd` stays open for the life of the
        // process (the serving loop owns it and ends the process on return).
        let n = unsafe { libc::poll(&mut poll, 1, -1) };
        if n > 0 && poll.revents & (libc::POLLHUP | libc::POLLERR) != 0 {
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
/// [`tether_fmi::instantiate`] in this process, an FMI 2.0 or FMI 3.0 one, and
/// keeps its FMU states in its own slots.
#[derive(Default)]
struct Host {
    instance: Option<Box<dyn FmuInstance>>,
    vrs: Vec<u32>,
    derivative_vrs: Vec<u32>,
    ints: Vec<i32>,
    reals: Vec<f64>,
    derivatives: Vec<f64>,
    bools: Vec<bool>,
    bytes: Vec<u8>,
}

/// Answers requests until the master closes the connection.
fn serve(requests: File, mut writer: File) -> std::io::Result<()> {
    let mut reader = BufReader::with_capacity(1 << 16, requests);
    let mut request = Vec::new();
    let mut out = Out::default();
    let mut host = Host::default();
    while protocol::receive(&mut reader, &mut request)? {
        let mut input = In::new(&request);
        let code = input.u8()?;
        out.start(protocol::OK);
        if let Err(e) = host.handle(code, &mut input, &mut out)? {
            out.start(protocol::ERR).error(&e);
        }
        out.send(&mut writer)?;
        if code == op::FREE_INSTANCE {
            break;
        }
    }
    Ok(())
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
                let options = InstanceOptions {
                    logging_on: input.bool()?,
                    visible: input.bool()?,
                };
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
                self.ints.clear();
                self.ints.resize(input.u32()? as usize, 0);
                i.get_integers(&self.vrs, &mut self.ints).map(|()| {
                    out.i32s(&self.ints);
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
            op::SET_INTEGER => {
                input.u32s(&mut self.vrs)?;
                input.i32s(&mut self.ints)?;
                i.set_integers(&self.vrs, &self.ints)
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
            op::SAVE_STATE => i.save(slot(input.u32()?, i)?),
            op::RESTORE_STATE => i.restore(slot(input.u32()?, i)?),
            op::FREE_STATE => i.free(slot(input.u32()?, i)?),
            op::SERIALIZE_STATE => {
                let s = slot(input.u32()?, i)?;
                i.serialize(s, &mut self.bytes).map(|()| {
                    out.bytes(&self.bytes);
                })
            }
            op::DESERIALIZE_STATE => {
                let s = slot(input.u32()?, i)?;
                let bytes = input.bytes()?;
                i.deserialize(s, bytes)
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

/// State slot `index` of a request, or an error for one the instance lacks.
fn slot(index: u32, i: &dyn FmuInstance) -> std::io::Result<tether_fmi::Slot> {
    let index = index as usize;
    if index < tether_fmi::SLOTS {
        Ok(index)
    } else {
        Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "instance '{}': state slot {index} (an instance has {})",
                i.name(),
                tether_fmi::SLOTS
            ),
        ))
    }
}

/// A log level sent as `log::LevelFilter as u8`.
fn level(code: u8) -> log::LevelFilter {
    log::LevelFilter::iter()
        .find(|l| *l as u8 == code)
        .unwrap_or(log::LevelFilter::Warn)
}

/// Logs like the `tether` binary: FMU messages at the master's level for them.
fn init_logger(max: log::LevelFilter, fmu: log::LevelFilter) {
    let _ = env_logger::Builder::new()
        .filter_level(max)
        .filter_module("fmu", fmu)
        .format_timestamp(None)
        .try_init();
}
