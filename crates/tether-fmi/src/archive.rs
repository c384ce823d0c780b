//! Unpacking `.fmu` archives (and tether-ssp's `.ssp` archives) safely.
//!
//! Every entry is validated before anything is written: no absolute paths, no path that
//! leaves the target directory, no symbolic links, no two entries for one path, only
//! stored or deflated data, and a size budget ([`ExtractLimits`]: total, per entry,
//! compression ratio, checked against the declared sizes first and the bytes actually
//! written second) so that a decompression bomb cannot fill the disk.

use std::collections::HashMap;
use std::fs;
use std::io::{self, BufReader, Read, Seek, SeekFrom, Write};
use std::path::{Component, Path, PathBuf};

use zip::CompressionMethod;

pub use crate::error::ArchiveKind;
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
    /// Maximum uncompressed size of one entry (default 512 MiB).
    pub max_entry_bytes: u64,
    /// Maximum compression ratio (uncompressed / compressed size) of an entry larger
    /// than [`RATIO_FREE_BYTES`] (default 100).
    pub max_ratio: u64,
}

/// Entries up to this uncompressed size (1 MiB) may have any compression ratio.
pub const RATIO_FREE_BYTES: u64 = 1 << 20;

impl Default for ExtractLimits {
    fn default() -> Self {
        ExtractLimits {
            max_total_bytes: 1 << 30,
            max_entries: 100_000,
            max_entry_bytes: 512 << 20,
            max_ratio: 100,
        }
    }
}

impl ArchiveKind {
    const ALL: [ArchiveKind; 2] = [ArchiveKind::Fmu, ArchiveKind::Ssp];

    /// Prefix of the extraction folders in `$TMPDIR`.
    fn prefix(self) -> &'static str {
        match self {
            ArchiveKind::Fmu => "tether-fmu-",
            ArchiveKind::Ssp => "tether-ssp-",
        }
    }
}

