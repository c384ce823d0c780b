//! Unpacking `.fmu` archives safely.
//!
//! Every entry is validated before anything is written: no absolute paths, no path that
//! leaves the target directory, no symbolic links, only stored or deflated data, and a
//! total size budget (checked against the declared sizes first and the bytes actually
//! written second) so that a decompression bomb cannot fill the disk.

use std::fs;
use std::io::{self, Read, Write};
use std::path::{Component, Path, PathBuf};

use zip::CompressionMethod;

use crate::error::{Error, Result};

/// `S_IFMT` / `S_IFLNK` from `<sys/stat.h>`, as stored in the upper half of a zip
/// entry's external attributes.
const S_IFMT: u32 = 0o170_000;
const S_IFLNK: u32 = 0o120_000;

/// Limits applied while extracting an archive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExtractLimits {
    /// Maximum total number of uncompressed bytes written (default 1 GiB).
    pub max_total_bytes: u64,
    /// Maximum number of entries in the archive (default 100 000).
    pub max_entries: usize,
}

impl Default for ExtractLimits {
    fn default() -> Self {
        ExtractLimits {
            max_total_bytes: 1 << 30,
            max_entries: 100_000,
        }
    }
}

/// The directory an FMU lives in: either a temporary extraction (removed when the last
/// holder drops it) or a directory the user unpacked and owns.
#[derive(Debug)]
pub struct FmuDir {
    root: PathBuf,
    _temp: Option<tempfile::TempDir>,
    /// The extraction folder itself, opened and locked (`flock`) for as long as
    /// it is in use, so that a later run can tell a leftover from a folder in use.
    _lock: Option<fs::File>,
}

/// Prefix of the extraction folders in `$TMPDIR`.
const PREFIX: &str = "tether-fmu-";

/// Written into an extraction folder once it is locked: a folder with the marker
/// and a free lock belongs to a process that is gone. (Its process may also have
/// died between creating and marking it: such an empty folder is left.)
const MARKER: &str = ".tether-lock";

/// The extraction folders of this process, for [`remove_extractions_now`].
static LIVE: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

impl Drop for FmuDir {
    fn drop(&mut self) {
        if self._temp.is_some() {
            let mut live = LIVE
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            live.retain(|p| *p != self.root);
        }
    }
}

/// Removes every extraction folder of this process now, for a program that is
/// about to end without dropping its FMUs (an FMU called `exit()`, or `abort()`):
/// the code of a loaded library stays mapped, so this is safe for the process
/// itself, but nothing may use the FMUs afterwards. Never blocks: if the registry
/// is busy, nothing is removed (a later run sweeps the folders,
/// [`sweep_leftovers`]). Returns how many folders were removed.
pub fn remove_extractions_now() -> usize {
    let Ok(mut live) = LIVE.try_lock() else {
        return 0;
    };
    live.drain(..)
        .filter(|dir| fs::remove_dir_all(dir).is_ok())
        .count()
}

/// Removes the extraction folders that killed runs left in the temporary
/// directory: `tether-fmu-*` folders whose lock no process holds. Runs once per
/// process, before its first extraction; returns how many were removed.
pub fn sweep_leftovers() -> usize {
    static SWEPT: std::sync::Once = std::sync::Once::new();
    let mut removed = 0;
    SWEPT.call_once(|| removed = sweep(&std::env::temp_dir()));
    removed
}

fn sweep(temp: &Path) -> usize {
    let Ok(entries) = fs::read_dir(temp) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        if !name.to_string_lossy().starts_with(PREFIX) {
            continue;
        }
        let dir = entry.path();
        // Only real folders, not symbolic links to elsewhere.
        if !entry.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        let Ok(folder) = fs::File::open(&dir) else {
            continue;
        };
        if folder.try_lock().is_err() {
            continue; // in use (or locks unsupported here: leave it)
        }
        // Without the marker the folder is being set up by a running process (it
        // locks before it marks), or it is from a version without locks: left alone.
        if dir.join(MARKER).exists() && fs::remove_dir_all(&dir).is_ok() {
            log::info!(target: "tether_fmi::archive", "removed the leftover {}", dir.display());
            removed += 1;
        }
    }
    removed
}

