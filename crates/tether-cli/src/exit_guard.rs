//! An FMU that ends the process from inside a call: `exit()` (any code, 0
//! included) or `abort()`. The run never returns there, so nothing would mark the
//! results file or report the error; worse, `exit(0)` looked like success.
//!
//! While a run is armed ([`arm`]), an exit hook (glibc's `on_exit`, which also
//! gives the exit code; `atexit` elsewhere) and a SIGABRT handler end the results
//! file with every accepted row and the trailer `# incomplete: FMU instance 'm'
//! called exit(3) inside fmi2DoStep at t=0.5` (the call this thread was inside,
//! from [`tether_fmi::current_call`]), remove the FMU extraction folders, print
//! the one-line error and end the process: exit code 1 after `exit()`, SIGABRT
//! (134) after `abort()`. The SIGABRT handler does more than a signal handler
//! may (locks, allocation): it is best effort, with `alarm(10)` as a backstop
//! should it deadlock. A second Ctrl-C (which exits at once, code 130) gets the
//! trailer and the folders removed the same way.
//!
//! A segmentation fault or SIGKILL cannot be handled in-process: the rows up to
//! the last flush are on disk (`tether_master::FLUSH_INTERVAL`) and the next run
//! sweeps the extraction folders (`tether_fmi::sweep_leftovers`).

use std::ffi::c_int;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, Once};
use std::time::Duration;

use tether_master::Emergency;

/// What the hooks need about the run in progress.
struct Armed {
    emergency: Option<Emergency>,
    out: PathBuf,
}

static ARMED: Mutex<Option<Armed>> = Mutex::new(None);

/// How long the hooks wait for the writer thread to write the last rows.
const WRITE_WAIT: Duration = Duration::from_secs(5);

/// Disarms on drop, when the run has returned.
pub struct Guard(());

impl Drop for Guard {
    fn drop(&mut self) {
        take_armed(true);
    }
}

/// Arms the hooks for a run recording into `out` (with `emergency` when the rows
/// are written by a writer thread).
pub fn arm(emergency: Option<Emergency>, out: &Path) -> Guard {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(install);
    crate::interrupt::run_started();
    *ARMED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(Armed {
        emergency,
        out: out.to_owned(),
    });
    Guard(())
}

/// Takes the armed run; `wait` false never blocks (hooks and handlers).
fn take_armed(wait: bool) -> Option<Armed> {
    if wait {
        ARMED
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    } else {
        match ARMED.try_lock() {
            Ok(mut armed) => armed.take(),
            Err(std::sync::TryLockError::Poisoned(p)) => p.into_inner().take(),
            Err(std::sync::TryLockError::WouldBlock) => None,
        }
    }
}

fn install() {
    register_exit_hook();
    let handler: extern "C" fn(c_int) = on_abort;
    // SAFETY: installs a handler for SIGABRT only; `on_abort` has the signature
    // sigaction expects for a handler without SA_SIGINFO, and the sigaction value is
    // fully initialised (zeroed, then the fields set).
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = handler as libc::sighandler_t;
        libc::sigemptyset(&mut action.sa_mask);
        libc::sigaction(libc::SIGABRT, &action, std::ptr::null_mut());
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
        on_exit_called(Some(code));
    }
    // SAFETY: glibc's on_exit takes a function of exactly this signature and an
    // argument it passes back unused; `hook` is a plain function living forever.
    unsafe { on_exit(hook, std::ptr::null_mut()) };
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn register_exit_hook() {
    extern "C" fn hook() {
        on_exit_called(None);
    }
    // SAFETY: atexit takes a function without arguments living forever.
    unsafe { libc::atexit(hook) };
}

/// The process is exiting (`exit(code)`) while a run is armed.
fn on_exit_called(code: Option<c_int>) {
    let Some(armed) = take_armed(false) else {
        return; // main returned: a normal end
    };
    if crate::interrupt::forced() {
        // A second Ctrl-C: the exit (130) goes on after the trailer.
        end(armed, crate::interrupt::FORCED_REASON);
        return;
    }
    let called = match code {
        Some(code) => format!("exit({code})"),
        None => "exit()".to_string(),
    };
    end(armed, &blame(&called));
    let _ = std::io::stdout().flush();
    // SAFETY: _exit ends the process at once with code 1, which is the point: the
    // code the FMU chose (0 included) must not be the run's.
    unsafe { libc::_exit(1) }
}

extern "C" fn on_abort(_signal: c_int) {
    // SAFETY: alarm is async-signal-safe: it ends the process (SIGALRM) in 10 s
    // should the best-effort work below deadlock.
    unsafe { libc::alarm(10) };
    if let Some(armed) = take_armed(false) {
        end(armed, &blame("abort()"));
    }
    // SAFETY: signal and raise are async-signal-safe; with the default action
    // restored, the SIGABRT raised here (blocked until this handler returns) ends
    // the process as abort() does, with its exit status.
    unsafe {
        libc::signal(libc::SIGABRT, libc::SIG_DFL);
        libc::raise(libc::SIGABRT);
    }
}

/// Ends the run at once from another thread (the watchdog): the results file
/// gets every accepted row and `reason` as its trailer, the extraction folders
/// are removed, the error line says so; exit code 1.
pub fn stop_now(reason: &str) -> ! {
    match take_armed(true) {
        Some(armed) => end(armed, reason),
        None => crate::say!("error: {reason}"),
    }
    let _ = std::io::stdout().flush();
    // SAFETY: _exit ends the process at once, without the exit hooks (the run
    // is already ended here) and without waiting for the stuck call.
    unsafe { libc::_exit(1) }
}

/// Who did it: the FMI call this thread is inside, if any.
fn blame(what: &str) -> String {
    match tether_fmi::current_call() {
        Some(call) => format!(
            "FMU instance '{}' called {what} inside {} at t={}",
            call.instance, call.function, call.time
        ),
        None => format!("{what} was called during the run, outside any FMI call"),
    }
}

/// Ends the results file with `reason`, removes the extraction folders, says so.
fn end(armed: Armed, reason: &str) {
    let kept = armed
        .emergency
        .is_some_and(|e| e.finish(reason, WRITE_WAIT));
    tether_fmi::remove_extractions_now();
    let out = armed.out.display();
    let line = if kept {
        format!("error: run stopped; results so far kept in {out} (marked incomplete): {reason}")
    } else {
        format!("error: run stopped; the results in {out} may lack the last rows: {reason}")
    };
    let _ = writeln!(std::io::stderr(), "{line}");
}
