//! Build workspace FMU crates and package them as `.fmu` archives.
//!
//! - [`package`]: a built FMU cdylib → `<out_dir>/<modelIdentifier>.fmu`.
//! - [`workspace_fmu`]: `cargo build --profile fmu -p <name>` into a separate target dir
//!   (`target/fmu-build`, so it works from inside `cargo test`), then [`package`] into
//!   `target/fmus/`. Cached per process, serialized across processes by a file lock.
//!   The `fmu` profile (the workspace's Cargo.toml) builds the same code wherever the
//!   FMUs are used: the README's run, the tests and the bench.
//! - [`workspace_fmus`]: the same for every crate under `fmus/`.
//!
//! Every kit-built library is both an FMI 2.0 and an FMI 3.0 FMU (one model, two C
//! layers). [`package`] and [`workspace_fmu`] make the FMI 2.0 archive
//! `<name>.fmu`; [`package_fmi3`] and [`workspace_fmu3`] the FMI 3.0 archive
//! `<name>-fmi3.fmu` of the same library; [`workspace_fmus`] makes both.

use std::collections::HashMap;
use std::ffi::{c_char, CStr};
use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, OnceLock};

use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipWriter};

/// Name of the symbol every kit-built FMU exports.
pub const MODEL_DESCRIPTION_SYMBOL: &str = "tether_fmu_kit_model_description";

/// Name of the symbol that gives the FMI 3.0 model description of a kit-built FMU.
pub const MODEL_DESCRIPTION_SYMBOL_FMI3: &str = "tether_fmu_kit_model_description_fmi3";

/// The FMI 3.0 platform tuple of this host (`binaries/<tuple>/`).
pub const PLATFORM_FMI3: &str = if cfg!(all(target_os = "linux", target_arch = "x86_64")) {
    "x86_64-linux"
} else if cfg!(all(target_os = "linux", target_arch = "aarch64")) {
    "aarch64-linux"
} else if cfg!(all(target_os = "macos", target_arch = "aarch64")) {
    "aarch64-darwin"
} else if cfg!(target_os = "macos") {
    "x86_64-darwin"
} else if cfg!(all(windows, target_pointer_width = "64")) {
    "x86_64-windows"
} else {
    "unknown"
};

/// The FMI version of an archive made from a kit-built library.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FmiVersion {
    /// `<modelIdentifier>.fmu`, `binaries/linux64/`.
    Fmi2,
    /// `<modelIdentifier>-fmi3.fmu`, `binaries/x86_64-linux/`.
    Fmi3,
}

impl FmiVersion {
    fn symbol(self) -> &'static str {
        match self {
            FmiVersion::Fmi2 => MODEL_DESCRIPTION_SYMBOL,
            FmiVersion::Fmi3 => MODEL_DESCRIPTION_SYMBOL_FMI3,
        }
    }

    fn platform(self) -> &'static str {
        match self {
            FmiVersion::Fmi2 => PLATFORM.0,
            FmiVersion::Fmi3 => PLATFORM_FMI3,
        }
    }

    /// The archive's file name for model identifier `id`.
    pub fn file_name(self, id: &str) -> String {
        match self {
            FmiVersion::Fmi2 => format!("{id}.fmu"),
            FmiVersion::Fmi3 => format!("{id}-fmi3.fmu"),
        }
    }
}

