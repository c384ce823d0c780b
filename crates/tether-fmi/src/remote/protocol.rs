//! The messages between the master and an FMU host process
//! (`tether-fmi-host`): one request, one reply, each a frame of a 4-byte
//! little-endian length and the payload. A request is a sequence of calls,
//! each an operation code and its arguments, which the host makes in order
//! (a batch: the calls that answer nothing travel with the next that does);
//! a reply is `OK` and the results of every call in order, or `ERR`, the
//! index of the call that failed in the request, and the error (the calls
//! after it are not made). Numbers are little-endian, slices are a 4-byte
//! count and the elements, strings and byte strings a 4-byte length and the
//! bytes.

use std::io::{self, Read, Write};

use crate::error::{Error, FmuMessages};
use crate::fmu::Interface;
use crate::instance::{Integrator, Method};
use crate::interface::Int;
use crate::model_description::FmiStandard;

/// Changes whenever a message changes: master and host must agree (8: the
/// interface in `INSTANTIATE`, model-exchange errors and function names).
pub const VERSION: u32 = 8;

/// Operation codes of the requests.
#[allow(missing_docs)]
pub mod op {
    pub const HELLO: u8 = 1;
    pub const INSTANTIATE: u8 = 2;
    pub const SETUP_EXPERIMENT: u8 = 3;
    pub const ENTER_INITIALIZATION_MODE: u8 = 4;
    pub const EXIT_INITIALIZATION_MODE: u8 = 5;
    pub const TERMINATE: u8 = 6;
    pub const RESET: u8 = 7;
    pub const SET_REAL: u8 = 8;
    pub const GET_REAL: u8 = 9;
    pub const SET_INTEGER: u8 = 10;
    pub const SET_BOOLEAN: u8 = 11;
    pub const SET_STRING: u8 = 12;
    /// The coupled inputs of a run ([`crate::interface::Inputs`]).
    pub const SET_INPUTS: u8 = 13;
    pub const GET_REAL_OUTPUT_DERIVATIVES: u8 = 14;
    pub const DO_STEP: u8 = 15;
    pub const SAVE_STATE: u8 = 18;
    pub const RESTORE_STATE: u8 = 19;
    pub const FREE_STATE: u8 = 20;
    pub const SERIALIZE_STATE: u8 = 21;
    pub const DESERIALIZE_STATE: u8 = 22;
    pub const FREE_INSTANCE: u8 = 23;
    pub const GET_INTEGER: u8 = 25;
    pub const GET_BOOLEAN: u8 = 26;
    pub const GET_STRING: u8 = 27;
    /// Answered by `exit` without a reply (for tests of the transport's cost).
    pub const PING: u8 = 24;
}

/// First byte of a reply.
pub const OK: u8 = 0;
/// First byte of a failed reply; an encoded error follows.
pub const ERR: u8 = 1;
/// First byte of the last frame a listener (`tether host --listen`) sends on a
/// connection whose host process ended without finishing (an FMU that crashed
/// it): how it ended (`was killed by signal 11 (SIGSEGV)`) follows as a string.
pub const ENDED: u8 = 2;

/// The largest frame accepted (a serialised FMU state can be large).
const MAX_FRAME: usize = 1 << 30;

