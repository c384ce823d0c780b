//! Forwarding of FMU log messages to the `log` facade.
//!
//! `fmi2CallbackLogger` is C-variadic; stable Rust cannot define such a function, so
//! `c/logger.c` does the `vsnprintf` and calls [`sink`] with the finished message. The
//! component environment passed to `fmi2Instantiate` is a [`LogEnv`], whose first field
//! is the address of [`sink`]: the C side needs no link-time reference to Rust.

use std::collections::VecDeque;
use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

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
type Wanted = extern "C" fn(*const LogEnv, c_int, *const c_char) -> c_int;

/// Messages per instance and category shown in one [`WINDOW`] unless
/// [`set_rate_limit`] says otherwise; more are counted and reported as
/// suppressed when the window ends (or the instance is freed).
pub const RATE_LIMIT: u32 = 20;

/// The environment variable that carries the rate limit to an isolated
/// instance's host process: a count, or `off`.
pub const RATE_LIMIT_ENV: &str = "TETHER_FMU_LOG_LIMIT";

/// The rate limit in force; `u32::MAX` means none.
static LIMIT: AtomicU32 = AtomicU32::new(RATE_LIMIT);

/// Sets the number of messages shown per instance, category and [`WINDOW`]
/// (`None`: every message is shown) for every instance of the process, and
/// for host processes started afterwards.
pub fn set_rate_limit(limit: Option<u32>) {
    LIMIT.store(limit.unwrap_or(u32::MAX), Ordering::Relaxed);
}

/// The rate limit in force as [`parse_rate_limit`] reads it, for a host
/// process's environment.
pub(crate) fn rate_limit_text() -> String {
    match LIMIT.load(Ordering::Relaxed) {
        u32::MAX => "off".to_string(),
        n => n.to_string(),
    }
}

/// Parses a rate limit as given on the command line: a count, or `off`.
pub fn parse_rate_limit(text: &str) -> std::result::Result<Option<u32>, String> {
    match text.trim() {
        "off" => Ok(None),
        t => t.parse::<u32>().map(Some).map_err(|_| {
            format!(
                "'{text}' is not a rate limit: expected a number of messages per second, or off"
            )
        }),
    }
}

/// Takes the rate limit from [`RATE_LIMIT_ENV`], if set (in a host process).
pub fn rate_limit_from_env() {
    if let Ok(text) = std::env::var(RATE_LIMIT_ENV) {
        if let Ok(limit) = parse_rate_limit(&text) {
            LIMIT.store(limit.unwrap_or(u32::MAX), Ordering::Relaxed);
        }
    }
}

/// The rate limit's window.
pub const WINDOW: Duration = Duration::from_secs(1);

/// Messages kept per instance for error reports: the last ones, each cut to
/// [`RECENT_CHARS`] characters.
pub const RECENT: usize = 5;

/// Longest message kept for an error report, in characters.
pub const RECENT_CHARS: usize = 300;

/// The component environment of one instance: the functions the C shim calls, then
/// the log target and the rate limit for this instance.
#[repr(C)]
pub(crate) struct LogEnv {
    sink: Sink,
    wanted: Wanted,
    target: String,
    /// Per category (as the FMU spells it): the current window.
    windows: Mutex<Vec<(Vec<u8>, Window)>>,
    /// Whether the message being formatted is to be shown (set by `wanted`
    /// for `sink`); otherwise it is only kept in `recent`.
    show: AtomicBool,
    /// The last messages formatted (every error, every message shown), for
    /// the report of a failed call.
    recent: Mutex<VecDeque<String>>,
}

/// One category's rate-limit window.
#[derive(Debug, Clone, Copy)]
struct Window {
    start: Instant,
    shown: u32,
    suppressed: u64,
    level: log::Level,
}

impl LogEnv {
    /// A boxed environment for the instance called `instance` (the box keeps its address
    /// stable for as long as the FMU may call back).
    pub(crate) fn new(instance: &str) -> Box<LogEnv> {
        Box::new(LogEnv::plain(instance))
    }

    /// The environment itself, for a caller that boxes it inside its own (the FMI
    /// 3.0 instance environment, whose first field it is).
    pub(crate) fn plain(instance: &str) -> LogEnv {
        LogEnv {
            sink,
            wanted,
            target: format!("fmu::{instance}"),
            windows: Mutex::new(Vec::new()),
            show: AtomicBool::new(false),
            recent: Mutex::new(VecDeque::with_capacity(RECENT)),
        }
    }

    /// The last messages of the instance, oldest first (at most [`RECENT`]).
    pub(crate) fn recent(&self) -> Vec<String> {
        let recent = self.recent.lock().unwrap_or_else(PoisonError::into_inner);
        recent.iter().cloned().collect()
    }

    fn keep(&self, category: &str, message: &str) {
        let mut text = if category.is_empty() {
            message.trim().to_string()
        } else {
            format!("[{category}] {}", message.trim())
        };
        if let Some((cut, _)) = text.char_indices().nth(RECENT_CHARS) {
            text.truncate(cut);
            text.push('…');
        }
        let mut recent = self.recent.lock().unwrap_or_else(PoisonError::into_inner);
        if recent.len() == RECENT {
            recent.pop_front();
        }
        recent.push_back(text.replace(['\n', '\r'], " "));
    }