/// The directory an FMU (or an SSP system) lives in: either a temporary extraction
/// (removed when the last holder drops it) or a directory the user unpacked and owns.
#[derive(Debug)]
pub struct FmuDir {
    root: PathBuf,
    _temp: Option<tempfile::TempDir>,
    /// The extraction folder itself, opened and locked (`flock`) for as long as
    /// it is in use, so that a later run can tell a leftover from a folder in use.
    _lock: Option<fs::File>,
}

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
/// directory: `tether-fmu-*` and `tether-ssp-*` folders whose lock no process
/// holds. Runs once per process, before its first extraction; returns how many
/// were removed.
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
        let name = name.to_string_lossy();
        if !ArchiveKind::ALL
            .iter()
            .any(|k| name.starts_with(k.prefix()))
        {
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
fn locked_temp_dir(kind: ArchiveKind) -> io::Result<(tempfile::TempDir, fs::File)> {
    sweep_leftovers();
    let mut builder = tempfile::Builder::new();
    builder.prefix(kind.prefix());
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

/// Extracts the FMU `archive` into a new temporary directory.
pub(crate) fn extract(archive: &Path, limits: &ExtractLimits) -> Result<FmuDir> {
    extract_archive(archive, ArchiveKind::Fmu, limits)
}

/// One entry to write, checked.
struct Planned {
    index: usize,
    name: String,
    relative: PathBuf,
    is_dir: bool,
    declared: u64,
}

/// The entry's name for an error when the zip reader cannot give its data: as
/// listed in the central directory, else its position.
fn listed_name<R: Read + Seek>(zip: &zip::ZipArchive<R>, index: usize) -> String {
    match zip.name_for_index(index) {
        Some(Ok(name)) => name.into_owned(),
        _ => format!("#{} in the central directory", index + 1),
    }
}

/// Extracts `archive` into a new private temporary directory (`$TMPDIR/tether-fmu-*`
/// or `$TMPDIR/tether-ssp-*`, mode 0700, locked while in use and swept by a later
/// process when its owner was killed; see [`sweep_leftovers`]), removed when the
/// returned [`FmuDir`] is dropped.
///
/// Every entry is checked before anything is written: its name (no absolute path, no
/// `..` leaving the folder, no control character, no second entry for the same path),
/// its type (no symbolic link, no encryption, stored or deflate only) and its declared
/// size against `limits`; the bytes inflated are counted as they are written. Every
/// error names the archive and the entry.
pub fn extract_archive(
    archive: &Path,
    kind: ArchiveKind,
    limits: &ExtractLimits,
) -> Result<FmuDir> {
    let io_err = |path: &Path| {
        let path = path.to_owned();
        move |source| Error::Io { path, source }
    };
    let file = fs::File::open(archive).map_err(io_err(archive))?;
    let mut zip = zip::ZipArchive::new(io::BufReader::new(file)).map_err(|e| {
        let reason = crate::error::one_line(&e.to_string());
        // A zip whose directory lists an entry the reader cannot read: name it.
        match broken_header(archive) {
            Some(header) => Error::UnsupportedEntry {
                kind,
                archive: archive.to_owned(),
                entry: header.shown(),
                reason: format!("unreadable central directory header: {reason}"),
            },
            None => Error::NotAnArchive {
                kind,
                path: archive.to_owned(),
                reason,
            },
        }
    })?;
    let too_large = |entry: &str, reason: String| Error::ArchiveTooLarge {
        kind,
        archive: archive.to_owned(),
        entry: entry.to_owned(),
        reason,
    };
    let unsupported = |entry: &str, reason: &str| Error::UnsupportedEntry {
        kind,
        archive: archive.to_owned(),
        entry: entry.to_owned(),
        reason: reason.to_owned(),
    };
    if zip.len() > limits.max_entries {
        // Named after the first entry past the limit.
        return Err(too_large(
            &listed_name(&zip, limits.max_entries),
            format!("{} entries, limit {}", zip.len(), limits.max_entries),
        ));
    }
    if zip.has_duplicate_names() {
        // The zip reader keeps one of the entries with the same name: that is
        // safe only when every copy is the same (as in the Reference FMU
        // Roberts, which lists its `extra/` folder twice).
        if let Some(entry) = differing_duplicate(archive) {
            return Err(unsupported(
                &entry,
                "duplicate entry (the archive has two entries of this name)",
            ));
        }
    }

    // Pass 1: validate every entry and the declared sizes before writing anything.
    let mut plan = Vec::with_capacity(zip.len());
    // Each path the archive extracts to: the entry's name and whether it is a folder.
    let mut paths: HashMap<PathBuf, (String, bool)> = HashMap::with_capacity(zip.len());
    let mut declared_total: u64 = 0;
    for index in 0..zip.len() {
        let listed = listed_name(&zip, index);
        let entry = zip.by_index_raw(index).map_err(|e| {
            unsupported(
                &listed,
                &format!("unreadable: {}", crate::error::one_line(&e.to_string())),
            )
        })?;
        let name = String::from_utf8_lossy(entry.name_raw()).into_owned();
        let relative = checked_relative_path(archive, kind, &name)?;
        if (entry.external_attributes() >> 16) & S_IFMT == S_IFLNK || entry.is_symlink() {
            return Err(Error::SymlinkEntry {
                kind,
                archive: archive.to_owned(),
                entry: name,
            });
        }
        if entry.encrypted() {
            return Err(unsupported(&name, "encrypted entries are not supported"));
        }
        if !matches!(
            entry.compression(),
            CompressionMethod::Stored | CompressionMethod::Deflated
        ) {
            return Err(unsupported(
                &name,
                &format!(
                    "compression method {:?} (only stored and deflate are accepted)",
                    entry.compression()
                ),
            ));
        }
        let size = entry.size();
        declared_total = declared_total.saturating_add(size);
        if declared_total > limits.max_total_bytes {
            return Err(too_large(
                &name,
                format!(
                    "declared uncompressed size reaches {declared_total} bytes, limit {}",
                    limits.max_total_bytes
                ),
            ));
        }
        if size > limits.max_entry_bytes {
            return Err(too_large(
                &name,
                format!(
                    "declares {size} bytes, limit {} per entry",
                    limits.max_entry_bytes
                ),
            ));
        }
        let compressed = entry.compressed_size();
        if size > RATIO_FREE_BYTES && size > compressed.saturating_mul(limits.max_ratio) {
            return Err(too_large(
                &name,
                format!(
                    "declares {size} bytes from {compressed} compressed, a compression ratio \
                     over the limit of {} (for entries over {RATIO_FREE_BYTES} bytes)",
                    limits.max_ratio
                ),
            ));
        }
        let is_dir = entry.is_dir();
        match paths.get(&relative) {
            Some((first, first_is_dir)) if !(is_dir && *first_is_dir) => {
                return Err(unsupported(
                    &name,
                    &format!("duplicate entry (the same path as entry '{first}')"),
                ));
            }
            Some(_) => {}
            None => {
                paths.insert(relative.clone(), (name.clone(), is_dir));
            }
        }
        plan.push(Planned {
            index,
            name,
            relative,
            is_dir,
            declared: size,
        });
    }
    // A path inside a file (`a` a file, `a/b` another entry) cannot be written.
    for planned in &plan {
        for parent in planned.relative.ancestors().skip(1) {
            if let Some((file, false)) = paths.get(parent) {
                return Err(unsupported(
                    &planned.name,
                    &format!("its folder is entry '{file}', a file"),
                ));
            }
        }
    }

    // Pass 2: extract, counting the bytes actually produced.
    let (temp, lock) = locked_temp_dir(kind).map_err(io_err(&std::env::temp_dir()))?;
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
    for Planned {
        index,
        name,
        relative,
        is_dir,
        declared,
    } in plan
    {
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
                    unsupported(&name, "duplicate entry")
                } else {
                    Error::Io {
                        path: target.clone(),
                        source,
                    }
                }
            })?;
        let entry = zip.by_index(index).map_err(|e| {
            unsupported(
                &name,
                &format!("unreadable: {}", crate::error::one_line(&e.to_string())),
            )
        })?;
        let budget = limits.max_total_bytes - written_total;
        let cap = budget.min(declared);
        // Read at most one byte more than allowed so an overrun is detected, not truncated.
        let copied = copy_bounded(entry, &mut out, cap.saturating_add(1)).map_err(|source| {
            unsupported(
                &name,
                &format!(
                    "corrupt data: {}",
                    crate::error::one_line(&source.to_string())
                ),
            )
        })?;
        if copied > cap {
            return Err(too_large(
                &name,
                if copied > declared {
                    format!("inflates to more than its declared {declared} bytes")
                } else {
                    format!(
                        "total exceeds the limit of {} bytes",
                        limits.max_total_bytes
                    )
                },
            ));
        }
        written_total += copied;
        out.flush().map_err(io_err(&target))?;
    }
    Ok(dir)
}

