//! `faults`: the oscillator FMU (same variables, same results in mode 0) that
//! misbehaves inside `fmi2DoStep` on demand, so that Tether's handling of FMUs
//! that crash, exit, hang or flood the log can be tested on a real FMU in a real
//! process (docs/reliability.md).
//!
//! The integer parameter `mode` selects the fault, struck in the first
//! `fmi2DoStep` whose communication point is at least `at` (default 0.5 s) and,
//! for the lasting faults, in every one after it:
//!
//! | mode | fault |
//! |---|---|
//! | 0 | none: the oscillator |
//! | 1 | segmentation fault (a write to an unmapped address) |
//! | 2 | `abort()` |
//! | 3 | `exit(0)` |
//! | 4 | `exit(3)` |
//! | 5 | an endless loop (busy) |
//! | 6 | a log flood: `flood` warnings per `fmi2DoStep` (default 2000) |
//! | 7 | slow calls: each `fmi2DoStep` sleeps `pause` seconds (default 1) |
//! | 8 | a helper process (`system("sleep 15 &")`), then a segmentation fault |
//! | 9 | `fork()`, and the child calls `exit(0)` (the parent waits for it and goes on; only in the step from `at`) |
//! | 10 | `fork()`, the child sleeps 15 s (holding every descriptor), the parent segfaults |
//! | 11 | a helper process (`system("sleep 15 &")`), and the run goes on (only in the step from `at`) |
//! | 12 | `fmi2SetFMUstate` restores the time but not the states (and returns fmi2OK) once the instance is at `at` or later |
//! | 13 | once the instance is at `at` or later, `fmi2SetFMUstate` restores the states (the outputs read back are the saved ones) but the next `fmi2DoStep` starts from them plus a pseudo-random offset in [-`noise`, `noise`] (default 0.01): a restore that is not deterministic |
//! | 14 | once the instance is at `at` or later, every read of the outputs adds `noise` to the position: outputs that change without a step |
//! | 15 | the library pins itself in the process (`RTLD_NODELETE`, as the loader pins a C++ library with unique symbols) and its destructor calls `abort()` at process exit, as pythonfmu3's runtime may (after a finished run; only from the step at `at`) |
//! | 16 | a barrier: the step from `at` marks its arrival with a file in the folder `$TETHER_FAULTS_BARRIER` and waits until `peers` (default 2) files are there; after 5 s it ends its process with exit code 16. Instances that meet there must be stepped at once (each in a host process of its own), not one after another |
//!
//! `delay` (seconds, default 0) makes every `fmi2DoStep` sleep, in every mode, to
//! slow a run down to wall-clock scales.
//!
//! The warnings of the log flood go through the environment's logger
//! ([`tether_fmu_kit::environment_logger`]) with a printf format of their own, as a
//! C FMU logs.

use std::ffi::{c_int, c_uint, c_void};
use std::sync::atomic::{AtomicBool, Ordering};

use tether_fmu_kit::export_fmu;

mod fault;
mod model;

pub use fault::Mode;
pub use model::Faults;

/// One warning through the environment's logger, formatted by the environment
/// (`%u`, `%g`), as a C FMU logs.
fn log_warning(n: u32, t: f64) {
    let Some(logger) = tether_fmu_kit::environment_logger() else {
        return;
    };
    // SAFETY: the kit hands out the logger, its environment and the instance name
    // that fmi2Instantiate received, during the fmi2DoStep running this (the FMI
    // contract keeps them valid until fmi2FreeInstance); the format's two
    // conversions match the unsigned int and the double passed.
    unsafe {
        (logger.logger)(
            logger.component_environment,
            logger.instance_name,
            1 as c_int,
            c"logStatusWarning".as_ptr(),
            c"flood message %u at t = %g".as_ptr(),
            n as c_uint,
            t,
        );
    }
}

/// Starts a helper in the background, as an FMU that runs a tool or a licence
/// daemon does: `system("sleep 15 &")` (the shell returns at once).
fn start_helper() {
    // SAFETY: system with a NUL-terminated command; it returns once the shell
    // has started `sleep` in the background and ended.
    unsafe { libc::system(c"sleep 15 &".as_ptr()) };
}

