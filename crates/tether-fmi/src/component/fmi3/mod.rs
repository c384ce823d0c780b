//! [`RawInstance3`]: owns one `fmi3Instance` and exposes the C functions one-to-one
//! (same names), with the fatal-state guard and the status check of every call.
//!
//! The value functions pass `nValues` as the length of the caller's slice; the safe
//! layer ([`Fmi3Instance`](crate::Fmi3Instance)) makes that the number of values of
//! the variables asked for (their array sizes summed) before calling.

use std::ffi::{c_char, CStr, CString};
use std::sync::Arc;

mod intermediate;
mod me;

use crate::archive::FmuDir;
use crate::error::{Error, Result};
use crate::library::Library;
use crate::logger::fmi3_log_message;
use crate::raw::fmi3::*;
use crate::raw::{check, CallSite};
use intermediate::{intermediate_update, Env3};

/// An FMU state pointer of an FMI 3.0 instance, freed by its owner
/// ([`RawInstance3::fmi3FreeFMUState`]) before the instance.
#[derive(Debug)]
pub(crate) struct RawState3 {
    ptr: fmi3FMUState,
}

// SAFETY: an fmi3FMUState is an opaque handle only ever passed back to the instance
// that made it, whose calls the safe layer serialises (`&mut Fmi3Instance`).
unsafe impl Send for RawState3 {}

/// The answers of `fmi3DoStep` besides its status.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StepAnswers {
    pub event_handling_needed: bool,
    pub terminate_simulation: bool,
    pub early_return: bool,
    pub last_successful_time: f64,
}

impl StepAnswers {
    /// The step ended at its end with nothing to report: no event, no
    /// request to terminate, no early return.
    #[inline]
    pub(crate) fn plain(&self) -> bool {
        !(self.event_handling_needed || self.terminate_simulation || self.early_return)
    }
}

/// One live `fmi3Instance`, freed with `fmi3FreeInstance` on drop.
pub(crate) struct RawInstance3 {
    instance: fmi3Instance,
    name: crate::current::Name,
    /// The communication time reported in errors; maintained by the safe layer.
    pub(crate) time: f64,
    /// Must outlive the instance: the FMU keeps the pointer.
    pub(crate) env: Box<Env3>,
    /// The intermediate update callback was given: the environment's
    /// polynomials are used (else they stay empty and are not touched).
    pub(crate) intermediate_update: bool,
    library: Arc<Library<Fmi3Functions>>,
    _dir: Arc<FmuDir>,
    /// Held while the instance lives when the model declares
    /// `canBeInstantiatedOnlyOncePerProcess` (released after `fmi3FreeInstance`).
    pub(crate) once: Option<crate::shared::OnceGuard>,
}

// SAFETY: FMI 3.0 lets an instance be used from any thread as long as calls are not
// concurrent; the safe layer calls it through `&mut Fmi3Instance`.
unsafe impl Send for RawInstance3 {}

impl std::fmt::Debug for RawInstance3 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawInstance3")
            .field("name", &self.name)
            .field("time", &self.time)
            .finish_non_exhaustive()
    }
}

/// Arguments of `fmi3InstantiateCoSimulation` besides the callbacks.
pub(crate) struct InstantiateArgs3<'a> {
    pub model: &'a str,
    pub instance_name: &'a str,
    pub instantiation_token: &'a str,
    /// The FMU's `resources/` directory as a native path ending in '/'.
    pub resource_path: &'a str,
    pub visible: bool,
    pub logging_on: bool,
    pub event_mode_used: bool,
    pub early_return_allowed: bool,
    pub required_intermediate_variables: &'a [fmi3ValueReference],
    /// Pass the intermediate update callback (the FMU provides intermediate update
    /// and its inputs take polynomials).
    pub intermediate_update: bool,
    /// `fmi3InstantiateModelExchange` instead (which takes no event mode, early
    /// return, intermediate variables or intermediate update callback).
    pub model_exchange: bool,
}

fn boolean(b: bool) -> fmi3Boolean {
    if b {
        fmi3True
    } else {
        fmi3False
    }
}