/// A central directory header: its position (from 1) and, if its bytes allow,
/// its name.
struct Header {
    position: usize,
    name: Option<Vec<u8>>,
}

impl Header {
    /// The entry's name for an error: escaped, or its position.
    fn shown(&self) -> String {
        match &self.name {
            Some(name) => String::from_utf8_lossy(name).escape_default().to_string(),
            None => format!("#{} in the central directory", self.position),
        }
    }
}

/// What a central directory header says of its entry, besides the name:
/// compression method, CRC-32, compressed and uncompressed size.
type Listing = (u16, u32, u32, u32);

/// Walks the central directory of `archive`, bytes `start..end`, handing each
/// header's name and [`Listing`] to `visit` until it returns `Some`. `Err` is the first header
/// whose fields do not fit the directory (or its extra field's blocks do not fit
/// the extra field); `Ok(None)` if every header was visited. Linear in the
/// directory.
fn walk_central_directory<T>(
    archive: &Path,
    start: u64,
    end: u64,
    mut visit: impl FnMut(&[u8], Listing) -> Option<T>,
) -> io::Result<Result<Option<T>, Header>> {
    let mut file = BufReader::new(fs::File::open(archive)?);
    file.seek(SeekFrom::Start(start))?;
    let mut at = start;
    let mut header = [0u8; 46];
    for position in 1.. {
        if at >= end {
            return Ok(Ok(None));
        }
        let broken = |name| Err(Header { position, name });
        if at + 46 > end || file.read_exact(&mut header).is_err() {
            return Ok(broken(None));
        }
        let field = |at: usize| u64::from(u16::from_le_bytes([header[at], header[at + 1]]));
        let (name_len, extra_len, comment_len) = (field(28), field(30), field(32));
        let mut name = vec![0; name_len as usize];
        let name_fits = at + 46 + name_len <= end && file.read_exact(&mut name).is_ok();
        let name = name_fits.then_some(name);
        if header[..4] != [0x50, 0x4b, 0x01, 0x02] || name.is_none() {
            return Ok(broken(name));
        }
        at += 46 + name_len + extra_len + comment_len;
        let mut extra = vec![0; extra_len as usize];
        if at > end || file.read_exact(&mut extra).is_err() {
            return Ok(broken(name));
        }
        // The extra field is blocks of (id, size, data).
        let mut rest = extra.as_slice();
        while rest.len() >= 4 {
            let size = usize::from(u16::from_le_bytes([rest[2], rest[3]]));
            if rest.len() < 4 + size {
                return Ok(broken(name));
            }
            rest = &rest[4 + size..];
        }
        file.seek_relative(comment_len as i64)?;
        let word = |at: usize| {
            u32::from_le_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
        };
        let listing = (field(10) as u16, word(16), word(20), word(24));
        if let Some(found) = visit(name.as_deref().unwrap_or_default(), listing) {
            return Ok(Ok(Some(found)));
        }
    }
    unreachable!("the loop returns")
}

