//! Ctrl-C (SIGINT), SIGTERM and SIGHUP: the first one asks the run to stop after the
//! current macro step, so the CSV gets its `# incomplete` trailer, every FMU instance is
//! freed and the FMU extraction directories are removed; the process then exits with
//! code 130. A second signal exits at once (no cleanup).
//!
//! Before the run starts (while the system file is read and the FMUs are
//! extracted, loaded and instantiated) there is nothing to keep: the first
//! signal ends the process at once, code 130, after removing the extraction
//! folders, so that an open that never returns (a slow file system, an FMU
//! stuck in `fmi2Instantiate`) cannot make it wait.

use std::sync::atomic::{AtomicBool, Ordering};

use tether_master::{Observer, Sample};

static SIGNALLED: AtomicBool = AtomicBool::new(false);

/// A second signal arrived: the process exits at once.
static FORCED: AtomicBool = AtomicBool::new(false);

/// The run has started ([`run_started`]): a first signal stops it after the
/// current macro step rather than ending the process.
static RUNNING: AtomicBool = AtomicBool::new(false);

/// What the error says when a signal ends the process before the run started.
pub const OPEN_REASON: &str =
    "interrupted by Ctrl-C or a termination signal before the run started (nothing was written)";

/// The trailer after a second signal.
pub const FORCED_REASON: &str =
    "interrupted by a second Ctrl-C or termination signal (exited at once)";

/// What the error and the CSV trailer say stopped the run.
pub const REASON: &str = "Ctrl-C or termination signal";

/// The exit code of an interrupted run (128 + SIGINT).
pub const EXIT_CODE: u8 = 130;

/// Installs the handler (once per process).
pub fn install() -> anyhow::Result<()> {
    ctrlc::set_handler(|| {
        if !RUNNING.load(Ordering::SeqCst) {
            // This runs on ctrlc's own thread: the main thread may be blocked
            // in the open for ever.
            crate::say!("error: {OPEN_REASON}");
            tether_fmi::remove_extractions_now();
            // SAFETY: _exit ends the process at once, without exit hooks or
            // destructors that could wait for the blocked main thread.
            unsafe { libc::_exit(i32::from(EXIT_CODE)) }
        }
        if SIGNALLED.swap(true, Ordering::SeqCst) {
            FORCED.store(true, Ordering::SeqCst);
            // The exit hook (crate::exit_guard) writes the trailer.
            std::process::exit(i32::from(EXIT_CODE));
        }
        say_what_keeps_the_run();
    })
    .map_err(|e| anyhow::anyhow!("cannot install the Ctrl-C handler: {e}"))
}

/// The run stops after the current macro step; a call that is still running a
/// moment later (an FMU stuck in `fmi2DoStep`) is named, so the user knows what
/// the run waits for and that a second Ctrl-C ends it at once.
fn say_what_keeps_the_run() {
    let before = tether_fmi::calls_in_progress();
    if before.is_empty() {
        return;
    }
    std::thread::sleep(std::time::Duration::from_millis(300));
    for c in tether_fmi::calls_in_progress() {
        if before.iter().any(|b| b.key == c.key) {
            crate::say!(
                "waiting for {} of instance '{}' at t={} to return; Ctrl-C again stops at once (the results so far are kept)",
                c.call.function,
                c.call.instance,
                c.call.time
            );
        }
    }
}

/// The run starts: from now on a first signal stops it after the current
/// macro step, with every row kept.
pub fn run_started() {
    RUNNING.store(true, Ordering::SeqCst);
}

/// Whether a second signal is ending the process.
pub fn forced() -> bool {
    FORCED.load(Ordering::SeqCst)
}

/// Whether a signal arrived.
pub fn pending() -> bool {
    SIGNALLED.load(Ordering::SeqCst)
}

/// An observer that records nothing and stops the run once a signal arrived.
pub struct Watch;

impl Observer for Watch {
    fn start(&mut self, _columns: &[String]) -> std::io::Result<()> {
        Ok(())
    }

    fn sample(&mut self, _sample: Sample<'_>) -> std::io::Result<()> {
        Ok(())
    }

    fn finish(&mut self, _failure: Option<&str>) -> std::io::Result<()> {
        Ok(())
    }

    fn interrupt(&mut self) -> Option<String> {
        pending().then(|| REASON.to_string())
    }
}