/// The FMI platform folder and library suffix of this host.
pub const PLATFORM: (&str, &str) = if cfg!(all(target_os = "linux", target_pointer_width = "64")) {
    ("linux64", "so")
} else if cfg!(target_os = "macos") {
    ("darwin64", "dylib")
} else if cfg!(all(windows, target_pointer_width = "64")) {
    ("win64", "dll")
} else {
    ("unknown", "so")
};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot load FMU library {path}: {source}")]
    Load {
        path: PathBuf,
        source: libloading::Error,
    },
    #[error("{path} does not export {symbol} (not built with tether-fmu-kit?): {source}")]
    Symbol {
        path: PathBuf,
        symbol: &'static str,
        source: libloading::Error,
    },
    #[error("{path}: {symbol} returned no description (invalid model declaration, see stderr)")]
    NoDescription { path: PathBuf, symbol: &'static str },
    #[error("{path}: modelDescription.xml has no valid modelIdentifier")]
    NoIdentifier { path: PathBuf },
    #[error("{action} {path}: {source}")]
    Io {
        action: &'static str,
        path: PathBuf,
        source: io::Error,
    },
    #[error("cannot write FMU archive {path}: {source}")]
    Zip {
        path: PathBuf,
        source: zip::result::ZipError,
    },
    #[error("no Cargo.toml with [workspace] in {start} or above")]
    NoWorkspace { start: PathBuf },
    #[error("cannot run `{command}`: {source}")]
    Spawn { command: String, source: io::Error },
    #[error("building FMU crate {name} failed: `{command}` exited with {status}: {stderr_tail}")]
    Build {
        name: String,
        command: String,
        status: std::process::ExitStatus,
        stderr_tail: String,
    },
    #[error("building FMU crate {name} produced no library at {path}")]
    MissingLibrary { name: String, path: PathBuf },
}

fn io_error<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(io::Error) -> Error + 'a {
    move |source| Error::Io {
        action,
        path: path.to_path_buf(),
        source,
    }
}

/// Reads the FMI 2.0 model description out of a built FMU library.
pub fn model_description(cdylib: &Path) -> Result<String, Error> {
    model_description_of(cdylib, FmiVersion::Fmi2)
}

/// Reads the model description of FMI version `version` out of a built FMU library.
pub fn model_description_of(cdylib: &Path, version: FmiVersion) -> Result<String, Error> {
    let symbol = version.symbol();
    // SAFETY: loading a library runs its initializers; this is a library built with
    // tether-fmu-kit, whose initializers are Rust's (none with side effects).
    let library = unsafe { libloading::Library::new(cdylib) }.map_err(|source| Error::Load {
        path: cdylib.to_path_buf(),
        source,
    })?;
    type Describe = unsafe extern "C" fn() -> *const c_char;
    // SAFETY: the kit exports this symbol with exactly this signature.
    let describe =
        unsafe { library.get::<Describe>(symbol.as_bytes()) }.map_err(|source| Error::Symbol {
            path: cdylib.to_path_buf(),
            symbol,
            source,
        })?;
    // SAFETY: the function takes no arguments and returns null or a static C string.
    let text = unsafe { describe() };
    if text.is_null() {
        return Err(Error::NoDescription {
            path: cdylib.to_path_buf(),
            symbol,
        });
    }
    // SAFETY: non-null, NUL-terminated and static for as long as `library` is loaded;
    // it is copied before the library is dropped.
    let xml = unsafe { CStr::from_ptr(text) }
        .to_string_lossy()
        .into_owned();
    Ok(xml)
}

/// The `modelIdentifier` attribute of the `<CoSimulation>` element.
pub fn model_identifier(xml: &str) -> Option<&str> {
    let start = xml.find("modelIdentifier=\"")? + "modelIdentifier=\"".len();
    let id = &xml[start..start + xml[start..].find('"')?];
    let valid = !id.is_empty() && id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    valid.then_some(id)
}

/// Packages a built FMU library as `<out_dir>/<modelIdentifier>.fmu` (deflate zip with
/// `modelDescription.xml` and `binaries/<platform>/<modelIdentifier>.<suffix>`),
/// written to a temporary file and renamed into place.
pub fn package(cdylib: &Path, out_dir: &Path) -> Result<PathBuf, Error> {
    package_as(cdylib, out_dir, FmiVersion::Fmi2)
}