/// The first name that appears twice in the central directory of `archive`
/// starting at byte `start` with copies that differ in compression method,
/// CRC-32 or sizes (the zip reader keeps one entry per name), `None` if every
/// copy of every name is the same; "(unknown)" if the directory cannot be
/// read.
fn differing_duplicate(archive: &Path) -> Option<String> {
    let unknown = || Some("(unknown)".to_string());
    let Some((start, end)) = central_directory(archive) else {
        return unknown();
    };
    let mut seen = HashMap::new();
    let found = walk_central_directory(archive, start, end, |name, listing| {
        let first = *seen.entry(name.to_vec()).or_insert(listing);
        (first != listing).then(|| String::from_utf8_lossy(name).escape_default().to_string())
    });
    match found {
        Ok(Ok(found)) => found,
        _ => unknown(),
    }
}

/// The central directory header the zip reader could not read, for an archive it
/// refused as a whole: found from the end-of-central-directory record, `None` if
/// that record is missing (the file is no zip, or is truncated), is ZIP64, or
/// every header reads.
fn broken_header(archive: &Path) -> Option<Header> {
    let (start, end) = central_directory(archive)?;
    walk_central_directory(archive, start, end, |_, _| None::<()>)
        .ok()?
        .err()
}

/// Where the central directory of `archive` starts and ends, from the
/// end-of-central-directory record (clipped to the file); `None` if that
/// record is missing (the file is no zip, or is truncated) or is ZIP64.
fn central_directory(archive: &Path) -> Option<(u64, u64)> {
    let mut file = fs::File::open(archive).ok()?;
    let len = file.metadata().ok()?.len();
    // The record (22 bytes) and its comment (at most 65 535) end the file.
    let tail_len = len.min(22 + 65_535);
    file.seek(SeekFrom::Start(len - tail_len)).ok()?;
    let mut tail = vec![0; tail_len as usize];
    file.read_exact(&mut tail).ok()?;
    let record = (0..tail.len().saturating_sub(21))
        .rev()
        .find(|&i| tail[i..i + 4] == [0x50, 0x4b, 0x05, 0x06])?;
    let word = |at: usize| {
        let at = record + at;
        u32::from_le_bytes([tail[at], tail[at + 1], tail[at + 2], tail[at + 3]])
    };
    let (size, start) = (word(12), word(16));
    if size == u32::MAX || start == u32::MAX {
        return None;
    }
    let (start, end) = (u64::from(start), u64::from(start) + u64::from(size));
    Some((start, end.min(len)))
}

/// Copies at most `max` bytes, returning how many were copied.
fn copy_bounded(reader: impl Read, writer: &mut impl Write, max: u64) -> io::Result<u64> {
    io::copy(&mut reader.take(max), writer)
}