/// Creates a private (0700) extraction folder, locks it and marks it.
fn locked_temp_dir() -> io::Result<(tempfile::TempDir, fs::File)> {
    sweep_leftovers();
    let mut builder = tempfile::Builder::new();
    builder.prefix(PREFIX);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(fs::Permissions::from_mode(0o700));
    }
    let temp = builder.tempdir()?;
    let lock = fs::File::open(temp.path())?;
    lock.lock()?;
    fs::File::create(temp.path().join(MARKER))?;
    Ok((temp, lock))
}

impl FmuDir {
    /// Uses an already-unpacked FMU directory in place.
    pub(crate) fn existing(dir: &Path) -> Result<FmuDir> {
        let root = dir.canonicalize().map_err(|source| Error::Io {
            path: dir.to_owned(),
            source,
        })?;
        Ok(FmuDir {
            root,
            _temp: None,
            _lock: None,
        })
    }

    /// The FMU's root directory (the one holding `modelDescription.xml`).
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The FMU's `resources/` directory (it need not exist).
    pub fn resources(&self) -> PathBuf {
        self.root.join("resources")
    }
}

/// Extracts `archive` into a new temporary directory.
pub(crate) fn extract(archive: &Path, limits: &ExtractLimits) -> Result<FmuDir> {
    let io_err = |path: &Path| {
        let path = path.to_owned();
        move |source| Error::Io { path, source }
    };
    let file = fs::File::open(archive).map_err(io_err(archive))?;
    let mut zip =
        zip::ZipArchive::new(io::BufReader::new(file)).map_err(|e| Error::NotAnArchive {
            path: archive.to_owned(),
            reason: crate::error::one_line(&e.to_string()),
        })?;
    if zip.len() > limits.max_entries {
        return Err(Error::ArchiveTooLarge {
            archive: archive.to_owned(),
            entry: String::new(),
            reason: format!("{} entries, limit {}", zip.len(), limits.max_entries),
        });
    }

    // Pass 1: validate every entry and the declared sizes before writing anything.
    let mut plan = Vec::with_capacity(zip.len());
    let mut declared_total: u64 = 0;
    for index in 0..zip.len() {
        let entry = zip.by_index_raw(index).map_err(|e| Error::NotAnArchive {
            path: archive.to_owned(),
            reason: crate::error::one_line(&e.to_string()),
        })?;
        let name = String::from_utf8_lossy(entry.name_raw()).into_owned();
        let relative = checked_relative_path(archive, &name)?;
        if (entry.external_attributes() >> 16) & S_IFMT == S_IFLNK || entry.is_symlink() {
            return Err(Error::SymlinkEntry {
                archive: archive.to_owned(),
                entry: name,
            });
        }
        let unsupported = |reason: &str| Error::UnsupportedEntry {
            archive: archive.to_owned(),
            entry: name.clone(),
            reason: reason.to_owned(),
        };
        if entry.encrypted() {
            return Err(unsupported("encrypted entries are not supported"));
        }
        if !matches!(
            entry.compression(),
            CompressionMethod::Stored | CompressionMethod::Deflated
        ) {
            return Err(unsupported(&format!(
                "compression method {:?} (only stored and deflate are accepted)",
                entry.compression()
            )));
        }
        declared_total = declared_total.saturating_add(entry.size());
        if declared_total > limits.max_total_bytes {
            return Err(Error::ArchiveTooLarge {
                archive: archive.to_owned(),
                entry: name,
                reason: format!(
                    "declared uncompressed size reaches {declared_total} bytes, limit {}",
                    limits.max_total_bytes
                ),
            });
        }
        let is_dir = entry.is_dir();
        plan.push((index, name, relative, is_dir, entry.size()));
    }

    // Pass 2: extract, counting the bytes actually produced.
    let (temp, lock) = locked_temp_dir().map_err(io_err(&std::env::temp_dir()))?;
    let root = temp.path().canonicalize().map_err(io_err(temp.path()))?;
    LIVE.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .push(root.clone());
    let dir = FmuDir {
        root: root.clone(),
        _temp: Some(temp),
        _lock: Some(lock),
    };
    let mut written_total: u64 = 0;
    for (index, name, relative, is_dir, declared) in plan {
        let target = root.join(&relative);
        if is_dir {
            fs::create_dir_all(&target).map_err(io_err(&target))?;
            continue;
        }
        if let Some(parent) = target.parent() {
            fs::create_dir_all(parent).map_err(io_err(parent))?;
        }
        let mut out = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&target)
            .map_err(|source| {
                if source.kind() == io::ErrorKind::AlreadyExists {
                    Error::UnsupportedEntry {
                        archive: archive.to_owned(),
                        entry: name.clone(),
                        reason: "duplicate entry".into(),
                    }
                } else {
                    Error::Io {
                        path: target.clone(),
                        source,
                    }
                }
            })?;
        let entry = zip.by_index(index).map_err(|e| Error::NotAnArchive {
            path: archive.to_owned(),
            reason: crate::error::one_line(&e.to_string()),
        })?;
        let budget = limits.max_total_bytes - written_total;
        let cap = budget.min(declared);
        // Read at most one byte more than allowed so an overrun is detected, not truncated.
        let copied = copy_bounded(entry, &mut out, cap.saturating_add(1)).map_err(|source| {
            Error::UnsupportedEntry {
                archive: archive.to_owned(),
                entry: name.clone(),
                reason: format!(
                    "corrupt data: {}",
                    crate::error::one_line(&source.to_string())
                ),
            }
        })?;
        if copied > cap {
            return Err(Error::ArchiveTooLarge {
                archive: archive.to_owned(),
                entry: name,
                reason: if copied > declared {
                    format!("inflates to more than its declared {declared} bytes")
                } else {
                    format!(
                        "total exceeds the limit of {} bytes",
                        limits.max_total_bytes
                    )
                },
            });
        }
        written_total += copied;
        out.flush().map_err(io_err(&target))?;
    }
    Ok(dir)
}