/// Every FMI function name the protocol may report, so that errors crossing
/// the process boundary keep their `&'static str`.
const FUNCTIONS: &[&str] = &[
    "fmi2Instantiate",
    "fmi2SetupExperiment",
    "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode",
    "fmi2Terminate",
    "fmi2Reset",
    "fmi2SetReal",
    "fmi2GetReal",
    "fmi2SetInteger",
    "fmi2GetInteger",
    "fmi2SetBoolean",
    "fmi2GetBoolean",
    "fmi2SetString",
    "fmi2GetString",
    "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives",
    "fmi2DoStep",
    "fmi2CancelStep",
    "fmi2GetStatus",
    "fmi2GetRealStatus",
    "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus",
    "fmi2GetStringStatus",
    "fmi2GetFMUstate",
    "fmi2SetFMUstate",
    "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize",
    "fmi2SerializeFMUstate",
    "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative",
    "fmi2SetDebugLogging",
    "fmi2FreeInstance",
    "fmi2SetTime",
    "fmi2SetContinuousStates",
    "fmi2GetDerivatives",
    "fmi2GetEventIndicators",
    "fmi2GetContinuousStates",
    "fmi2GetNominalsOfContinuousStates",
    "fmi2EnterEventMode",
    "fmi2NewDiscreteStates",
    "fmi2EnterContinuousTimeMode",
    "fmi2CompletedIntegratorStep",
    "fmi3InstantiateCoSimulation",
    "fmi3InstantiateModelExchange",
    "fmi3EnterConfigurationMode",
    "fmi3ExitConfigurationMode",
    "fmi3EnterInitializationMode",
    "fmi3ExitInitializationMode",
    "fmi3Terminate",
    "fmi3Reset",
    "fmi3GetFloat64",
    "fmi3SetFloat64",
    "fmi3GetFloat32",
    "fmi3SetFloat32",
    "fmi3GetInt8",
    "fmi3SetInt8",
    "fmi3GetUInt8",
    "fmi3SetUInt8",
    "fmi3GetInt16",
    "fmi3SetInt16",
    "fmi3GetUInt16",
    "fmi3SetUInt16",
    "fmi3GetInt32",
    "fmi3SetInt32",
    "fmi3GetUInt32",
    "fmi3SetUInt32",
    "fmi3GetInt64",
    "fmi3SetInt64",
    "fmi3GetUInt64",
    "fmi3SetUInt64",
    "fmi3GetBoolean",
    "fmi3SetBoolean",
    "fmi3GetString",
    "fmi3SetString",
    "fmi3GetBinary",
    "fmi3SetBinary",
    "fmi3GetOutputDerivatives",
    "fmi3DoStep",
    "fmi3GetFMUState",
    "fmi3SetFMUState",
    "fmi3FreeFMUState",
    "fmi3SerializedFMUStateSize",
    "fmi3SerializeFMUState",
    "fmi3DeserializeFMUState",
    "fmi3SetDebugLogging",
    "fmi3FreeInstance",
    "fmi3SetTime",
    "fmi3SetContinuousStates",
    "fmi3GetContinuousStateDerivatives",
    "fmi3GetEventIndicators",
    "fmi3GetContinuousStates",
    "fmi3GetNominalsOfContinuousStates",
    "fmi3GetNumberOfContinuousStates",
    "fmi3GetNumberOfEventIndicators",
    "fmi3EnterEventMode",
    "fmi3UpdateDiscreteStates",
    "fmi3EnterContinuousTimeMode",
    "fmi3CompletedIntegratorStep",
    "fmi3GetDirectionalDerivative",
];

/// The FMI function operation `code` calls on a co-simulation instance of
/// FMI `standard`, for errors and time-outs.
pub fn op_function(code: u8, standard: FmiStandard) -> &'static str {
    op_function_for(code, standard, false)
}

/// [`op_function`] for an instance made for model exchange if
/// `model_exchange`: its instantiation, and for a step the derivatives, the
/// function the integrator calls most.
pub fn op_function_for(code: u8, standard: FmiStandard, model_exchange: bool) -> &'static str {
    let (fmi2, fmi3) = match code {
        op::INSTANTIATE if model_exchange => ("fmi2Instantiate", "fmi3InstantiateModelExchange"),
        op::DO_STEP if model_exchange => {
            ("fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives")
        }
        op::INSTANTIATE => ("fmi2Instantiate", "fmi3InstantiateCoSimulation"),
        // FMI 3.0 passes the experiment to fmi3EnterInitializationMode.
        op::SETUP_EXPERIMENT => ("fmi2SetupExperiment", "fmi3EnterInitializationMode"),
        op::ENTER_INITIALIZATION_MODE => {
            ("fmi2EnterInitializationMode", "fmi3EnterInitializationMode")
        }
        op::EXIT_INITIALIZATION_MODE => {
            ("fmi2ExitInitializationMode", "fmi3ExitInitializationMode")
        }
        op::TERMINATE => ("fmi2Terminate", "fmi3Terminate"),
        op::RESET => ("fmi2Reset", "fmi3Reset"),
        op::SET_REAL | op::SET_INPUTS => ("fmi2SetReal", "fmi3SetFloat64"),
        op::GET_REAL => ("fmi2GetReal", "fmi3GetFloat64"),
        op::SET_INTEGER => ("fmi2SetInteger", "fmi3SetInt32"),
        op::GET_INTEGER => ("fmi2GetInteger", "fmi3GetInt32"),
        op::SET_BOOLEAN => ("fmi2SetBoolean", "fmi3SetBoolean"),
        op::GET_BOOLEAN => ("fmi2GetBoolean", "fmi3GetBoolean"),
        op::SET_STRING => ("fmi2SetString", "fmi3SetString"),
        op::GET_REAL_OUTPUT_DERIVATIVES => {
            ("fmi2GetRealOutputDerivatives", "fmi3GetOutputDerivatives")
        }
        op::DO_STEP => ("fmi2DoStep", "fmi3DoStep"),
        op::SAVE_STATE => ("fmi2GetFMUstate", "fmi3GetFMUState"),
        op::RESTORE_STATE => ("fmi2SetFMUstate", "fmi3SetFMUState"),
        op::FREE_STATE => ("fmi2FreeFMUstate", "fmi3FreeFMUState"),
        op::SERIALIZE_STATE => ("fmi2SerializeFMUstate", "fmi3SerializeFMUState"),
        op::DESERIALIZE_STATE => ("fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"),
        op::FREE_INSTANCE => ("fmi2FreeInstance", "fmi3FreeInstance"),
        _ => ("an FMI function", "an FMI function"),
    };
    match standard {
        FmiStandard::Fmi2 => fmi2,
        FmiStandard::Fmi3 => fmi3,
    }
}