/// Turns an entry name into a normalised relative path, refusing absolute names and
/// names that resolve outside the extraction directory.
fn checked_relative_path(archive: &Path, kind: ArchiveKind, name: &str) -> Result<PathBuf> {
    let err_abs = || Error::AbsoluteEntry {
        kind,
        archive: archive.to_owned(),
        entry: name.to_owned(),
    };
    // A NUL or a newline in a name would truncate the path or split error messages
    // (found by fuzzing); the name is shown escaped.
    if name.chars().any(char::is_control) {
        return Err(Error::UnsupportedEntry {
            kind,
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
                        kind,
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
            kind,
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

    /// Writes a zip of `(name, bytes)` entries, deflated.
    fn zip_of(path: &Path, entries: &[(&str, &[u8])]) {
        let mut zip = zip::ZipWriter::new(fs::File::create(path).unwrap());
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(CompressionMethod::Deflated);
        for (name, bytes) in entries {
            zip.start_file(*name, options).unwrap();
            zip.write_all(bytes).unwrap();
        }
        zip.finish().unwrap();
    }

    /// Replaces every occurrence of `from` in the file by `to` (same length).
    fn patch(path: &Path, from: &[u8], to: &[u8]) {
        assert_eq!(from.len(), to.len());
        let mut bytes = fs::read(path).unwrap();
        let mut found = 0;
        for i in 0..=bytes.len() - from.len() {
            if &bytes[i..i + from.len()] == from {
                bytes[i..i + from.len()].copy_from_slice(to);
                found += 1;
            }
        }
        assert!(found > 0);
        fs::write(path, bytes).unwrap();
    }

    fn ssp_err(path: &Path) -> Error {
        match extract_archive(path, ArchiveKind::Ssp, &ExtractLimits::default()) {
            Ok(dir) => panic!("accepted, extracted to {}", dir.root().display()),
            Err(e) => e,
        }
    }

    #[test]
    fn an_entry_over_the_compression_ratio_limit_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ratio.ssp");
        // 2 MiB of zeros deflate to about 2 KiB: a ratio near 1000.
        zip_of(
            &path,
            &[
                ("SystemStructure.ssd", b"<a/>"),
                ("resources/zeros", &[0; 2 << 20]),
            ],
        );
        let err = ssp_err(&path);
        assert!(matches!(err, Error::ArchiveTooLarge { .. }), "{err:?}");
        let text = err.to_string();
        assert!(
            text.starts_with(&format!(
                "SSP archive '{}' exceeds the extraction limit at entry 'resources/zeros': \
                 declares 2097152 bytes from",
                path.display()
            )),
            "{text}"
        );
        assert!(
            text.contains("compression ratio over the limit of 100"),
            "{text}"
        );
        // Within the ratio, or small, it is extracted.
        let noise: Vec<u8> = (0..2u32 << 20)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        zip_of(&path, &[("resources/noise", &noise), ("small", &[0; 4096])]);
        let extracted =
            extract_archive(&path, ArchiveKind::Ssp, &ExtractLimits::default()).unwrap();
        assert_eq!(
            fs::read(extracted.root().join("resources/noise")).unwrap(),
            noise
        );
    }

    #[test]
    fn an_entry_declared_over_the_per_entry_limit_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.ssp");
        // 600 MiB declared (under the 1 GiB total): 4 KiB of data, declared sizes patched.
        let data: Vec<u8> = (0..4096u32).map(|i| (i * 7919 % 251) as u8).collect();
        zip_of(&path, &[("resources/big.fmu", &data)]);
        let mut bytes = fs::read(&path).unwrap();
        for i in 0..bytes.len() - 4 {
            let at = match &bytes[i..i + 4] {
                [0x50, 0x4b, 0x03, 0x04] => 22,
                [0x50, 0x4b, 0x01, 0x02] => 24,
                _ => continue,
            };
            bytes[i + at..i + at + 4].copy_from_slice(&(600u32 << 20).to_le_bytes());
        }
        fs::write(&path, bytes).unwrap();
        let err = ssp_err(&path);
        assert_eq!(
            err.to_string(),
            format!(
                "SSP archive '{}' exceeds the extraction limit at entry 'resources/big.fmu': \
                 declares 629145600 bytes, limit 536870912 per entry",
                path.display()
            )
        );
    }

    #[test]
    fn two_entries_for_one_path_are_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("twice.ssp");
        // The zip writer refuses equal names: write two, then make them equal.
        zip_of(
            &path,
            &[
                ("SystemStructure.ssd", b"<a/>"),
                ("SystemStructure.ssX", b"<b/>"),
            ],
        );
        patch(&path, b"SystemStructure.ssX", b"SystemStructure.ssd");
        let err = ssp_err(&path);
        assert_eq!(
            err.to_string(),
            format!(
                "SSP archive '{}' has entry 'SystemStructure.ssd' that cannot be extracted: \
                 duplicate entry (the archive has two entries of this name)",
                path.display()
            )
        );
        // The same entry twice (name, method, CRC-32, sizes: as the Reference
        // FMU Roberts lists its `extra/` folder) is extracted once.
        zip_of(
            &path,
            &[
                ("SystemStructure.ssd", b"<a/>"),
                ("SystemStructure.ssX", b"<a/>"),
            ],
        );
        patch(&path, b"SystemStructure.ssX", b"SystemStructure.ssd");
        let extracted =
            extract_archive(&path, ArchiveKind::Ssp, &ExtractLimits::default()).unwrap();
        assert_eq!(
            fs::read(extracted.root().join("SystemStructure.ssd")).unwrap(),
            b"<a/>"
        );
        // Two names for one path.
        zip_of(
            &path,
            &[("resources/a.fmu", b"1"), ("resources/./a.fmu", b"2")],
        );
        let err = ssp_err(&path).to_string();
        assert!(
            err.contains(
                "entry 'resources/./a.fmu' that cannot be extracted: duplicate entry \
                 (the same path as entry 'resources/a.fmu')"
            ),
            "{err}"
        );
        // A file where another entry needs a folder.
        zip_of(&path, &[("resources", b"1"), ("resources/a.fmu", b"2")]);
        let err = ssp_err(&path).to_string();
        assert!(
            err.contains("entry 'resources/a.fmu' that cannot be extracted: its folder is entry 'resources', a file"),
            "{err}"
        );
    }

    #[test]
    fn unreadable_entries_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("corrupt.ssp");
        zip_of(&path, &[("a.txt", b"aaaa"), ("resources/b.txt", b"bbbb")]);
        // Break the second entry's local header (its signature).
        let mut bytes = fs::read(&path).unwrap();
        let second = (1..bytes.len() - 4)
            .find(|&i| bytes[i..i + 4] == [0x50, 0x4b, 0x03, 0x04])
            .unwrap();
        bytes[second + 3] = 0x09;
        fs::write(&path, bytes).unwrap();
        let err = ssp_err(&path);
        assert!(matches!(err, Error::UnsupportedEntry { .. }), "{err:?}");
        let text = err.to_string();
        assert!(
            text.starts_with(&format!(
                "SSP archive '{}' has entry 'resources/b.txt' that cannot be extracted: unreadable:",
                path.display()
            )),
            "{text}"
        );
        assert!(!text.contains('\n'));
    }

    /// The zip reader refuses an archive as a whole when one header of its central
    /// directory cannot be read: the error names that entry.
    #[test]
    fn a_broken_central_directory_header_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("directory.ssp");
        let header = |bytes: &[u8], n: usize| {
            (0..bytes.len() - 4)
                .filter(|&i| bytes[i..i + 4] == [0x50, 0x4b, 0x01, 0x02])
                .nth(n)
                .unwrap()
        };
        // The second header's extra field runs past the directory, then its
        // signature is broken.
        for (field, value, reason) in [
            (
                30,
                60_000u16,
                "Variable-length field extends beyond file boundary",
            ),
            (0, 0x0a0d, "Invalid Central Directory header"),
        ] {
            zip_of(&path, &[("a.txt", b"aaaa"), ("resources/b.txt", b"bbbb")]);
            let mut bytes = fs::read(&path).unwrap();
            let at = header(&bytes, 1) + field;
            bytes[at..at + 2].copy_from_slice(&value.to_le_bytes());
            fs::write(&path, bytes).unwrap();
            let err = ssp_err(&path);
            assert!(matches!(err, Error::UnsupportedEntry { .. }), "{err:?}");
            assert_eq!(
                err.to_string(),
                format!(
                    "SSP archive '{}' has entry 'resources/b.txt' that cannot be extracted: \
                     unreadable central directory header: invalid Zip archive: {reason}",
                    path.display()
                )
            );
        }
        // No end-of-directory record: not a zip, no entry to name.
        fs::write(&path, b"PK\x03\x04 and nothing else").unwrap();
        assert!(matches!(ssp_err(&path), Error::NotAnArchive { .. }));
    }

    #[test]
    fn extraction_folders_are_private_and_leftovers_of_both_kinds_are_swept() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ok.ssp");
        zip_of(&path, &[("SystemStructure.ssd", b"<a/>")]);
        let extracted =
            extract_archive(&path, ArchiveKind::Ssp, &ExtractLimits::default()).unwrap();
        let name = extracted.root().file_name().unwrap().to_string_lossy();
        assert!(name.starts_with("tether-ssp-"), "{name}");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = fs::metadata(extracted.root()).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o700);
        }
        // In a temporary directory of their own: marked folders of both kinds whose
        // lock is free go, an unmarked one and another program's stay.
        let temp = tempfile::tempdir().unwrap();
        for folder in [
            "tether-fmu-a",
            "tether-ssp-b",
            "tether-ssp-unmarked",
            "other-c",
        ] {
            fs::create_dir(temp.path().join(folder)).unwrap();
            if !folder.ends_with("unmarked") {
                fs::write(temp.path().join(folder).join(MARKER), b"").unwrap();
            }
        }
        assert_eq!(sweep(temp.path()), 2);
        let mut left: Vec<String> = fs::read_dir(temp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["other-c", "tether-ssp-unmarked"]);
    }

    fn rel(name: &str) -> Result<PathBuf> {
        checked_relative_path(Path::new("a.fmu"), ArchiveKind::Fmu, name)
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
