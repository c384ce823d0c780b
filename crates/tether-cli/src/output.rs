//! The results file: checked against the run's inputs, locked against a second
//! run writing it, and created readable and writable (so that the recorder can
//! cut it back to its last whole row after a failed write).

use std::fs::{File, OpenOptions, TryLockError};
use std::path::Path;

use anyhow::{bail, Context, Result};

/// Refuses an `out` that is one of the run's `inputs` (the system file, an FMU):
/// writing the results would destroy it.
pub fn not_an_input<'a>(out: &Path, inputs: impl IntoIterator<Item = &'a Path>) -> Result<()> {
    let Ok(out_id) = identity(out) else {
        return Ok(()); // does not exist yet: cannot be an input
    };
    for input in inputs {
        if identity(input).is_ok_and(|id| id == out_id) {
            bail!(
                "refusing to write the results to {}: it is the run's input {}",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// The file's identity: the same file under any name (links, `./`, symlinks).
#[cfg(unix)]
fn identity(path: &Path) -> std::io::Result<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    let meta = std::fs::metadata(path)?;
    Ok((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn identity(path: &Path) -> std::io::Result<std::path::PathBuf> {
    path.canonicalize()
}

/// Opens the results file `path`, takes its advisory lock (another `tether`
/// writing it is refused, rather than both interleaving in one file) and only
/// then empties it. The lock is held as long as the file is open.
pub fn create(path: &Path) -> Result<File> {
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .with_context(|| format!("cannot create {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => bail!(
            "cannot write {}: another run is writing it (the file is locked)",
            path.display()
        ),
        // Locks unsupported here (some network file systems, devices): go on.
        Err(TryLockError::Error(_)) => {}
    }
    // Only a regular file is emptied (not /dev/null, a pipe, a terminal).
    if file.metadata().is_ok_and(|m| m.is_file()) {
        file.set_len(0)
            .with_context(|| format!("cannot empty {}", path.display()))?;
    }
    Ok(file)
}