/// Packages a built FMU library as the FMI 3.0 archive `<out_dir>/<modelIdentifier>-fmi3.fmu`
/// (`binaries/x86_64-linux/<modelIdentifier>.so` on Linux).
pub fn package_fmi3(cdylib: &Path, out_dir: &Path) -> Result<PathBuf, Error> {
    package_as(cdylib, out_dir, FmiVersion::Fmi3)
}

fn package_as(cdylib: &Path, out_dir: &Path, version: FmiVersion) -> Result<PathBuf, Error> {
    let xml = model_description_of(cdylib, version)?;
    let id = model_identifier(&xml).ok_or_else(|| Error::NoIdentifier {
        path: cdylib.to_path_buf(),
    })?;
    let binary = fs::read(cdylib).map_err(io_error("cannot read", cdylib))?;
    fs::create_dir_all(out_dir).map_err(io_error("cannot create", out_dir))?;
    let file_name = version.file_name(id);
    let target = out_dir.join(&file_name);
    let temp = out_dir.join(format!(
        ".{file_name}.{}.{:?}.tmp",
        std::process::id(),
        std::thread::current().id()
    ));
    let written = write_zip(&temp, &xml, id, &binary, version.platform())
        .and_then(|()| fs::rename(&temp, &target).map_err(io_error("cannot rename into", &target)));
    if written.is_err() {
        let _ = fs::remove_file(&temp);
    }
    written.map(|()| target)
}

fn write_zip(path: &Path, xml: &str, id: &str, binary: &[u8], platform: &str) -> Result<(), Error> {
    let file = File::create(path).map_err(io_error("cannot create", path))?;
    let zip_error = |source| Error::Zip {
        path: path.to_path_buf(),
        source,
    };
    let mut zip = ZipWriter::new(file);
    // A fixed timestamp makes the archive a function of its contents.
    let options = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Deflated)
        .last_modified_time(DateTime::default());
    let (_, suffix) = PLATFORM;
    zip.start_file("modelDescription.xml", options.unix_permissions(0o644))
        .map_err(zip_error)?;
    zip.write_all(xml.as_bytes())
        .map_err(io_error("cannot write", path))?;
    zip.start_file(
        format!("binaries/{platform}/{id}.{suffix}"),
        options.unix_permissions(0o755),
    )
    .map_err(zip_error)?;
    zip.write_all(binary)
        .map_err(io_error("cannot write", path))?;
    let file = zip.finish().map_err(zip_error)?;
    file.sync_all().map_err(io_error("cannot sync", path))
}

/// The workspace root: the nearest directory at or above `CARGO_MANIFEST_DIR` (or the
/// current directory) whose Cargo.toml has a `[workspace]` table.
pub fn workspace_root() -> Result<PathBuf, Error> {
    let start = match std::env::var_os("CARGO_MANIFEST_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => std::env::current_dir().map_err(io_error("cannot read", Path::new(".")))?,
    };
    let is_workspace = |dir: &Path| {
        fs::read_to_string(dir.join("Cargo.toml"))
            .is_ok_and(|text| text.lines().any(|line| line.trim() == "[workspace]"))
    };
    start
        .ancestors()
        .find(|dir| is_workspace(dir))
        .map(Path::to_path_buf)
        .ok_or(Error::NoWorkspace { start })
}

/// Whether this host runs the binaries of the vendored third-party test FMUs
/// (`tests/fixtures/`): they are built for x86_64 Linux only.
pub const FIXTURE_BINARIES_RUN: bool = cfg!(all(target_os = "linux", target_arch = "x86_64"));

/// A vendored third-party test FMU, `<root>/tests/fixtures/<relative>` (for example
/// `reference-fmus/fmi3/StateSpace.fmu`), for a test that loads its binary.
///
/// On a host where the binaries do not run ([`FIXTURE_BINARIES_RUN`]) it prints one
/// line naming the test's FMU and returns `None`, so the test skips; with `CI` set it
/// panics instead, so that CI cannot pass by skipping.
pub fn fixture_fmu(relative: &str) -> Option<PathBuf> {
    let path = fixture_path(relative);
    if FIXTURE_BINARIES_RUN {
        return Some(path);
    }
    let why = format!(
        "{relative}: skipped, its binaries are built for x86_64 Linux and this host is {} {}",
        std::env::consts::ARCH,
        std::env::consts::OS
    );
    assert!(std::env::var_os("CI").is_none(), "{why} (CI is set)");
    eprintln!("{why}");
    None
}

