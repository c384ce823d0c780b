//! [`RawComponent`]: owns one `fmi2Component` and exposes the C functions one-to-one
//! (same names), with slice-length checks, the fatal-state guard and the status check.

use std::ffi::{c_char, CStr, CString};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

mod me;
mod state;
mod values;

pub(crate) use me::EventInfo;

use crate::archive::FmuDir;
use crate::error::{Error, Result};
use crate::library::Library;
use crate::logger::LogEnv;
use crate::raw::*;

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// An FMU state pointer together with the identity of the component that made it.
#[derive(Debug)]
pub(crate) struct RawState {
    ptr: fmi2FMUstate,
    owner: u64,
    owner_name: Arc<str>,
}

// SAFETY: an fmi2FMUstate is an opaque handle only ever passed back to its owning
// component, whose calls the safe layer serialises (`&mut Instance`, or the lock of
// the instance's orphans once the instance is gone).
unsafe impl Send for RawState {}

impl RawState {
    /// The name of the instance that created this state.
    pub(crate) fn owner_name(&self) -> &Arc<str> {
        &self.owner_name
    }

    /// Moves the handle out, leaving this value marked freed (NULL).
    pub(crate) fn take(&mut self) -> RawState {
        RawState {
            ptr: std::mem::replace(&mut self.ptr, std::ptr::null_mut()),
            owner: self.owner,
            owner_name: Arc::clone(&self.owner_name),
        }
    }
}

/// One live `fmi2Component`, freed with `fmi2FreeInstance` on drop.
pub(crate) struct RawComponent {
    component: fmi2Component,
    id: u64,
    name: crate::current::Name,
    /// The communication time reported in errors; maintained by the safe layer.
    pub(crate) time: f64,
    bool_scratch: Vec<fmi2Boolean>,
    /// Must outlive the component: the FMU may keep pointers to both.
    _callbacks: Box<fmi2CallbackFunctions>,
    _env: Box<LogEnv>,
    library: Arc<Library>,
    _dir: Arc<FmuDir>,
    /// Held while the component lives when the model declares
    /// `canBeInstantiatedOnlyOncePerProcess` (released after `fmi2FreeInstance`).
    pub(crate) once: Option<crate::shared::OnceGuard>,
}

// SAFETY: FMI 2.0 lets an instance be used from any thread as long as calls are not
// concurrent; the safe layer calls it through `&mut Instance`, or under the lock of
// the instance's orphans once the `Instance` value is gone.
unsafe impl Send for RawComponent {}

impl std::fmt::Debug for RawComponent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawComponent")
            .field("name", &self.name)
            .field("time", &self.time)
            .finish_non_exhaustive()
    }
}

/// Arguments of `fmi2Instantiate` besides the callbacks.
pub(crate) struct InstantiateArgs<'a> {
    pub model: &'a str,
    pub instance_name: &'a str,
    pub guid: &'a str,
    pub resource_location: &'a str,
    pub visible: bool,
    pub logging_on: bool,
    /// `fmi2ModelExchange` instead of `fmi2CoSimulation`.
    pub model_exchange: bool,
}

pub(super) fn boolean(b: bool) -> fmi2Boolean {
    if b {
        fmi2True
    } else {
        fmi2False
    }
}

impl RawComponent {
    /// `fmi2Instantiate` for co-simulation (or model exchange, as `args` says).
    pub(crate) fn fmi2Instantiate(
        library: Arc<Library>,
        dir: Arc<FmuDir>,
        args: &InstantiateArgs<'_>,
    ) -> Result<RawComponent> {
        let invalid = |what: &str| Error::InvalidArgument {
            function: "fmi2Instantiate",
            instance: args.instance_name.to_owned(),
            message: format!("{what} contains a NUL byte"),
        };
        let name_c = CString::new(args.instance_name).map_err(|_| invalid("the instance name"))?;
        let guid_c = CString::new(args.guid).map_err(|_| invalid("the GUID"))?;
        let location_c =
            CString::new(args.resource_location).map_err(|_| invalid("the resource location"))?;
        let mut env = LogEnv::new(args.instance_name);
        let callbacks = Box::new(env.callbacks());
        if library.is_fatal() {
            return Err(Error::FmuDead {
                function: "fmi2Instantiate",
                instance: args.instance_name.to_owned(),
                time: 0.0,
                messages: Default::default(),
            });
        }
        log::trace!(target: "tether_fmi::call", "fmi2Instantiate({})", args.instance_name);
        let name = crate::current::Name::new(args.instance_name);
        let entered = crate::current::Entered::new("fmi2Instantiate", &name, 0.0);
        // SAFETY: all strings are NUL-terminated and live across the call; `callbacks`
        // and the environment it points to are boxed and kept in the returned component
        // until after fmi2FreeInstance, as FMI 2.0.5 requires.
        let component = unsafe {
            (library.functions().fmi2Instantiate)(
                name_c.as_ptr(),
                if args.model_exchange {
                    fmi2ModelExchange
                } else {
                    fmi2CoSimulation
                },
                guid_c.as_ptr(),
                location_c.as_ptr(),
                &*callbacks,
                boolean(args.visible),
                boolean(args.logging_on),
            )
        };
        drop(entered);
        if component.is_null() {
            return Err(Error::InstantiationFailed {
                model: args.model.to_owned(),
                instance: args.instance_name.to_owned(),
                messages: crate::error::FmuMessages(env.recent()),
            });
        }
        Ok(RawComponent {
            component,
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            name,
            time: 0.0,
            bool_scratch: Vec::new(),
            _callbacks: callbacks,
            _env: env,
            library,
            _dir: dir,
            once: None,
        })
    }