/// `fork()`; the child calls `exit(0)` at once (running the process's exit
/// hooks, as a child of an FMU that does not `exec` does), the parent waits for
/// it.
fn fork_and_exit_in_child() {
    // SAFETY: fork in a multithreaded process: the child only calls exit, as the
    // FMU this mode stands for does; the parent reaps its own child.
    unsafe {
        match libc::fork() {
            0 => libc::exit(0),
            -1 => {}
            child => {
                libc::waitpid(child, std::ptr::null_mut(), 0);
            }
        }
    }
}

/// `fork()`; the child sleeps 15 s, holding a copy of every descriptor of the
/// process (also those that are close-on-exec: it does not `exec`), then ends
/// without running the exit hooks.
fn fork_lingering_child() {
    // SAFETY: fork in a multithreaded process: the child only calls the
    // async-signal-safe sleep and _exit.
    unsafe {
        if libc::fork() == 0 {
            libc::sleep(15);
            libc::_exit(0);
        }
    }
}

/// Mode 15 has struck: the library's destructor aborts.
static ABORT_AT_EXIT: AtomicBool = AtomicBool::new(false);

/// Mode 15: keeps this library loaded to the end of the process, as the loader
/// keeps a C++ library whose unique symbols libstdc++ binds (pythonfmu3's
/// runtime is one), so that its destructor runs at process exit, and makes that
/// destructor abort, as a runtime that resets a static the exit handlers have
/// destroyed may.
fn abort_at_exit() {
    ABORT_AT_EXIT.store(true, Ordering::SeqCst);
    // SAFETY: dladdr with the address of a function of this library fills
    // `info` with the path the library was loaded from (valid while it is
    // loaded, as it is during this call); dlopen of that path with RTLD_NOLOAD
    // only takes another reference to the loaded library, and RTLD_NODELETE
    // keeps it loaded when every reference is dropped.
    unsafe {
        let mut info: libc::Dl_info = std::mem::zeroed();
        let here = abort_at_exit as fn() as *const c_void;
        if libc::dladdr(here, &mut info) != 0 && !info.dli_fname.is_null() {
            libc::dlopen(
                info.dli_fname,
                libc::RTLD_NOW | libc::RTLD_NOLOAD | libc::RTLD_NODELETE,
            );
        }
    }
}

/// The library's destructor (run by `dlclose`, or at process exit for a library
/// still loaded): aborts once mode 15 has struck.
extern "C" fn at_unload() {
    if ABORT_AT_EXIT.load(Ordering::SeqCst) {
        std::process::abort();
    }
}

#[used]
#[link_section = ".fini_array"]
static AT_UNLOAD: extern "C" fn() = at_unload;

/// A segmentation fault, as a buggy FMU has one: a write to an unmapped address.
fn crash() -> ! {
    let address = std::ptr::without_provenance_mut::<u64>(64);
    // SAFETY: none: this write is the fault the `segfault` mode asks for. The page
    // at address 64 is never mapped on Linux (mmap_min_addr), so the process gets
    // SIGSEGV; the volatile write keeps the compiler from reasoning about it.
    unsafe { address.write_volatile(0xdead) };
    std::process::abort()
}

export_fmu!(Faults);

/// Mode 16: marks this instance's arrival in the step from `at` with a file
/// of its own in the folder `$TETHER_FAULTS_BARRIER` and waits until `peers`
/// files are there (instances of any process). A master that awaits one
/// instance's step before it asks for the other's never lets them meet: after
/// 5 s the process ends with exit code 16.
fn barrier(peers: u32) {
    static ARRIVALS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let Some(dir) = std::env::var_os("TETHER_FAULTS_BARRIER") else {
        std::process::exit(16);
    };
    let dir = std::path::PathBuf::from(dir);
    let n = ARRIVALS.fetch_add(1, Ordering::SeqCst);
    let mine = dir.join(format!("{}-{n}", std::process::id()));
    if std::fs::write(mine, b"").is_err() {
        std::process::exit(16);
    }
    let start = std::time::Instant::now();
    while start.elapsed() < std::time::Duration::from_secs(5) {
        let arrived = std::fs::read_dir(&dir).map_or(0, |d| d.count());
        if arrived >= peers as usize {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    std::process::exit(16);
}