    /// Whether a message of `level` in `category` is shown: counts it against the
    /// window, reporting what the previous window suppressed when a new one starts.
    fn admit(&self, level: log::Level, category: &[u8]) -> bool {
        let now = Instant::now();
        let mut windows = self.windows.lock().unwrap_or_else(PoisonError::into_inner);
        let i = match windows.iter().position(|(c, _)| c == category) {
            Some(i) => i,
            None => {
                let fresh = Window {
                    start: now,
                    shown: 0,
                    suppressed: 0,
                    level,
                };
                windows.push((category.to_vec(), fresh));
                windows.len() - 1
            }
        };
        let (name, window) = &mut windows[i];
        if now.duration_since(window.start) >= WINDOW {
            let ended = *window;
            *window = Window {
                start: now,
                shown: 0,
                suppressed: 0,
                level,
            };
            if ended.suppressed > 0 {
                let name = String::from_utf8_lossy(name).into_owned();
                drop(windows);
                self.report(&name, ended);
                windows = self.windows.lock().unwrap_or_else(PoisonError::into_inner);
                windows[i].1.shown += 1;
                return true;
            }
        }
        if window.shown < LIMIT.load(Ordering::Relaxed) {
            window.shown += 1;
            true
        } else {
            window.suppressed += 1;
            window.level = window.level.min(level);
            false
        }
    }

    fn report(&self, category: &str, window: Window) {
        log::log!(
            target: &self.target,
            window.level,
            "[{category}] {} more messages suppressed (more than {} in {} s; --fmu-log-limit)",
            window.suppressed,
            LIMIT.load(Ordering::Relaxed),
            WINDOW.as_secs_f64()
        );
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

impl Drop for LogEnv {
    /// Reports what the last windows suppressed (the instance is freed).
    fn drop(&mut self) {
        let windows = std::mem::take(
            self.windows
                .get_mut()
                .unwrap_or_else(PoisonError::into_inner),
        );
        for (category, window) in windows {
            if window.suppressed > 0 {
                self.report(&String::from_utf8_lossy(&category), window);
            }
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

/// Asked by `c/logger.c` before it formats a message: 1 if it is shown or
/// kept for error reports (every error is: formatting errors costs little,
/// they are rare), 0 if it is dropped unformatted.
extern "C" fn wanted(env: *const LogEnv, status: c_int, category: *const c_char) -> c_int {
    if env.is_null() {
        return 0;
    }
    // SAFETY: as in `sink`: the environment handed to fmi2Instantiate, alive until
    // after fmi2FreeInstance.
    let env = unsafe { &*env };
    let level = level_for(Status::from(status));
    let category: &[u8] = if category.is_null() {
        b""
    } else {
        // SAFETY: a non-NULL category is a NUL-terminated string valid during the call.
        unsafe { CStr::from_ptr(category) }.to_bytes()
    };
    let show = log::log_enabled!(target: &env.target, level) && env.admit(level, category);
    env.show.store(show, Ordering::Relaxed);
    c_int::from(show || level == log::Level::Error)
}

/// The FMI 3.0 log callback (`fmi3LogMessageCallback`): FMI 3.0 hands over the
/// finished message, so no C shim is needed; the instance environment starts with
/// the instance's [`LogEnv`] (`Env3`, `#[repr(C)]`), as for FMI 2.0.
pub(crate) extern "C" fn fmi3_log_message(
    env: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    let env = env.cast_const().cast::<LogEnv>();
    if wanted(env, status, category) == 0 {
        return;
    }
    sink(env, std::ptr::null(), status, category, message);
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
    let category = text(category);
    let message = text(message);
    env.keep(&category, &message);
    if env.show.load(Ordering::Relaxed) && log::log_enabled!(target: &env.target, level) {
        log::log!(target: &env.target, level, "[{category}] {message}");
    }
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

        // A flood: RATE_LIMIT shown, the rest counted and reported once the
        // instance's environment goes (fmi2FreeInstance).
        let flood = CString::new("flood").unwrap();
        for n in 0..1000 {
            // SAFETY: as above; "%d" matches the int passed.
            unsafe {
                logger(
                    callbacks.componentEnvironment,
                    std::ptr::null(),
                    1,
                    flood.as_ptr(),
                    c"message %d".as_ptr(),
                    n as c_int,
                );
            }
        }
        drop(env);
        let records = CAPTURE.0.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let flooded: Vec<_> = records[2..].iter().map(|r| r.2.as_str()).collect();
        assert_eq!(flooded.len(), RATE_LIMIT as usize + 1, "{flooded:?}");
        assert_eq!(flooded[0], "[flood] message 0");
        assert_eq!(
            flooded.last().unwrap(),
            &format!(
                "[flood] {} more messages suppressed (more than {RATE_LIMIT} in 1 s; --fmu-log-limit)",
                1000 - RATE_LIMIT
            )
        );

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
