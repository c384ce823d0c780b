//! Isolated instances (`isolation = "process"`, docs/reliability.md): the
//! host program a Python process starts, and serving instances from Python.

use super::*;

/// Start the host processes of isolated instances as `program args…`
/// (the package's import sets `python -m tether._fmi_host`; the
/// `TETHER_FMI_HOST` environment variable still comes first).
#[pyfunction]
pub(crate) fn use_fmi_host(program: PathBuf, args: Vec<String>) {
    tether_fmi::remote::set_host(tether_fmi::remote::HostCommand {
        program,
        args: args.into_iter().map(Into::into).collect(),
    });
}

/// Serve one isolated FMU instance on standard input and output until the
/// master closes them (the body of `python -m tether._fmi_host`).
#[pyfunction]
pub(crate) fn serve_fmi_host(py: Python<'_>) -> PyResult<()> {
    // A host's exit, whatever its code, is reported by the master it serves.
    SERVING_HOST.store(true, std::sync::atomic::Ordering::SeqCst);
    py.detach(tether_fmi_host::serve_standard_streams)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("tether-fmi-host: {e}")))
}

/// Serve FMU instances to masters on `address` as `tether host --listen`
/// does (docs/remote.md), until the process is killed: the body of
/// `python -m tether._fmi_host --listen` that `tether.run(system,
/// client=…)` starts on a Dask worker. With `parent`, the process ends when
/// the process of that id (its parent) does.
#[pyfunction]
#[pyo3(signature = (address, token_file, max_fmu_bytes, max_frame_bytes, parent=None))]
pub(crate) fn listen_host(
    py: Python<'_>,
    address: String,
    token_file: PathBuf,
    max_fmu_bytes: u64,
    max_frame_bytes: u64,
    parent: Option<i32>,
) -> PyResult<()> {
    if let Some(parent) = parent {
        // SAFETY: prctl and getppid take and return plain integers; after
        // prctl the kernel kills this process when its parent ends, and a
        // parent that ended before it shows as another parent id.
        let orphaned = unsafe {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            libc::getppid() != parent
        };
        if orphaned {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "tether host: the process that started it has ended",
            ));
        }
    }
    let options = tether_fmi_host::listen::ListenOptions {
        address,
        token_file,
        max_fmu_bytes,
        max_frame_bytes,
    };
    py.detach(|| tether_fmi_host::listen::listen(&options))
        .map_err(pyo3::exceptions::PyRuntimeError::new_err)
}

/// This process is the host of an isolated instance (`serve_fmi_host`): its
/// FMU's exit is left to the master, which reports it with the exit code.
pub(crate) static SERVING_HOST: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// An in-process FMU ends the process from inside a call (`exit()` or
/// `abort()`, tether_fmi::exit_hook): Python cannot be told, and `exit(0)`
/// would end it with status 0, silently. One line names the instance, the
/// call and the time, the extraction folders are removed, and the process
/// ends with status 1 after `exit()` (SIGABRT after `abort()`). An exit
/// outside any FMI call (the interpreter's own) is left alone.
pub(crate) fn on_ending(ending: tether_fmi::exit_hook::Ending) {
    use std::io::Write as _;
    if SERVING_HOST.load(std::sync::atomic::Ordering::SeqCst) {
        return;
    }
    let Some(blame) = tether_fmi::exit_hook::blame(ending) else {
        return;
    };
    let _ = writeln!(
        std::io::stderr(),
        "error: the Python process ends: {blame} (an in-process FMU shares Python's process; with isolation = \"process\" this is an exception)"
    );
    tether_fmi::remove_extractions_now();
    if let tether_fmi::exit_hook::Ending::Exit(_) = ending {
        // SAFETY: _exit ends the process at once with status 1: the code the
        // FMU chose (0 included) must not be the process's.
        unsafe { libc::_exit(1) }
    }
}

/// The exit hook acts in this process too: called in the child after
/// Python's `os.fork()` (a `multiprocessing` worker is a Python program of
/// its own), never after an FMU's own `fork()`.
#[pyfunction]
pub(crate) fn adopt_exit_hook() {
    tether_fmi::exit_hook::adopt();
}