macro_rules! numeric {
    ($($get:ident, $set:ident: $t:ty;)*) => {
        $(
            #[doc = concat!("`", stringify!($get), "` into `out` (`nValues` = its length).")]
            pub(crate) fn $get(&mut self, vrs: &[fmi3ValueReference], out: &mut [$t]) -> Result<()> {
                // SAFETY: `vrs` holds `vrs.len()` references and `out` is writable for
                // `out.len()` values, passed as nValues.
                self.call(stringify!($get), |f, c| unsafe {
                    (f.$get)(c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len())
                })
            }

            #[doc = concat!("`", stringify!($set), "` (`nValues` = the length of `values`).")]
            pub(crate) fn $set(&mut self, vrs: &[fmi3ValueReference], values: &[$t]) -> Result<()> {
                // SAFETY: `vrs` holds `vrs.len()` references and `values` holds
                // `values.len()` values, passed as nValues.
                self.call(stringify!($set), |f, c| unsafe {
                    (f.$set)(c, vrs.as_ptr(), vrs.len(), values.as_ptr(), values.len())
                })
            }
        )*
    };
}

impl RawInstance3 {
    /// `fmi3InstantiateCoSimulation`, or `fmi3InstantiateModelExchange` when
    /// `args.model_exchange`.
    pub(crate) fn fmi3InstantiateCoSimulation(
        library: Arc<Library<Fmi3Functions>>,
        dir: Arc<FmuDir>,
        args: &InstantiateArgs3<'_>,
    ) -> Result<RawInstance3> {
        let function: &'static str = if args.model_exchange {
            "fmi3InstantiateModelExchange"
        } else {
            "fmi3InstantiateCoSimulation"
        };
        let me_instantiate = if args.model_exchange {
            Some(library.me()?.fmi3InstantiateModelExchange)
        } else {
            None
        };
        let invalid = |what: &str| Error::InvalidArgument {
            function,
            instance: args.instance_name.to_owned(),
            message: format!("{what} contains a NUL byte"),
        };
        let name_c = CString::new(args.instance_name).map_err(|_| invalid("the instance name"))?;
        let token_c = CString::new(args.instantiation_token)
            .map_err(|_| invalid("the instantiation token"))?;
        let path_c = CString::new(args.resource_path).map_err(|_| invalid("the resource path"))?;
        let mut env = Env3::new(args.instance_name);
        let environment = env.pointer();
        if library.is_fatal() {
            return Err(Error::FmuDead {
                function,
                instance: args.instance_name.to_owned(),
                time: 0.0,
                messages: Default::default(),
            });
        }
        log::trace!(target: "tether_fmi::call", "{function}({})", args.instance_name);
        let name = crate::current::Name::new(args.instance_name);
        let entered = crate::current::Entered::new(function, &name, 0.0);
        let required = args.required_intermediate_variables;
        let instance = match me_instantiate {
            // SAFETY: as for co-simulation below, without the intermediate variables
            // and the intermediate update callback, which model exchange has not.
            Some(instantiate) => unsafe {
                instantiate(
                    name_c.as_ptr(),
                    token_c.as_ptr(),
                    path_c.as_ptr(),
                    boolean(args.visible),
                    boolean(args.logging_on),
                    environment,
                    Some(fmi3_log_message),
                )
            },
            // SAFETY: all strings are NUL-terminated and live across the call; `required`
            // holds `required.len()` references; the environment is boxed and kept in the
            // returned instance until after fmi3FreeInstance; the callbacks match
            // fmi3LogMessageCallback and fmi3IntermediateUpdateCallback.
            None => unsafe {
                (library.functions().fmi3InstantiateCoSimulation)(
                    name_c.as_ptr(),
                    token_c.as_ptr(),
                    path_c.as_ptr(),
                    boolean(args.visible),
                    boolean(args.logging_on),
                    boolean(args.event_mode_used),
                    boolean(args.early_return_allowed),
                    if required.is_empty() {
                        std::ptr::null()
                    } else {
                        required.as_ptr()
                    },
                    required.len(),
                    environment,
                    Some(fmi3_log_message),
                    if args.intermediate_update {
                        Some(intermediate_update)
                    } else {
                        None
                    },
                )
            },
        };
        drop(entered);
        if instance.is_null() {
            return Err(Error::InstantiationFailed {
                model: args.model.to_owned(),
                instance: args.instance_name.to_owned(),
                messages: crate::error::FmuMessages(env.log.recent()),
            });
        }
        env.set_target(instance, library.functions().fmi3SetFloat64);
        Ok(RawInstance3 {
            instance,
            name,
            time: 0.0,
            env,
            intermediate_update: args.intermediate_update,
            library,
            _dir: dir,
            once: None,
        })
    }

    /// The instance name.
    pub(crate) fn name(&self) -> &str {
        self.name.as_str()
    }

    /// Whether this FMU has returned fmi3Fatal.
    pub(crate) fn is_fatal(&self) -> bool {
        self.library.is_fatal()
    }

    /// Refuses calls after fmi3Fatal, runs `call`, records a new fatal status and checks
    /// the result: every FMI 3.0 call of an instance goes through here.
    #[inline]
    fn call(
        &mut self,
        function: &'static str,
        call: impl FnOnce(&Fmi3Functions, fmi3Instance) -> fmi3Status,
    ) -> Result<()> {
        if self.library.is_fatal() {
            return Err(self.dead(function));
        }
        let status = {
            let _entered = crate::current::Entered::new(function, &self.name, self.time);
            call(self.library.functions(), self.instance)
        };
        if status == fmi3OK && log::max_level() < log::LevelFilter::Trace {
            return Ok(());
        }
        self.finish(function, status)
    }

    #[cold]
    #[inline(never)]
    fn dead(&self, function: &'static str) -> Error {
        Error::FmuDead {
            function,
            instance: self.name.to_string(),
            time: self.time,
            messages: crate::error::FmuMessages(self.env.log.recent()),
        }
    }

    /// A status other than OK, or any status with trace logging on.
    #[cold]
    #[inline(never)]
    fn finish(&self, function: &'static str, status: fmi3Status) -> Result<()> {
        if status == fmi3Fatal {
            self.library.mark_fatal();
        }
        let site = CallSite {
            function,
            instance: self.name.as_str(),
            time: self.time,
        };
        check(site, status).map_err(|mut e| {
            if let Error::Discard { messages, .. }
            | Error::Failed { messages, .. }
            | Error::Fatal { messages, .. } = &mut e
            {
                *messages = crate::error::FmuMessages(self.env.log.recent());
            }
            e
        })
    }

    /// `fmi3SetDebugLogging`.
    pub(crate) fn fmi3SetDebugLogging(
        &mut self,
        logging_on: bool,
        categories: &[&str],
    ) -> Result<()> {
        const F: &str = "fmi3SetDebugLogging";
        let owned = super::c_strings(categories, "category name", F, &self.name.to_string())?;
        let ptrs: Vec<fmi3String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: `ptrs` holds `ptrs.len()` valid C strings that outlive the call.
        self.call(F, |f, c| unsafe {
            (f.fmi3SetDebugLogging)(c, boolean(logging_on), ptrs.len(), ptrs.as_ptr())
        })
    }

    /// `fmi3EnterInitializationMode`.
    pub(crate) fn fmi3EnterInitializationMode(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<()> {
        // SAFETY: scalar arguments only; the instance is live.
        self.call("fmi3EnterInitializationMode", |f, c| unsafe {
            (f.fmi3EnterInitializationMode)(
                c,
                boolean(tolerance.is_some()),
                tolerance.unwrap_or(0.0),
                start,
                boolean(stop.is_some()),
                stop.unwrap_or(0.0),
            )
        })
    }

    /// `fmi3ExitInitializationMode`.
    pub(crate) fn fmi3ExitInitializationMode(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call("fmi3ExitInitializationMode", |f, c| unsafe {
            (f.fmi3ExitInitializationMode)(c)
        })
    }

    /// `fmi3EnterConfigurationMode`.
    pub(crate) fn fmi3EnterConfigurationMode(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call("fmi3EnterConfigurationMode", |f, c| unsafe {
            (f.fmi3EnterConfigurationMode)(c)
        })
    }

    /// `fmi3ExitConfigurationMode`.
    pub(crate) fn fmi3ExitConfigurationMode(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call("fmi3ExitConfigurationMode", |f, c| unsafe {
            (f.fmi3ExitConfigurationMode)(c)
        })
    }

    /// `fmi3Terminate`.
    pub(crate) fn fmi3Terminate(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call("fmi3Terminate", |f, c| unsafe { (f.fmi3Terminate)(c) })
    }

    /// `fmi3Reset`.
    pub(crate) fn fmi3Reset(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call("fmi3Reset", |f, c| unsafe { (f.fmi3Reset)(c) })
    }

    numeric! {
        fmi3GetFloat32, fmi3SetFloat32: f32;
        fmi3GetFloat64, fmi3SetFloat64: f64;
        fmi3GetInt8, fmi3SetInt8: i8;
        fmi3GetUInt8, fmi3SetUInt8: u8;
        fmi3GetInt16, fmi3SetInt16: i16;
        fmi3GetUInt16, fmi3SetUInt16: u16;
        fmi3GetInt32, fmi3SetInt32: i32;
        fmi3GetUInt32, fmi3SetUInt32: u32;
        fmi3GetInt64, fmi3SetInt64: i64;
        fmi3GetUInt64, fmi3SetUInt64: u64;
    }

    /// `fmi3GetBoolean` into `out` (`nValues` = its length).
    pub(crate) fn fmi3GetBoolean(
        &mut self,
        vrs: &[fmi3ValueReference],
        out: &mut [bool],
    ) -> Result<()> {
        let mut bytes = vec![fmi3False; out.len()];
        // SAFETY: `bytes` is writable for `bytes.len()` values, passed as nValues; a byte
        // holds any value the FMU writes.
        self.call("fmi3GetBoolean", |f, c| unsafe {
            (f.fmi3GetBoolean)(c, vrs.as_ptr(), vrs.len(), bytes.as_mut_ptr(), bytes.len())
        })?;
        for (o, b) in out.iter_mut().zip(bytes) {
            *o = b != fmi3False;
        }
        Ok(())
    }

    /// `fmi3SetBoolean`.
    pub(crate) fn fmi3SetBoolean(
        &mut self,
        vrs: &[fmi3ValueReference],
        values: &[bool],
    ) -> Result<()> {
        let bytes: Vec<fmi3Boolean> = values.iter().map(|&b| boolean(b)).collect();
        // SAFETY: `bytes` holds `bytes.len()` values, passed as nValues.
        self.call("fmi3SetBoolean", |f, c| unsafe {
            (f.fmi3SetBoolean)(c, vrs.as_ptr(), vrs.len(), bytes.as_ptr(), bytes.len())
        })
    }

    /// `fmi3GetString`, copied into `out`.
    pub(crate) fn fmi3GetString(
        &mut self,
        vrs: &[fmi3ValueReference],
        out: &mut [String],
    ) -> Result<()> {
        let mut ptrs: Vec<fmi3String> = vec![std::ptr::null(); out.len()];
        // SAFETY: `ptrs` is writable for `ptrs.len()` values, passed as nValues.
        self.call("fmi3GetString", |f, c| unsafe {
            (f.fmi3GetString)(c, vrs.as_ptr(), vrs.len(), ptrs.as_mut_ptr(), ptrs.len())
        })?;
        for (o, &p) in out.iter_mut().zip(&ptrs) {
            o.clear();
            if !p.is_null() {
                // SAFETY: the FMU returned NUL-terminated strings valid until its next
                // call on this instance; they are copied now.
                o.push_str(&unsafe { CStr::from_ptr(p as *const c_char) }.to_string_lossy());
            }
        }
        Ok(())
    }

    /// `fmi3SetString`.
    pub(crate) fn fmi3SetString(
        &mut self,
        vrs: &[fmi3ValueReference],
        values: &[&str],
    ) -> Result<()> {
        const F: &str = "fmi3SetString";
        let owned = super::c_strings(values, "string value", F, &self.name.to_string())?;
        let ptrs: Vec<fmi3String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: `ptrs` holds `ptrs.len()` C strings that outlive the call, passed as
        // nValues.
        self.call(F, |f, c| unsafe {
            (f.fmi3SetString)(c, vrs.as_ptr(), vrs.len(), ptrs.as_ptr(), ptrs.len())
        })
    }

    /// `fmi3GetBinary`, copied into `out`.
    pub(crate) fn fmi3GetBinary(
        &mut self,
        vrs: &[fmi3ValueReference],
        out: &mut [Vec<u8>],
    ) -> Result<()> {
        let mut sizes = vec![0usize; out.len()];
        let mut ptrs: Vec<fmi3Binary> = vec![std::ptr::null(); out.len()];
        // SAFETY: `sizes` and `ptrs` are writable for `out.len()` values, passed as nValues.
        self.call("fmi3GetBinary", |f, c| unsafe {
            (f.fmi3GetBinary)(
                c,
                vrs.as_ptr(),
                vrs.len(),
                sizes.as_mut_ptr(),
                ptrs.as_mut_ptr(),
                ptrs.len(),
            )
        })?;
        for ((o, &p), &n) in out.iter_mut().zip(&ptrs).zip(&sizes) {
            o.clear();
            if !p.is_null() && n > 0 {
                // SAFETY: the FMU returned `n` readable bytes at `p`, valid until its next
                // call on this instance; they are copied now.
                o.extend_from_slice(unsafe { std::slice::from_raw_parts(p, n) });
            }
        }
        Ok(())
    }

    /// `fmi3SetBinary`.
    pub(crate) fn fmi3SetBinary(
        &mut self,
        vrs: &[fmi3ValueReference],
        values: &[&[u8]],
    ) -> Result<()> {
        let sizes: Vec<usize> = values.iter().map(|v| v.len()).collect();
        let ptrs: Vec<fmi3Binary> = values.iter().map(|v| v.as_ptr()).collect();
        // SAFETY: `ptrs[i]` is readable for `sizes[i]` bytes during the call; both arrays
        // hold `values.len()` entries, passed as nValues.
        self.call("fmi3SetBinary", |f, c| unsafe {
            (f.fmi3SetBinary)(
                c,
                vrs.as_ptr(),
                vrs.len(),
                sizes.as_ptr(),
                ptrs.as_ptr(),
                ptrs.len(),
            )
        })
    }

    /// `fmi3GetOutputDerivatives` into `out` (`nValues` = its length).
    pub(crate) fn fmi3GetOutputDerivatives(
        &mut self,
        vrs: &[fmi3ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        if orders.len() != vrs.len() {
            return Err(Error::LengthMismatch {
                function: "fmi3GetOutputDerivatives",
                instance: self.name.to_string(),
                what: "the orders",
                expected: vrs.len(),
                got: orders.len(),
            });
        }
        // SAFETY: `vrs` and `orders` hold `vrs.len()` entries (checked); `out` is
        // writable for `out.len()` values, passed as nValues.
        self.call("fmi3GetOutputDerivatives", |f, c| unsafe {
            (f.fmi3GetOutputDerivatives)(
                c,
                vrs.as_ptr(),
                vrs.len(),
                orders.as_ptr(),
                out.as_mut_ptr(),
                out.len(),
            )
        })
    }

    /// `fmi3DoStep`: the status is checked; the answers are returned for an OK or
    /// Warning status and, with a Discard, handed to `discarded` (the FMU may ask to end
    /// the simulation with it).
    pub(crate) fn fmi3DoStep(
        &mut self,
        t: f64,
        h: f64,
        no_set_fmu_state_prior: bool,
    ) -> (Result<()>, StepAnswers) {
        let mut event = fmi3False;
        let mut terminate = fmi3False;
        let mut early = fmi3False;
        let mut last = t;
        // SAFETY: scalar arguments and four out-pointers valid for the call's duration.
        let result = self.call("fmi3DoStep", |f, c| unsafe {
            (f.fmi3DoStep)(
                c,
                t,
                h,
                boolean(no_set_fmu_state_prior),
                &mut event,
                &mut terminate,
                &mut early,
                &mut last,
            )
        });
        // An input the intermediate update callback could not set is the cause of
        // whatever the step returned.
        let failure = if self.intermediate_update {
            self.env.take_failure()
        } else {
            None
        };
        let result = match failure {
            Some((status, at)) => {
                let time = std::mem::replace(&mut self.time, at);
                let set = self.finish("fmi3SetFloat64", status);
                self.time = time;
                set.and(result)
            }
            None => result,
        };
        let answers = StepAnswers {
            event_handling_needed: event != fmi3False,
            terminate_simulation: terminate != fmi3False,
            early_return: early != fmi3False,
            last_successful_time: last,
        };
        (result, answers)
    }

    /// `fmi3GetFMUState` into `state` (a new state when `None`, else updated in place).
    pub(crate) fn fmi3GetFMUState(&mut self, state: &mut Option<RawState3>) -> Result<()> {
        const F: &str = "fmi3GetFMUState";
        let mut ptr = state.as_ref().map_or(std::ptr::null_mut(), |s| s.ptr);
        // SAFETY: `ptr` is NULL (asking for a new state) or a live state of this instance.
        let result = self.call(F, |f, c| unsafe { (f.fmi3GetFMUState)(c, &mut ptr) });
        // The FMU may have replaced the pointer even on failure; keep what it left.
        if !ptr.is_null() {
            *state = Some(RawState3 { ptr });
        }
        result?;
        if state.is_none() {
            return Err(Error::InvalidArgument {
                function: F,
                instance: self.name.to_string(),
                message: "the FMU returned fmi3OK but a NULL state".into(),
            });
        }
        Ok(())
    }

    /// `fmi3SetFMUState`.
    pub(crate) fn fmi3SetFMUState(&mut self, state: &RawState3) -> Result<()> {
        let ptr = state.ptr;
        // SAFETY: `ptr` is a live state of this instance (states are only made here and
        // freed by `fmi3FreeFMUState`, which consumes them).
        self.call("fmi3SetFMUState", |f, c| unsafe {
            (f.fmi3SetFMUState)(c, ptr)
        })
    }

    /// `fmi3FreeFMUState`; the state is gone whatever the outcome.
    pub(crate) fn fmi3FreeFMUState(&mut self, state: RawState3) -> Result<()> {
        let mut ptr = state.ptr;
        // SAFETY: `ptr` is a live state of this instance, consumed here.
        self.call("fmi3FreeFMUState", |f, c| unsafe {
            (f.fmi3FreeFMUState)(c, &mut ptr)
        })
    }

    /// `fmi3SerializedFMUStateSize` then `fmi3SerializeFMUState` into `out`.
    pub(crate) fn fmi3SerializeFMUState(
        &mut self,
        state: &RawState3,
        out: &mut Vec<u8>,
    ) -> Result<()> {
        let ptr = state.ptr;
        let mut size = 0usize;
        // SAFETY: `ptr` is a live state of this instance; `size` is a valid out-pointer.
        self.call("fmi3SerializedFMUStateSize", |f, c| unsafe {
            (f.fmi3SerializedFMUStateSize)(c, ptr, &mut size)
        })?;
        out.clear();
        out.resize(size, 0);
        // SAFETY: `out` is writable for `size` bytes; `ptr` is a live state.
        self.call("fmi3SerializeFMUState", |f, c| unsafe {
            (f.fmi3SerializeFMUState)(c, ptr, out.as_mut_ptr(), size)
        })
    }

    /// `fmi3DeserializeFMUState` into a new state.
    pub(crate) fn fmi3DeserializeFMUState(&mut self, bytes: &[u8]) -> Result<RawState3> {
        const F: &str = "fmi3DeserializeFMUState";
        let mut ptr: fmi3FMUState = std::ptr::null_mut();
        // SAFETY: `bytes` is readable for `bytes.len()` bytes; `ptr` holds NULL, asking
        // the FMU for a new state.
        self.call(F, |f, c| unsafe {
            (f.fmi3DeserializeFMUState)(c, bytes.as_ptr(), bytes.len(), &mut ptr)
        })?;
        if ptr.is_null() {
            return Err(Error::InvalidArgument {
                function: F,
                instance: self.name.to_string(),
                message: "the FMU returned fmi3OK but a NULL state".into(),
            });
        }
        Ok(RawState3 { ptr })
    }
}

impl Drop for RawInstance3 {
    fn drop(&mut self) {
        if self.library.is_fatal() {
            // FMI 3.0: after fmi3Fatal no function of any instance may be called.
            log::warn!(
                target: "tether_fmi::call",
                "not calling fmi3FreeInstance({}) after fmi3Fatal",
                self.name
            );
            return;
        }
        log::trace!(target: "tether_fmi::call", "fmi3FreeInstance({})", self.name);
        let _entered = crate::current::Entered::new("fmi3FreeInstance", &self.name, self.time);
        // SAFETY: the instance is live and freed exactly once, here; its states were
        // freed by the safe layer before (`Fmi3Instance::drop`).
        unsafe { (self.library.functions().fmi3FreeInstance)(self.instance) };
    }
}