/// The path of a vendored test file, `<root>/tests/fixtures/<relative>`, for reading it
/// (its model description) on any host. Panics when the workspace root cannot be found.
pub fn fixture_path(relative: &str) -> PathBuf {
    workspace_root()
        .expect("the workspace root (a Cargo.toml with [workspace])")
        .join("tests/fixtures")
        .join(relative)
}

/// The cargo profile of the workspace FMUs (`[profile.fmu]` in the workspace's Cargo.toml).
pub const FMU_PROFILE: &str = "fmu";

/// Builds the workspace crate `name` with the [`FMU_PROFILE`] and packages it as FMI 2.0
/// into `<root>/target/fmus/<name>.fmu`. Cached per process; a file lock serializes
/// concurrent processes (parallel test binaries).
pub fn workspace_fmu(name: &str) -> Result<PathBuf, Error> {
    workspace_fmu_as(name, FmiVersion::Fmi2)
}

/// The same library packaged as FMI 3.0: `<root>/target/fmus/<name>-fmi3.fmu`.
pub fn workspace_fmu3(name: &str) -> Result<PathBuf, Error> {
    workspace_fmu_as(name, FmiVersion::Fmi3)
}

/// [`workspace_fmu`] or [`workspace_fmu3`].
pub fn workspace_fmu_as(name: &str, version: FmiVersion) -> Result<PathBuf, Error> {
    static BUILT: OnceLock<Mutex<HashMap<(String, FmiVersion), PathBuf>>> = OnceLock::new();
    let mut built = BUILT
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let key = (name.to_string(), version);
    if let Some(path) = built.get(&key) {
        return Ok(path.clone());
    }
    let root = workspace_root()?;
    let target = root.join("target");
    fs::create_dir_all(&target).map_err(io_error("cannot create", &target))?;
    let lock_path = target.join("fmu-build.lock");
    let lock = File::create(&lock_path).map_err(io_error("cannot create", &lock_path))?;
    lock.lock().map_err(io_error("cannot lock", &lock_path))?;
    let path = build_and_package(&root, name, version);
    drop(lock);
    let path = path?;
    built.insert(key, path.clone());
    Ok(path)
}