    /// The instance name.
    pub(crate) fn name(&self) -> &str {
        self.name.as_str()
    }

    /// Whether this FMU has returned fmi2Fatal.
    pub(crate) fn is_fatal(&self) -> bool {
        self.library.is_fatal()
    }

    fn site(&self, function: &'static str) -> CallSite<'_> {
        CallSite {
            function,
            instance: self.name.as_str(),
            time: self.time,
        }
    }

    /// Refuses calls after fmi2Fatal, runs `call`, records a new fatal status and checks
    /// the result: every FMI call of an instance goes through here. The common case (OK,
    /// no trace logging) is a load, the call and a compare.
    #[inline]
    fn call(
        &mut self,
        function: &'static str,
        call: impl FnOnce(&Fmi2Functions, fmi2Component) -> fmi2Status,
    ) -> Result<()> {
        if self.library.is_fatal() {
            return Err(self.dead(function));
        }
        let status = {
            let _entered = crate::current::Entered::new(function, &self.name, self.time);
            call(self.library.functions(), self.component)
        };
        if status == fmi2OK && log::max_level() < log::LevelFilter::Trace {
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
            messages: crate::error::FmuMessages(self._env.recent()),
        }
    }

    /// A status other than OK, or any status with trace logging on.
    #[cold]
    #[inline(never)]
    fn finish(&self, function: &'static str, status: fmi2Status) -> Result<()> {
        if status == fmi2Fatal {
            self.library.mark_fatal();
        }
        check(self.site(function), status).map_err(|mut e| {
            if let Error::Discard { messages, .. }
            | Error::Failed { messages, .. }
            | Error::Fatal { messages, .. } = &mut e
            {
                *messages = crate::error::FmuMessages(self._env.recent());
            }
            e
        })
    }

    #[inline]
    fn same_len(
        &self,
        function: &'static str,
        what: &'static str,
        expected: usize,
        got: usize,
    ) -> Result<()> {
        if expected == got {
            Ok(())
        } else {
            Err(self.length_mismatch(function, what, expected, got))
        }
    }

    #[cold]
    #[inline(never)]
    fn length_mismatch(
        &self,
        function: &'static str,
        what: &'static str,
        expected: usize,
        got: usize,
    ) -> Error {
        Error::LengthMismatch {
            function,
            instance: self.name.to_string(),
            what,
            expected,
            got,
        }
    }

    /// Whether `state` is a live state of this component.
    #[inline]
    fn owned(&self, function: &'static str, state: &RawState) -> Result<()> {
        if !state.ptr.is_null() && state.owner == self.id {
            Ok(())
        } else {
            Err(self.not_owned(function, state))
        }
    }

    #[cold]
    #[inline(never)]
    fn not_owned(&self, function: &'static str, state: &RawState) -> Error {
        if state.ptr.is_null() {
            Error::InvalidArgument {
                function,
                instance: self.name.to_string(),
                message: "the FMU state was already freed".into(),
            }
        } else {
            Error::ForeignState {
                function,
                instance: self.name.to_string(),
                owner: state.owner_name.to_string(),
            }
        }
    }

    /// `fmi2SetDebugLogging`.
    pub(crate) fn fmi2SetDebugLogging(
        &mut self,
        logging_on: bool,
        categories: &[&str],
    ) -> Result<()> {
        const F: &str = "fmi2SetDebugLogging";
        let owned = super::c_strings(categories, "category name", F, &self.name.to_string())?;
        let ptrs: Vec<fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: `ptrs` holds `ptrs.len()` valid C strings that outlive the call.
        self.call(F, |f, c| unsafe {
            (f.fmi2SetDebugLogging)(c, boolean(logging_on), ptrs.len(), ptrs.as_ptr())
        })
    }

    /// `fmi2SetupExperiment`.
    pub(crate) fn fmi2SetupExperiment(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<()> {
        // SAFETY: scalar arguments only; the component is live.
        self.call("fmi2SetupExperiment", |f, c| unsafe {
            (f.fmi2SetupExperiment)(
                c,
                boolean(tolerance.is_some()),
                tolerance.unwrap_or(0.0),
                start,
                boolean(stop.is_some()),
                stop.unwrap_or(0.0),
            )
        })
    }

    /// `fmi2EnterInitializationMode`.
    pub(crate) fn fmi2EnterInitializationMode(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call("fmi2EnterInitializationMode", |f, c| unsafe {
            (f.fmi2EnterInitializationMode)(c)
        })
    }

    /// `fmi2ExitInitializationMode`.
    pub(crate) fn fmi2ExitInitializationMode(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call("fmi2ExitInitializationMode", |f, c| unsafe {
            (f.fmi2ExitInitializationMode)(c)
        })
    }

    /// `fmi2Terminate`.
    pub(crate) fn fmi2Terminate(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call("fmi2Terminate", |f, c| unsafe { (f.fmi2Terminate)(c) })
    }

    /// `fmi2Reset`.
    pub(crate) fn fmi2Reset(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call("fmi2Reset", |f, c| unsafe { (f.fmi2Reset)(c) })
    }

    /// `fmi2DoStep`.
    #[inline]
    pub(crate) fn fmi2DoStep(
        &mut self,
        t: f64,
        h: f64,
        no_set_fmu_state_prior: bool,
    ) -> Result<()> {
        // SAFETY: scalar arguments only; the component is live.
        self.call("fmi2DoStep", |f, c| unsafe {
            (f.fmi2DoStep)(c, t, h, boolean(no_set_fmu_state_prior))
        })
    }

    /// `fmi2CancelStep`.
    pub(crate) fn fmi2CancelStep(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call("fmi2CancelStep", |f, c| unsafe { (f.fmi2CancelStep)(c) })
    }

    /// `fmi2GetStatus`.
    pub(crate) fn fmi2GetStatus(&mut self, kind: fmi2StatusKind) -> Result<Status> {
        let mut value: fmi2Status = fmi2OK;
        // SAFETY: `value` is a valid out-pointer for the call's duration.
        self.call("fmi2GetStatus", |f, c| unsafe {
            (f.fmi2GetStatus)(c, kind, &mut value)
        })?;
        Ok(Status::from(value))
    }

    /// `fmi2GetRealStatus`.
    pub(crate) fn fmi2GetRealStatus(&mut self, kind: fmi2StatusKind) -> Result<f64> {
        let mut value = 0.0;
        // SAFETY: `value` is a valid out-pointer for the call's duration.
        self.call("fmi2GetRealStatus", |f, c| unsafe {
            (f.fmi2GetRealStatus)(c, kind, &mut value)
        })?;
        Ok(value)
    }

    /// `fmi2GetIntegerStatus`.
    pub(crate) fn fmi2GetIntegerStatus(&mut self, kind: fmi2StatusKind) -> Result<i32> {
        let mut value = 0;
        // SAFETY: `value` is a valid out-pointer for the call's duration.
        self.call("fmi2GetIntegerStatus", |f, c| unsafe {
            (f.fmi2GetIntegerStatus)(c, kind, &mut value)
        })?;
        Ok(value)
    }

    /// `fmi2GetBooleanStatus`.
    pub(crate) fn fmi2GetBooleanStatus(&mut self, kind: fmi2StatusKind) -> Result<bool> {
        let mut value = fmi2False;
        // SAFETY: `value` is a valid out-pointer for the call's duration.
        self.call("fmi2GetBooleanStatus", |f, c| unsafe {
            (f.fmi2GetBooleanStatus)(c, kind, &mut value)
        })?;
        Ok(value != fmi2False)
    }

    /// `fmi2GetStringStatus`.
    pub(crate) fn fmi2GetStringStatus(&mut self, kind: fmi2StatusKind) -> Result<String> {
        let mut value: fmi2String = std::ptr::null();
        // SAFETY: `value` is a valid out-pointer for the call's duration.
        self.call("fmi2GetStringStatus", |f, c| unsafe {
            (f.fmi2GetStringStatus)(c, kind, &mut value)
        })?;
        if value.is_null() {
            return Ok(String::new());
        }
        // SAFETY: a non-NULL result is a NUL-terminated string owned by the FMU, valid
        // until the next call on this instance; it is copied at once.
        Ok(unsafe { CStr::from_ptr(value as *const c_char) }
            .to_string_lossy()
            .into_owned())
    }
}

impl Drop for RawComponent {
    fn drop(&mut self) {
        if self.library.is_fatal() {
            // FMI 2.0: after fmi2Fatal no function of any instance may be called.
            log::warn!(
                target: "tether_fmi::call",
                "not calling fmi2FreeInstance({}) after fmi2Fatal",
                self.name
            );
            return;
        }
        log::trace!(target: "tether_fmi::call", "fmi2FreeInstance({})", self.name);
        let _entered = crate::current::Entered::new("fmi2FreeInstance", &self.name, self.time);
        // SAFETY: the component is live and freed exactly once, here; it is dropped
        // only after every state of it was freed (see `instance::fmi2::Orphans`).
        unsafe { (self.library.functions().fmi2FreeInstance)(self.component) };
    }
}