/// The static name of FMI function `name` ("an FMI function" if unknown).
pub fn function_name(name: &str) -> &'static str {
    FUNCTIONS
        .iter()
        .find(|f| **f == name)
        .copied()
        .unwrap_or("an FMI function")
}

/// A message being built; `start` leaves room for the frame's length.
#[derive(Debug, Default)]
pub struct Out(pub Vec<u8>);

impl Out {
    /// Begin a new frame whose first byte is `tag` (an operation or OK/ERR).
    pub fn start(&mut self, tag: u8) -> &mut Out {
        self.0.clear();
        self.0.extend_from_slice(&[0; 4]);
        self.0.push(tag);
        self
    }
    /// One more call of a request: its operation `code` (the frame begins
    /// with the first).
    pub fn call(&mut self, code: u8) -> &mut Out {
        if self.0.is_empty() {
            self.0.extend_from_slice(&[0; 4]);
        }
        self.0.push(code);
        self
    }
    /// Whether no call is waiting to be sent.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// A byte.
    pub fn u8(&mut self, v: u8) -> &mut Out {
        self.0.push(v);
        self
    }
    /// A boolean (one byte).
    pub fn bool(&mut self, v: bool) -> &mut Out {
        self.u8(u8::from(v))
    }
    /// A 32-bit unsigned integer.
    pub fn u32(&mut self, v: u32) -> &mut Out {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A 64-bit unsigned integer.
    pub fn u64(&mut self, v: u64) -> &mut Out {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A 32-bit signed integer.
    pub fn i32(&mut self, v: i32) -> &mut Out {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A 64-bit float, bit for bit.
    pub fn f64(&mut self, v: f64) -> &mut Out {
        self.0.extend_from_slice(&v.to_bits().to_le_bytes());
        self
    }
    /// A length as 4 bytes.
    fn len(&mut self, n: usize) -> &mut Out {
        self.u32(u32::try_from(n).expect("a message part below 4 GiB"))
    }
    /// Bytes.
    pub fn bytes(&mut self, v: &[u8]) -> &mut Out {
        self.len(v.len());
        self.0.extend_from_slice(v);
        self
    }
    /// A string.
    pub fn str(&mut self, v: &str) -> &mut Out {
        self.bytes(v.as_bytes())
    }
    /// Value references.
    pub fn u32s(&mut self, v: &[u32]) -> &mut Out {
        self.len(v.len());
        v.iter().for_each(|x| {
            self.u32(*x);
        });
        self
    }
    /// Integers.
    pub fn i32s(&mut self, v: &[i32]) -> &mut Out {
        self.len(v.len());
        v.iter().for_each(|x| {
            self.i32(*x);
        });
        self
    }
    /// Integer values of any FMI type, 16 bytes each.
    pub fn ints(&mut self, v: &[Int]) -> &mut Out {
        self.len(v.len());
        v.iter().for_each(|x| {
            self.0.extend_from_slice(&x.to_le_bytes());
        });
        self
    }
    /// Reals.
    pub fn f64s(&mut self, v: &[f64]) -> &mut Out {
        self.len(v.len());
        v.iter().for_each(|x| {
            self.f64(*x);
        });
        self
    }
    /// Booleans.
    pub fn bools(&mut self, v: &[bool]) -> &mut Out {
        self.len(v.len());
        v.iter().for_each(|x| {
            self.bool(*x);
        });
        self
    }
    /// The interface of an `INSTANTIATE` request: 0 co-simulation; 1 model
    /// exchange, the integration method's name and rtol, atol, max_step,
    /// each a flag (given) and a real.
    pub fn interface(&mut self, interface: &Interface) -> &mut Out {
        match interface {
            Interface::CoSimulation => self.u8(0),
            Interface::ModelExchange(integrator) => {
                self.u8(1).str(integrator.method.name());
                for value in [integrator.rtol, integrator.atol, integrator.max_step] {
                    self.bool(value.is_some()).f64(value.unwrap_or(0.0));
                }
                self
            }
        }
    }
    /// An error of a call (status errors keep their kind, others their message).
    pub fn error(&mut self, e: &Error) -> &mut Out {
        let none = FmuMessages::default();
        let (kind, function, instance, time, code, messages) = match e {
            Error::Discard {
                function,
                instance,
                time,
                messages,
            } => (0, *function, instance.as_str(), *time, 0, messages),
            Error::Failed {
                function,
                instance,
                time,
                messages,
            } => (1, *function, instance.as_str(), *time, 0, messages),
            Error::Fatal {
                function,
                instance,
                time,
                messages,
            } => (2, *function, instance.as_str(), *time, 0, messages),
            Error::Pending {
                function,
                instance,
                time,
            } => (3, *function, instance.as_str(), *time, 0, &none),
            Error::FmuDead {
                function,
                instance,
                time,
                messages,
            } => (4, *function, instance.as_str(), *time, 0, messages),
            Error::UnknownStatus {
                function,
                instance,
                time,
                code,
            } => (5, *function, instance.as_str(), *time, *code, &none),
            Error::CallTimeout {
                function,
                instance,
                time,
                seconds,
            } => {
                return self
                    .u8(7)
                    .str(function)
                    .str(instance)
                    .f64(*time)
                    .f64(*seconds);
            }
            Error::TerminationRequested {
                instance,
                time,
                how,
            } => {
                return self
                    .u8(8)
                    .str(instance)
                    .f64(*time)
                    .bool(how.is_some())
                    .str(how.as_deref().unwrap_or(""));
            }
            Error::ModelExchange {
                instance,
                time,
                cause,
            } => {
                return self.u8(9).str(instance).f64(*time).str(cause);
            }
            other => {
                return self.u8(6).str(&crate::error::one_line(&other.to_string()));
            }
        };
        self.u8(kind)
            .str(function)
            .str(instance)
            .f64(time)
            .i32(code)
            .u32(u32::try_from(messages.0.len()).unwrap_or(u32::MAX));
        for m in &messages.0 {
            self.str(m);
        }
        self
    }
    /// Writes the frame (its length first) to `to`.
    pub fn send(&mut self, to: &mut impl Write) -> io::Result<()> {
        let n = u32::try_from(self.0.len() - 4).expect("a frame below 4 GiB");
        self.0[..4].copy_from_slice(&n.to_le_bytes());
        to.write_all(&self.0)
    }
    /// Forgets the frame (sent, or not to be sent).
    pub fn clear(&mut self) {
        self.0.clear();
    }
}

/// Reads one frame from `from` into `buf` (its capacity is reused); `Ok(false)`
/// at the end of the stream before a frame began.
pub fn receive(from: &mut impl Read, buf: &mut Vec<u8>) -> io::Result<bool> {
    receive_bounded(from, buf, MAX_FRAME)
}

/// A frame up to this size is read into a buffer of its announced length;
/// a larger one grows its buffer with the bytes that actually arrive, so
/// that announcing a length costs the peer as much as it costs the reader.
const EAGER_FRAME: usize = 1 << 16;

/// [`receive`] of a frame of at most `max` bytes (a host's
/// `--max-frame-mib`): a longer one is refused before anything is allocated.
pub fn receive_bounded(from: &mut impl Read, buf: &mut Vec<u8>, max: usize) -> io::Result<bool> {
    let mut len = [0u8; 4];
    let mut got = 0;
    while got < 4 {
        match from.read(&mut len[got..]) {
            Ok(0) if got == 0 => return Ok(false),
            Ok(0) => return Err(io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    let n = u32::from_le_bytes(len) as usize;
    if n == 0 || n > max.min(MAX_FRAME) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "a frame of {n} bytes where at most {} are expected",
                max.min(MAX_FRAME)
            ),
        ));
    }
    buf.clear();
    if n <= EAGER_FRAME {
        buf.resize(n, 0);
        from.read_exact(buf)?;
    } else if from.take(n as u64).read_to_end(buf)? < n {
        return Err(io::ErrorKind::UnexpectedEof.into());
    }
    Ok(true)
}

/// Reads the parts of a received frame in order.
#[derive(Debug, Clone, Copy)]
pub struct In<'a> {
    data: &'a [u8],
}

/// A message that does not parse.
fn malformed() -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, "a malformed message")
}