/// Whether the FMUs' cargo builds show their progress on stderr (set by
/// [`show_build_progress`]); otherwise their output is kept for errors.
static SHOW_PROGRESS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Let the FMUs' cargo builds print their progress on stderr (for a person
/// waiting on a first build, `cargo tether`), instead of keeping it for the
/// error of a failed build.
pub fn show_build_progress(on: bool) {
    SHOW_PROGRESS.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Builds `name` and packages it. The first build of a process builds every crate under
/// `fmus/` with it, in one cargo run: cargo then compiles them side by side on every
/// core, and a later call finds them built.
fn build_and_package(root: &Path, name: &str, version: FmiVersion) -> Result<PathBuf, Error> {
    static ALL_BUILT: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    let build_dir = root.join("target").join("fmu-build");
    let mut names = vec![name.to_string()];
    if !ALL_BUILT.load(std::sync::atomic::Ordering::Relaxed) {
        names.extend(workspace_fmu_names()?.into_iter().filter(|n| n != name));
    }
    let packages: Vec<String> = names
        .iter()
        .flat_map(|n| ["-p".into(), n.clone()])
        .collect();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut command = Command::new(&cargo);
    command
        .current_dir(root)
        .args(["build", "--profile", FMU_PROFILE])
        .args(&packages)
        .arg("--target-dir")
        .arg(&build_dir);
    // The outer cargo (e.g. `cargo test`) may have set these for itself.
    for var in [
        "CARGO_TARGET_DIR",
        "CARGO_BUILD_TARGET_DIR",
        "CARGO_BUILD_TARGET",
        "CARGO_MAKEFLAGS",
        "MAKEFLAGS",
        "MFLAGS",
    ] {
        command.env_remove(var);
    }
    let shown = format!(
        "{} build --profile {FMU_PROFILE} {} --target-dir {}",
        cargo.to_string_lossy(),
        packages.join(" "),
        build_dir.display()
    );
    // The first build of the process builds them all: its progress shows.
    if SHOW_PROGRESS.load(std::sync::atomic::Ordering::Relaxed)
        && !ALL_BUILT.load(std::sync::atomic::Ordering::Relaxed)
    {
        command.stderr(std::process::Stdio::inherit());
    }
    let output = command.output().map_err(|source| Error::Spawn {
        command: shown.clone(),
        source,
    })?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        let stderr_tail = lines[lines.len().saturating_sub(12)..].join(" | ");
        return Err(Error::Build {
            name: name.to_string(),
            command: shown,
            status: output.status,
            stderr_tail,
        });
    }
    ALL_BUILT.store(true, std::sync::atomic::Ordering::Relaxed);
    let (_, suffix) = PLATFORM;
    let prefix = if cfg!(windows) { "" } else { "lib" };
    let library = build_dir
        .join(FMU_PROFILE)
        .join(format!("{prefix}{}.{suffix}", name.replace('-', "_")));
    if !library.is_file() {
        return Err(Error::MissingLibrary {
            name: name.to_string(),
            path: library,
        });
    }
    package_as(&library, &root.join("target").join("fmus"), version)
}

/// The package names of every crate under `<root>/fmus/`, sorted.
pub fn workspace_fmu_names() -> Result<Vec<String>, Error> {
    let fmus = workspace_root()?.join("fmus");
    let entries = fs::read_dir(&fmus).map_err(io_error("cannot read", &fmus))?;
    let mut names = Vec::new();
    for entry in entries {
        let dir = entry.map_err(io_error("cannot read", &fmus))?.path();
        let manifest = dir.join("Cargo.toml");
        let Ok(text) = fs::read_to_string(&manifest) else {
            continue;
        };
        let name = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix("name"))
            .filter_map(|rest| rest.trim().strip_prefix('='))
            .map(|v| v.trim().trim_matches('"').to_string())
            .next();
        if let Some(name) =
            name.or_else(|| dir.file_name().map(|n| n.to_string_lossy().into_owned()))
        {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

/// Builds and packages every crate under `fmus/`, as FMI 2.0 and as FMI 3.0;
/// returns the `.fmu` paths (`<name>.fmu`, `<name>-fmi3.fmu`, …).
pub fn workspace_fmus() -> Result<Vec<PathBuf>, Error> {
    let mut fmus = Vec::new();
    for name in workspace_fmu_names()? {
        fmus.push(workspace_fmu(&name)?);
        fmus.push(workspace_fmu3(&name)?);
    }
    Ok(fmus)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_identifier_is_read_from_the_cosimulation_element() {
        let xml =
            r#"<fmiModelDescription modelName="x"><CoSimulation modelIdentifier="osc_1" a="b"/>"#;
        assert_eq!(model_identifier(xml), Some("osc_1"));
        assert_eq!(
            model_identifier(r#"<CoSimulation modelIdentifier="../evil"/>"#),
            None
        );
        assert_eq!(model_identifier("<CoSimulation/>"), None);
    }

    #[test]
    fn workspace_root_has_the_fmus_folder() {
        let root = workspace_root().unwrap();
        assert!(root.join("fmus").is_dir(), "{}", root.display());
        assert!(workspace_fmu_names()
            .unwrap()
            .contains(&"oscillator".to_string()));
    }
}
