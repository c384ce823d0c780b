//! An FMU that ends the process from inside a call: `exit()` (any code, 0
//! included) or `abort()`. The run never returns there, so nothing would mark the
//! results file or report the error; worse, `exit(0)` looked like success.
//!
//! While a run is armed ([`arm`]), the exit hook and SIGABRT handler of
//! [`tether_fmi::exit_hook`] (glibc's `on_exit`, which also gives the exit
//! code; `atexit` elsewhere; acting only in this process, not in a child an
//! FMU forked) end the results
//! file with every accepted row and the trailer `# incomplete: FMU instance 'm'
//! called exit(3) inside fmi2DoStep at t=0.5` (the call this thread was inside,
//! from [`tether_fmi::current_call`]), remove the FMU extraction folders, print
//! the one-line error and end the process: exit code 1 after `exit()`, SIGABRT
//! (134) after `abort()`. The SIGABRT handler does more than a signal handler
//! may (locks, allocation): it is best effort, with `alarm(10)` as a backstop
//! should it deadlock. A second Ctrl-C (which exits at once, code 130) gets the
//! trailer and the folders removed the same way.
//!
//! The hooks act only in the process that installed them: a child that an FMU
//! forks inherits them, and its `exit()` (or `abort()`) must neither report the
//! run as stopped nor remove the parent's extraction folders; in a child they
//! let the exit go on as it would without Tether.
//!
//! A segmentation fault or SIGKILL cannot be handled in-process: the rows up to
//! the last flush are on disk (`tether_master::FLUSH_INTERVAL`) and the next run
//! sweeps the extraction folders (`tether_fmi::sweep_leftovers`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, Once};
use std::time::Duration;

use tether_fmi::exit_hook::Ending;
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
    tether_fmi::exit_hook::install(on_ending);
}

/// The process is ending by `exit()` or `abort()` (tether_fmi::exit_hook).
fn on_ending(ending: Ending) {
    match ending {
        Ending::Exit(_) => on_exit_called(ending),
        Ending::Abort => {
            if let Some(armed) = take_armed(false) {
                end(armed, &blame(ending));
            }
        }
    }
}

/// The process is exiting (`exit(code)`) while a run is armed.
fn on_exit_called(ending: Ending) {
    let Some(armed) = take_armed(false) else {
        return; // main returned: a normal end
    };
    if crate::interrupt::forced() {
        // A second Ctrl-C: the exit (130) goes on after the trailer.
        end(armed, crate::interrupt::FORCED_REASON);
        return;
    }
    end(armed, &blame(ending));
    let _ = std::io::stdout().flush();
    // SAFETY: _exit ends the process at once with code 1, which is the point: the
    // code the FMU chose (0 included) must not be the run's.
    unsafe { libc::_exit(1) }
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
fn blame(ending: Ending) -> String {
    tether_fmi::exit_hook::blame(ending).unwrap_or_else(|| {
        format!(
            "{} was called during the run, outside any FMI call",
            ending.called()
        )
    })
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
