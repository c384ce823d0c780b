//! An in-process FMU that ends the process from inside a call: `exit()` (any
//! code, 0 included) or `abort()`. The call never returns, so no error value
//! says what happened, and `exit(0)` looks like success to whoever started the
//! process. A program (the `tether` CLI, the Python package) installs a
//! handler with [`install`]: it runs from an exit hook (glibc's `on_exit`,
//! which also gives the exit code; `atexit` elsewhere) or from a SIGABRT
//! handler, and [`blame`] names the FMI call this thread is inside (from
//! [`crate::current_call`]).
//!
//! The hooks act only in the process that installed them: a child the FMU
//! forked (which inherits them) exits or aborts as if they were not there.
//! After an abort the handler has returned, the SIGABRT action found at
//! [`install`] (the default, or Python's `faulthandler`) is restored and the
//! signal raised again, so the process still ends by SIGABRT (status 134);
//! `alarm(10)` is the backstop should the handler deadlock (it does more than
//! a signal handler may: locks, allocation; best effort).

use std::ffi::c_int;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::{Once, OnceLock};

/// How the process is ending.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// `exit(code)`; the code where the C library tells it.
    Exit(Option<i32>),
    /// `abort()` (SIGABRT).
    Abort,
}

impl Ending {
    /// What was called: `exit(3)`, `exit()`, `abort()`.
    pub fn called(self) -> String {
        match self {
            Ending::Exit(Some(code)) => format!("exit({code})"),
            Ending::Exit(None) => "exit()".to_string(),
            Ending::Abort => "abort()".to_string(),
        }
    }
}

static HANDLER: OnceLock<fn(Ending)> = OnceLock::new();

/// The SIGABRT action before [`install`], restored before the signal is
/// raised again.
struct Previous(libc::sigaction);

// SAFETY: a plain C struct of a handler address, a signal mask and flags,
// written once (before the handler that reads it is installed), then only read.
unsafe impl Sync for Previous {}
unsafe impl Send for Previous {}

static PREVIOUS: OnceLock<Previous> = OnceLock::new();

/// The process that installed the hooks (a forked child has another id).
static INSTALLER: AtomicI32 = AtomicI32::new(0);

/// Installs the exit hook and the SIGABRT handler, once per process, calling
/// `handler` when the process ends by `exit()` or `abort()`. The handler runs
/// on the thread that called `exit()` or `abort()`: [`blame`] names the call
/// it was inside. A second `install` in the same process changes nothing.
pub fn install(handler: fn(Ending)) {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let _ = HANDLER.set(handler);
        // SAFETY: getpid has no preconditions.
        INSTALLER.store(unsafe { libc::getpid() }, Ordering::SeqCst);
        register_exit_hook();
        let on_abort: extern "C" fn(c_int) = on_abort;
        // SAFETY: installs a handler for SIGABRT only; `on_abort` has the
        // signature sigaction expects for a handler without SA_SIGINFO, and
        // the sigaction value is fully initialised (zeroed, then the fields set).
        unsafe {
            let mut previous: libc::sigaction = std::mem::zeroed();
            libc::sigaction(libc::SIGABRT, std::ptr::null(), &mut previous);
            let _ = PREVIOUS.set(Previous(previous));
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_abort as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(libc::SIGABRT, &action, std::ptr::null_mut());
        }
    });
}

/// Makes this process the hooks' own: for a child the program itself forked
/// to go on as a program of its own (Python's `os.fork()`, as a
/// `multiprocessing` pool does), not for one an FMU forked. Nothing if the
/// hooks are not installed.
pub fn adopt() {
    if HANDLER.get().is_some() {
        // SAFETY: getpid has no preconditions.
        INSTALLER.store(unsafe { libc::getpid() }, Ordering::SeqCst);
    }
}

/// Who did it: `FMU instance 'm' called exit(3) inside fmi2DoStep at t=0.5`,
/// if this thread is inside an FMI call.
pub fn blame(ending: Ending) -> Option<String> {
    crate::current_call().map(|call| {
        format!(
            "FMU instance '{}' called {} inside {} at t={}",
            call.instance,
            ending.called(),
            call.function,
            call.time
        )
    })
}

/// Whether this is the process that installed the hooks.
fn installer() -> bool {
    // SAFETY: getpid has no preconditions and is async-signal-safe.
    INSTALLER.load(Ordering::SeqCst) == unsafe { libc::getpid() }
}

fn run_handler(ending: Ending) {
    if !installer() {
        return;
    }
    if let Some(handler) = HANDLER.get() {
        handler(ending);
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn register_exit_hook() {
    use std::ffi::c_void;
    extern "C" {
        /// glibc: like atexit, and the function receives the exit code.
        fn on_exit(function: extern "C" fn(c_int, *mut c_void), arg: *mut c_void) -> c_int;
    }
    extern "C" fn hook(code: c_int, _arg: *mut c_void) {
        run_handler(Ending::Exit(Some(code)));
    }
    // SAFETY: glibc's on_exit takes a function of exactly this signature and an
    // argument it passes back unused; `hook` is a plain function living forever.
    unsafe { on_exit(hook, std::ptr::null_mut()) };
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn register_exit_hook() {
    extern "C" fn hook() {
        run_handler(Ending::Exit(None));
    }
    // SAFETY: atexit takes a function without arguments living forever.
    unsafe { libc::atexit(hook) };
}

extern "C" fn on_abort(_signal: c_int) {
    if installer() {
        // SAFETY: alarm is async-signal-safe: it ends the process (SIGALRM) in
        // 10 s should the best-effort handler deadlock.
        unsafe { libc::alarm(10) };
        run_handler(Ending::Abort);
    }
    // SAFETY: sigaction, signal and raise are async-signal-safe; with the
    // action before ours restored (the default, or another handler that ends
    // with it), the SIGABRT raised here (blocked until this handler returns)
    // ends the process as abort() does, with its exit status. Should that
    // action return (SIG_IGN), abort() itself goes on to end the process.
    unsafe {
        match PREVIOUS.get() {
            Some(Previous(previous)) => {
                libc::sigaction(libc::SIGABRT, previous, std::ptr::null_mut());
            }
            None => {
                libc::signal(libc::SIGABRT, libc::SIG_DFL);
            }
        }
        libc::raise(libc::SIGABRT);
    }
}

/// Ends this process with `code`, once the program has finished its work and
/// dropped what it owns (instances freed, libraries released, results files
/// closed, extraction folders removed): standard output and error are flushed,
/// then `_exit` ends the process without the C library's exit handlers and
/// the destructors of shared libraries still loaded.
///
/// Those are the FMUs' own teardown, which FMI does not define and a finished
/// run does not need; some run code that is unsafe at process exit. An FMU
/// library that the loader cannot unload (a C++ library with unique symbols
/// is pinned, `RTLD_NODELETE`) keeps its destructors for the exit, and
/// pythonfmu3's runtime then resets a static that the exit handlers have
/// already destroyed: a use after free that ends a finished run by SIGABRT
/// now and then (docs/reliability.md, "After the run").
pub fn leave(code: u8) -> ! {
    use std::io::Write as _;
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    // SAFETY: _exit has no preconditions; everything this process must write
    // is written (the buffered standard streams flushed just above, files
    // closed by their owners before the call).
    unsafe { libc::_exit(c_int::from(code)) }
}