/// Copies at most `max` bytes, returning how many were copied.
fn copy_bounded(reader: impl Read, writer: &mut impl Write, max: u64) -> io::Result<u64> {
    io::copy(&mut reader.take(max), writer)
}

/// Turns an entry name into a normalised relative path, refusing absolute names and
/// names that resolve outside the extraction directory.
fn checked_relative_path(archive: &Path, name: &str) -> Result<PathBuf> {
    let err_abs = || Error::AbsoluteEntry {
        archive: archive.to_owned(),
        entry: name.to_owned(),
    };
    // A NUL or a newline in a name would truncate the path or split error messages
    // (found by fuzzing); the name is shown escaped.
    if name.chars().any(char::is_control) {
        return Err(Error::UnsupportedEntry {
            archive: archive.to_owned(),
            entry: name.escape_default().to_string(),
            reason: "control character in the name".into(),
        });
    }
    let unified = name.replace('\\', "/");
    let bytes = unified.as_bytes();
    if unified.starts_with('/') || (bytes.len() >= 2 && bytes[1] == b':') {
        return Err(err_abs());
    }
    let mut out = PathBuf::new();
    for component in Path::new(&unified).components() {
        match component {
            Component::Normal(part) => out.push(part),
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    return Err(Error::EntryEscapes {
                        archive: archive.to_owned(),
                        entry: name.to_owned(),
                    });
                }
            }
            Component::RootDir | Component::Prefix(_) => return Err(err_abs()),
        }
    }
    if out.as_os_str().is_empty() {
        return Err(Error::UnsupportedEntry {
            archive: archive.to_owned(),
            entry: name.to_owned(),
            reason: "empty name".into(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(name: &str) -> Result<PathBuf> {
        checked_relative_path(Path::new("a.fmu"), name)
    }

    #[test]
    fn relative_names_are_normalised() {
        assert_eq!(rel("a/./b/../c").unwrap(), PathBuf::from("a/c"));
        assert_eq!(rel("dir/").unwrap(), PathBuf::from("dir"));
    }

    #[test]
    fn escaping_and_absolute_names_are_refused() {
        assert!(matches!(rel("../evil"), Err(Error::EntryEscapes { .. })));
        assert!(matches!(
            rel("a/../../evil"),
            Err(Error::EntryEscapes { .. })
        ));
        assert!(matches!(
            rel("/etc/passwd"),
            Err(Error::AbsoluteEntry { .. })
        ));
        assert!(matches!(rel("C:/x"), Err(Error::AbsoluteEntry { .. })));
        assert!(matches!(rel("\\x"), Err(Error::AbsoluteEntry { .. })));
        assert!(matches!(rel("a\0b"), Err(Error::UnsupportedEntry { .. })));
        let err = rel("binaries/\nlinux64/x.so").unwrap_err();
        assert!(matches!(err, Error::UnsupportedEntry { .. }), "{err:?}");
        assert!(!err.to_string().contains('\n'), "{err}");
        assert!(
            err.to_string().contains("binaries/\\nlinux64/x.so"),
            "{err}"
        );
    }
}