impl<'a> In<'a> {
    /// The parts of `data`.
    pub fn new(data: &'a [u8]) -> In<'a> {
        In { data }
    }
    fn take(&mut self, n: usize) -> io::Result<&'a [u8]> {
        if self.data.len() < n {
            return Err(malformed());
        }
        let (head, rest) = self.data.split_at(n);
        self.data = rest;
        Ok(head)
    }
    /// Whether every part was read.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }
    /// A byte.
    pub fn u8(&mut self) -> io::Result<u8> {
        Ok(self.take(1)?[0])
    }
    /// A boolean.
    pub fn bool(&mut self) -> io::Result<bool> {
        Ok(self.u8()? != 0)
    }
    /// A 32-bit unsigned integer.
    pub fn u32(&mut self) -> io::Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    /// A 64-bit unsigned integer.
    pub fn u64(&mut self) -> io::Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    /// A 32-bit signed integer.
    pub fn i32(&mut self) -> io::Result<i32> {
        Ok(i32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    /// A 64-bit float.
    pub fn f64(&mut self) -> io::Result<f64> {
        Ok(f64::from_bits(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        )))
    }
    fn len(&mut self, size: usize) -> io::Result<usize> {
        let n = self.u32()? as usize;
        if n.saturating_mul(size) > self.data.len() {
            return Err(malformed());
        }
        Ok(n)
    }
    /// Bytes.
    pub fn bytes(&mut self) -> io::Result<&'a [u8]> {
        let n = self.len(1)?;
        self.take(n)
    }
    /// A string.
    pub fn str(&mut self) -> io::Result<&'a str> {
        std::str::from_utf8(self.bytes()?).map_err(|_| malformed())
    }
    /// Value references.
    pub fn u32s(&mut self, out: &mut Vec<u32>) -> io::Result<()> {
        let n = self.len(4)?;
        out.clear();
        for _ in 0..n {
            out.push(self.u32()?);
        }
        Ok(())
    }
    /// Integers.
    pub fn i32s(&mut self, out: &mut Vec<i32>) -> io::Result<()> {
        let n = self.len(4)?;
        out.clear();
        for _ in 0..n {
            out.push(self.i32()?);
        }
        Ok(())
    }
    /// Integer values of any FMI type.
    pub fn ints(&mut self, out: &mut Vec<Int>) -> io::Result<()> {
        let n = self.len(16)?;
        out.clear();
        for _ in 0..n {
            out.push(Int::from_le_bytes(
                self.take(16)?.try_into().expect("16 bytes"),
            ));
        }
        Ok(())
    }
    /// Reals into `out`, which must have the sent length.
    pub fn f64s_into(&mut self, out: &mut [f64]) -> io::Result<()> {
        if self.len(8)? != out.len() {
            return Err(malformed());
        }
        for x in out {
            *x = self.f64()?;
        }
        Ok(())
    }
    /// Reals.
    pub fn f64s(&mut self, out: &mut Vec<f64>) -> io::Result<()> {
        let n = self.len(8)?;
        out.clear();
        for _ in 0..n {
            out.push(self.f64()?);
        }
        Ok(())
    }
    /// Booleans.
    pub fn bools(&mut self, out: &mut Vec<bool>) -> io::Result<()> {
        let n = self.len(1)?;
        out.clear();
        for _ in 0..n {
            out.push(self.bool()?);
        }
        Ok(())
    }
    /// The interface written by [`Out::interface`]; an unknown kind or
    /// method is an error that names it.
    pub fn interface(&mut self) -> io::Result<Interface> {
        match self.u8()? {
            0 => Ok(Interface::CoSimulation),
            1 => {
                let name = self.str()?;
                let method = Method::parse(name).ok_or_else(|| {
                    io::Error::new(
                        io::ErrorKind::InvalidData,
                        format!("an unknown integration method '{}'", name.escape_debug()),
                    )
                })?;
                let mut value = || -> io::Result<Option<f64>> {
                    let given = self.bool()?;
                    let value = self.f64()?;
                    Ok(given.then_some(value))
                };
                Ok(Interface::ModelExchange(Integrator {
                    method,
                    rtol: value()?,
                    atol: value()?,
                    max_step: value()?,
                }))
            }
            kind => Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("an unknown interface {kind}"),
            )),
        }
    }
    /// An error written by [`Out::error`]; `instance` names the instance for
    /// errors that crossed as messages.
    pub fn error(&mut self, instance: &str) -> io::Result<Error> {
        let kind = self.u8()?;
        if kind == 6 {
            return Ok(Error::Host {
                instance: instance.to_string(),
                message: self.str()?.to_string(),
            });
        }
        if kind == 7 {
            return Ok(Error::CallTimeout {
                function: function_name(self.str()?),
                instance: self.str()?.to_string(),
                time: self.f64()?,
                seconds: self.f64()?,
            });
        }
        if kind == 9 {
            return Ok(Error::ModelExchange {
                instance: self.str()?.to_string(),
                time: self.f64()?,
                cause: self.str()?.to_string(),
            });
        }
        if kind == 8 {
            let instance = self.str()?.to_string();
            let time = self.f64()?;
            let has_how = self.bool()?;
            let how = self.str()?;
            return Ok(Error::TerminationRequested {
                instance,
                time,
                how: has_how.then(|| how.to_string()),
            });
        }
        let function = function_name(self.str()?);
        let instance = self.str()?.to_string();
        let time = self.f64()?;
        let code = self.i32()?;
        let count = self.u32()?;
        let mut messages = FmuMessages::default();
        for _ in 0..count {
            messages.0.push(self.str()?.to_string());
        }
        Ok(match kind {
            0 => Error::Discard {
                function,
                instance,
                time,
                messages,
            },
            1 => Error::Failed {
                function,
                instance,
                time,
                messages,
            },
            2 => Error::Fatal {
                function,
                instance,
                time,
                messages,
            },
            3 => Error::Pending {
                function,
                instance,
                time,
            },
            4 => Error::FmuDead {
                function,
                instance,
                time,
                messages,
            },
            _ => Error::UnknownStatus {
                function,
                instance,
                time,
                code,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_and_errors_cross_unchanged() {
        let mut out = Out::default();
        out.start(op::SET_REAL)
            .u32s(&[1, 2])
            .f64s(&[0.1, f64::NAN])
            .str("mass2")
            .error(&Error::Discard {
                function: "fmi2DoStep",
                instance: "mass2".into(),
                time: 0.5,
                messages: FmuMessages(vec!["[logStatusError] step too large".into()]),
            });
        let mut wire = Vec::new();
        out.send(&mut wire).unwrap();
        let mut buf = Vec::new();
        assert!(receive(&mut wire.as_slice(), &mut buf).unwrap());
        let mut input = In::new(&buf);
        assert_eq!(input.u8().unwrap(), op::SET_REAL);
        let (mut vrs, mut values) = (Vec::new(), Vec::new());
        input.u32s(&mut vrs).unwrap();
        input.f64s(&mut values).unwrap();
        assert_eq!(vrs, [1, 2]);
        assert_eq!(values[0].to_bits(), 0.1f64.to_bits());
        assert!(values[1].is_nan());
        assert_eq!(input.str().unwrap(), "mass2");
        let e = input.error("mass2").unwrap();
        assert_eq!(
            e.to_string(),
            "fmi2DoStep returned fmi2Discard on instance 'mass2' at t=0.5; \
             the FMU's last messages: [logStatusError] step too large"
        );
        assert!(input.u8().is_err(), "nothing left");
        // A truncated frame is an error, not a panic.
        assert!(receive(&mut &wire[..wire.len() - 1], &mut buf).is_err());
        assert!(!receive(&mut &wire[..0], &mut buf).unwrap());
    }

    /// A frame longer than the bound is refused before its body is read;
    /// one within it but longer than 64 KiB grows its buffer with the bytes
    /// that arrive, not with the length announced.
    #[test]
    fn announced_lengths_allocate_only_what_arrives() {
        let mut buf = Vec::new();
        let mut wire = (512u32 << 20).to_le_bytes().to_vec();
        wire.extend_from_slice(&[1; 100]);
        let e = receive_bounded(&mut wire.as_slice(), &mut buf, 1 << 20).unwrap_err();
        assert_eq!(
            e.to_string(),
            "a frame of 536870912 bytes where at most 1048576 are expected"
        );
        assert_eq!(buf.capacity(), 0);
        // 1 GiB − 1 announced, 100 bytes sent, the stream ends.
        let mut wire = ((1u32 << 30) - 1).to_le_bytes().to_vec();
        wire.extend_from_slice(&[1; 100]);
        let e = receive(&mut wire.as_slice(), &mut buf).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof);
        assert!(buf.capacity() < 1 << 16, "{}", buf.capacity());
        // A long frame that arrives whole is read whole.
        let mut out = Out::default();
        out.start(OK).bytes(&vec![3; 200_000]);
        let mut wire = Vec::new();
        out.send(&mut wire).unwrap();
        assert!(receive_bounded(&mut wire.as_slice(), &mut buf, 1 << 20).unwrap());
        assert_eq!(&buf[..], &wire[4..]);
    }

    /// A time-out and a request to end the simulation cross as themselves,
    /// with an FMI 3.0 function name kept as the static name.
    #[test]
    fn time_outs_and_termination_requests_cross_as_such() {
        let sent = [
            Error::CallTimeout {
                function: op_function(op::DO_STEP, FmiStandard::Fmi3),
                instance: "mass2".into(),
                time: 0.25,
                seconds: 0.5,
            },
            Error::TerminationRequested {
                instance: "stair".into(),
                time: 9.0,
                how: Some("fmi3DoStep returned terminateSimulation = true".into()),
            },
            Error::TerminationRequested {
                instance: "osc".into(),
                time: 1.5,
                how: None,
            },
        ];
        let mut out = Out::default();
        out.start(ERR);
        for e in &sent {
            out.error(e);
        }
        let mut wire = Vec::new();
        out.send(&mut wire).unwrap();
        let mut buf = Vec::new();
        assert!(receive(&mut wire.as_slice(), &mut buf).unwrap());
        let mut input = In::new(&buf[1..]);
        for e in &sent {
            let received = input.error("other").unwrap();
            assert_eq!(format!("{received:?}"), format!("{e:?}"));
        }
        assert!(input.is_empty());
    }

    /// Every operation's FMI function, of either standard, is one the
    /// protocol can report (an error keeps its name when it crosses).
    #[test]
    fn every_operation_names_a_function_the_protocol_knows() {
        let codes = [
            op::INSTANTIATE,
            op::SETUP_EXPERIMENT,
            op::ENTER_INITIALIZATION_MODE,
            op::EXIT_INITIALIZATION_MODE,
            op::TERMINATE,
            op::RESET,
            op::SET_REAL,
            op::GET_REAL,
            op::SET_INTEGER,
            op::SET_BOOLEAN,
            op::SET_STRING,
            op::SET_INPUTS,
            op::GET_REAL_OUTPUT_DERIVATIVES,
            op::DO_STEP,
            op::SAVE_STATE,
            op::RESTORE_STATE,
            op::FREE_STATE,
            op::SERIALIZE_STATE,
            op::DESERIALIZE_STATE,
            op::FREE_INSTANCE,
            op::GET_INTEGER,
            op::GET_BOOLEAN,
        ];
        for standard in [FmiStandard::Fmi2, FmiStandard::Fmi3] {
            let prefix = match standard {
                FmiStandard::Fmi2 => "fmi2",
                FmiStandard::Fmi3 => "fmi3",
            };
            for code in codes {
                let name = op_function(code, standard);
                assert!(name.starts_with(prefix), "{code}: {name}");
                assert_eq!(function_name(name), name, "{code}");
            }
        }
        assert_eq!(op_function(op::DO_STEP, FmiStandard::Fmi3), "fmi3DoStep");
        for standard in [FmiStandard::Fmi2, FmiStandard::Fmi3] {
            for code in [op::INSTANTIATE, op::DO_STEP] {
                let name = op_function_for(code, standard, true);
                assert_eq!(function_name(name), name, "{code}");
            }
        }
        assert_eq!(
            op_function_for(op::DO_STEP, FmiStandard::Fmi2, true),
            "fmi2GetDerivatives"
        );
    }

    /// Every function a model-exchange instance calls keeps its name when
    /// its error crosses, and a model-exchange error crosses as itself.
    #[test]
    fn model_exchange_errors_cross_as_such() {
        for name in [
            "fmi2SetTime",
            "fmi2SetContinuousStates",
            "fmi2GetDerivatives",
            "fmi2GetEventIndicators",
            "fmi2GetContinuousStates",
            "fmi2GetNominalsOfContinuousStates",
            "fmi2EnterEventMode",
            "fmi2NewDiscreteStates",
            "fmi2EnterContinuousTimeMode",
            "fmi2CompletedIntegratorStep",
            "fmi3InstantiateModelExchange",
            "fmi3SetTime",
            "fmi3SetContinuousStates",
            "fmi3GetContinuousStateDerivatives",
            "fmi3GetEventIndicators",
            "fmi3GetContinuousStates",
            "fmi3GetNominalsOfContinuousStates",
            "fmi3GetNumberOfContinuousStates",
            "fmi3GetNumberOfEventIndicators",
            "fmi3EnterEventMode",
            "fmi3UpdateDiscreteStates",
            "fmi3EnterContinuousTimeMode",
            "fmi3CompletedIntegratorStep",
            // The implicit methods' Jacobian.
            "fmi2GetDirectionalDerivative",
            "fmi3GetDirectionalDerivative",
        ] {
            assert_eq!(function_name(name), name);
        }
        let sent = Error::ModelExchange {
            instance: "saw".into(),
            time: 0.625,
            cause: "fmi2GetDerivatives returned NaN".into(),
        };
        let mut out = Out::default();
        out.start(ERR).error(&sent);
        let mut wire = Vec::new();
        out.send(&mut wire).unwrap();
        let mut buf = Vec::new();
        assert!(receive(&mut wire.as_slice(), &mut buf).unwrap());
        let mut input = In::new(&buf[1..]);
        let received = input.error("other").unwrap();
        assert_eq!(format!("{received:?}"), format!("{sent:?}"));
        assert!(input.is_empty());
    }

    /// The interface of an instantiate request crosses bit for bit; an
    /// unknown interface or method is an error naming it, not a panic.
    #[test]
    fn interfaces_cross_and_unknown_ones_are_named() {
        let sent = [
            Interface::CoSimulation,
            Interface::ModelExchange(Integrator::default()),
            Interface::ModelExchange(Integrator {
                method: Method::Dop853,
                rtol: Some(1e-10),
                atol: None,
                max_step: Some(0.05),
            }),
        ];
        let mut out = Out::default();
        out.start(op::INSTANTIATE);
        for interface in &sent {
            out.interface(interface);
        }
        let mut input = In::new(&out.0[5..]);
        for interface in &sent {
            assert_eq!(input.interface().unwrap(), *interface);
        }
        assert!(input.is_empty());
        let e = In::new(&[7]).interface().unwrap_err();
        assert_eq!(e.to_string(), "an unknown interface 7");
        let mut out = Out::default();
        out.start(op::INSTANTIATE).u8(1).str("euler\n");
        let e = In::new(&out.0[5..]).interface().unwrap_err();
        assert_eq!(e.to_string(), "an unknown integration method 'euler\\n'");
        // Truncated after the method: malformed, not a panic.
        out.bool(true);
        assert!(In::new(&out.0[5..]).interface().is_err());
    }
}
