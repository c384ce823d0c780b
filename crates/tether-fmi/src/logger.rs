//! Forwarding of FMU log messages to the `log` facade.
//!
//! `fmi2CallbackLogger` is C-variadic; stable Rust cannot define such a function, so
//! `c/logger.c` does the `vsnprintf` and calls [`sink`] with the finished message. The
//! component environment passed to `fmi2Instantiate` is a [`LogEnv`], whose first field
//! is the address of [`sink`]: the C side needs no link-time reference to Rust.

use std::ffi::{c_char, c_int, c_void, CStr};

use crate::raw::{self, fmi2CallbackFunctions, fmi2ComponentEnvironment, Status};

extern "C" {
    /// The variadic logger of `c/logger.c`.
    fn tether_fmi_logger(
        env: fmi2ComponentEnvironment,
        instance: raw::fmi2String,
        status: raw::fmi2Status,
        category: raw::fmi2String,
        message: raw::fmi2String,
        ...
    );
    /// `calloc`, via `c/logger.c`.
    fn tether_fmi_calloc(nobj: usize, size: usize) -> *mut c_void;
    /// `free`, via `c/logger.c`.
    fn tether_fmi_free(obj: *mut c_void);
}

type Sink = extern "C" fn(*const LogEnv, *const c_char, c_int, *const c_char, *const c_char);

/// The component environment of one instance: the sink the C shim calls, then the log
/// target for this instance.
#[repr(C)]
pub(crate) struct LogEnv {
    sink: Sink,
    target: String,
}

impl LogEnv {
    /// A boxed environment for the instance called `instance` (the box keeps its address
    /// stable for as long as the FMU may call back).
    pub(crate) fn new(instance: &str) -> Box<LogEnv> {
        Box::new(LogEnv {
            sink,
            target: format!("fmu::{instance}"),
        })
    }

    /// The callback table for `fmi2Instantiate`, pointing at this environment.
    pub(crate) fn callbacks(self: &mut Box<Self>) -> fmi2CallbackFunctions {
        let env: *mut LogEnv = &mut **self;
        fmi2CallbackFunctions {
            logger: Some(tether_fmi_logger),
            allocateMemory: Some(tether_fmi_calloc),
            freeMemory: Some(tether_fmi_free),
            stepFinished: None,
            componentEnvironment: env.cast(),
        }
    }
}

/// The log level for a message logged with `status`.
pub(crate) fn level_for(status: Status) -> log::Level {
    match status {
        Status::Ok => log::Level::Info,
        Status::Pending => log::Level::Debug,
        Status::Warning | Status::Discard => log::Level::Warn,
        Status::Error | Status::Fatal | Status::Unknown(_) => log::Level::Error,
    }
}

/// Text of a possibly-NULL C string, lossily decoded.
fn text(ptr: *const c_char) -> String {
    if ptr.is_null() {
        return String::new();
    }
    // SAFETY: non-NULL strings passed to the logger are NUL-terminated per the FMI
    // standard (the message one was produced by vsnprintf in c/logger.c) and stay valid for
    // the duration of the callback, during which this borrow ends.
    let c = unsafe { CStr::from_ptr(ptr) };
    c.to_string_lossy().into_owned()
}

/// Receives a formatted message from `c/logger.c`.
extern "C" fn sink(
    env: *const LogEnv,
    _instance: *const c_char,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    if env.is_null() {
        return;
    }
    // SAFETY: `env` is the `componentEnvironment` handed to fmi2Instantiate, which points
    // to a `LogEnv` boxed in the owning component and freed only after fmi2FreeInstance.
    let env = unsafe { &*env };
    let level = level_for(Status::from(status));
    if !log::log_enabled!(target: &env.target, level) {
        return;
    }
    let category = text(category);
    let message = text(message);
    log::log!(target: &env.target, level, "[{category}] {message}");
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::CString;

    #[test]
    fn statuses_map_to_levels() {
        assert_eq!(level_for(Status::Ok), log::Level::Info);
        assert_eq!(level_for(Status::Warning), log::Level::Warn);
        assert_eq!(level_for(Status::Fatal), log::Level::Error);
    }

    /// Captures records of targets starting with "fmu::".
    struct Capture(std::sync::Mutex<Vec<(log::Level, String, String)>>);

    impl log::Log for Capture {
        fn enabled(&self, _: &log::Metadata<'_>) -> bool {
            true
        }
        fn log(&self, record: &log::Record<'_>) {
            if record.target().starts_with("fmu::") {
                let mut records = self.0.lock().unwrap_or_else(|e| e.into_inner());
                records.push((
                    record.level(),
                    record.target().to_owned(),
                    record.args().to_string(),
                ));
            }
        }
        fn flush(&self) {}
    }

    static CAPTURE: Capture = Capture(std::sync::Mutex::new(Vec::new()));

    #[test]
    fn the_c_shim_formats_and_reaches_the_sink() {
        log::set_logger(&CAPTURE).expect("only this test installs a logger");
        log::set_max_level(log::LevelFilter::Trace);
        let mut env = LogEnv::new("unit");
        let callbacks = env.callbacks();
        let logger = callbacks.logger.expect("logger is set");
        let fmt = CString::new("value %d of %s and a long tail %0600d %0600d").unwrap();
        let arg = CString::new("x").unwrap();
        let cat = CString::new("logAll").unwrap();
        // SAFETY: the environment is the live `LogEnv` above; the format string's
        // conversions match the arguments passed.
        unsafe {
            logger(
                callbacks.componentEnvironment,
                std::ptr::null(),
                0,
                cat.as_ptr(),
                fmt.as_ptr(),
                42 as c_int,
                arg.as_ptr(),
                1 as c_int,
                2 as c_int,
            );
        }
        // SAFETY: as above, with a warning and no format arguments.
        unsafe {
            logger(
                callbacks.componentEnvironment,
                std::ptr::null(),
                1,
                std::ptr::null(),
                CString::new("100%% sure").unwrap().as_ptr(),
            );
        }
        let records = CAPTURE.0.lock().unwrap_or_else(|e| e.into_inner()).clone();
        assert_eq!(records.len(), 2, "{records:?}");
        let (level, target, message) = &records[0];
        assert_eq!((*level, target.as_str()), (log::Level::Info, "fmu::unit"));
        let expected = format!(
            "[logAll] value 42 of x and a long tail {:0600} {:0600}",
            1, 2
        );
        assert_eq!(message, &expected);
        assert_eq!(records[1].0, log::Level::Warn);
        assert_eq!(records[1].2, "[] 100% sure");

        let alloc = callbacks.allocateMemory.expect("allocator is set");
        let free = callbacks.freeMemory.expect("free is set");
        // SAFETY: calloc/free pair on a fresh allocation.
        unsafe {
            let p = alloc(4, 8).cast::<u64>();
            assert!(!p.is_null());
            assert_eq!(*p.add(3), 0);
            free(p.cast());
        }
    }
}
