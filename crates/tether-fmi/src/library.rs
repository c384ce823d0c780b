//! Loading an FMU's shared library and resolving the FMI 2.0 or FMI 3.0 co-simulation
//! API.

use std::ffi::CStr;
use std::mem::ManuallyDrop;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{one_line, Error, Result};
use crate::model_description::FmiStandard;
use crate::raw::fmi3::Fmi3Functions;
use crate::raw::{Fmi2Functions, Fmi2MeFunctions, Fmi3MeFunctions};

/// The platform directory under `binaries/` this build loads FMI 2.0 FMUs from.
pub const PLATFORM: &str = "linux64";

/// The platform tuple under `binaries/` this build loads FMI 3.0 FMUs from.
pub const PLATFORM_FMI3: &str = "x86_64-linux";

/// A function table of one FMI version: resolved from a library, then checked.
pub(crate) trait Api: Sized {
    /// The model-exchange functions of this FMI version.
    type Me;
    /// Resolves every function, naming the first one that is missing (the
    /// co-simulation ones only when `co_simulation`).
    fn resolve(lib: &libloading::Library, path: &Path, co_simulation: bool) -> Result<Self>;
    /// Resolves the model-exchange functions; `Err` names the first missing one.
    fn resolve_me(lib: &libloading::Library) -> std::result::Result<Self::Me, &'static str>;
    /// Checks what the library says about itself (version, platform).
    fn check_identity(&self, path: &Path) -> Result<()>;
}

/// A possibly-NULL static C string returned by `fmiXGetVersion` and the like.
fn static_text(ptr: *const std::ffi::c_char) -> String {
    if ptr.is_null() {
        return String::from("(NULL)");
    }
    // SAFETY: the standard requires a static NUL-terminated string.
    unsafe { CStr::from_ptr(ptr) }
        .to_string_lossy()
        .into_owned()
}

impl Api for Fmi2Functions {
    type Me = Fmi2MeFunctions;
    fn resolve(lib: &libloading::Library, path: &Path, co_simulation: bool) -> Result<Self> {
        Fmi2Functions::resolve(lib, path, co_simulation)
    }
    fn resolve_me(lib: &libloading::Library) -> std::result::Result<Self::Me, &'static str> {
        Fmi2MeFunctions::resolve(lib)
    }

    /// Checks `fmi2GetVersion` = "2.0" and `fmi2GetTypesPlatform` = "default".
    fn check_identity(&self, path: &Path) -> Result<()> {
        // SAFETY: both functions take no arguments and may be called before any instance
        // exists (FMI 2.0, section 2.1.4).
        let (version, platform) =
            unsafe { ((self.fmi2GetVersion)(), (self.fmi2GetTypesPlatform)()) };
        for (function, ptr, expected) in [
            ("fmi2GetVersion", version, "2.0"),
            ("fmi2GetTypesPlatform", platform, "default"),
        ] {
            let found = static_text(ptr);
            if found != expected {
                return Err(Error::IncompatibleLibrary {
                    library: path.to_owned(),
                    function,
                    found,
                    expected,
                });
            }
        }
        Ok(())
    }
}

impl Api for Fmi3Functions {
    type Me = Fmi3MeFunctions;
    fn resolve(lib: &libloading::Library, path: &Path, co_simulation: bool) -> Result<Self> {
        Fmi3Functions::resolve(lib, path, co_simulation)
    }
    fn resolve_me(lib: &libloading::Library) -> std::result::Result<Self::Me, &'static str> {
        Fmi3MeFunctions::resolve(lib)
    }

    /// Checks that `fmi3GetVersion` is "3.x".
    fn check_identity(&self, path: &Path) -> Result<()> {
        // SAFETY: fmi3GetVersion takes no argument and may be called before any
        // instance exists (FMI 3.0, section 2.3.1).
        let found = static_text(unsafe { (self.fmi3GetVersion)() });
        if found.starts_with("3.") {
            Ok(())
        } else {
            Err(Error::IncompatibleLibrary {
                library: path.to_owned(),
                function: "fmi3GetVersion",
                found,
                expected: "3.0",
            })
        }
    }
}

/// A loaded FMU shared library with its resolved function table.
///
/// Shared (in an `Arc`) by the [`Fmu`](crate::Fmu) and every instance, so the code stays
/// mapped while anything can still call it.
pub(crate) struct Library<F: Api = Fmi2Functions> {
    path: PathBuf,
    functions: F,
    /// The model-exchange functions, or the first that is missing.
    me: std::result::Result<F::Me, &'static str>,
    handle: ManuallyDrop<libloading::Library>,
    /// Set once any call returned fmi2Fatal: per the standard no further function of
    /// any instance of this FMU may be called.
    fatal: AtomicBool,
}

impl<F: Api> std::fmt::Debug for Library<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Library")
            .field("path", &self.path)
            .field("fatal", &self.is_fatal())
            .finish_non_exhaustive()
    }
}

/// The expected path of the shared library inside an FMU directory.
pub(crate) fn binary_path(root: &Path, model_identifier: &str, standard: FmiStandard) -> PathBuf {
    let platform = match standard {
        FmiStandard::Fmi2 => PLATFORM,
        FmiStandard::Fmi3 => PLATFORM_FMI3,
    };
    root.join("binaries")
        .join(platform)
        .join(format!("{model_identifier}.so"))
}

/// The loader's own words (libloading's error says only "dlopen failed"; the
/// reason is its source), with a hint for FMUs that need the Python runtime.
fn load_message(e: &libloading::Error) -> String {
    let mut message = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(cause) = source {
        message = format!("{message}: {cause}");
        source = cause.source();
    }
    if message.contains("undefined symbol: _Py") || message.contains("undefined symbol: Py") {
        message.push_str(
            " (the FMU needs the Python runtime, as FMUs exported by pythonfmu do: preload \
             libpython, e.g. LD_PRELOAD=$(python3 -c \"import sysconfig, os; \
             print(os.path.join(sysconfig.get_config_var('LIBDIR'), \
             sysconfig.get_config_var('LDLIBRARY')))\"))",
        );
    }
    one_line(&message)
}

impl<F: Api> Library<F> {
    /// Loads `path` (binding all symbols now) and resolves every function of the API
    /// (the co-simulation functions required when `co_simulation`: the FMU declares
    /// co-simulation), and the model-exchange ones where the library has them.
    pub(crate) fn load(path: &Path, co_simulation: bool) -> Result<Library<F>> {
        use libloading::os::unix::{Library as UnixLibrary, RTLD_LOCAL, RTLD_NOW};
        // SAFETY: loading a library runs its initialisers; an FMU's shared library is
        // trusted code by the nature of co-simulation (we are about to call into it).
        // RTLD_NOW makes unresolved dependencies fail here instead of at a later call.
        let handle =
            unsafe { UnixLibrary::open(Some(path), RTLD_NOW | RTLD_LOCAL) }.map_err(|e| {
                Error::LibraryLoad {
                    path: path.to_owned(),
                    message: load_message(&e),
                }
            })?;
        let handle = libloading::Library::from(handle);
        let functions = F::resolve(&handle, path, co_simulation)?;
        functions.check_identity(path)?;
        let me = F::resolve_me(&handle);
        Ok(Library {
            path: path.to_owned(),
            functions,
            me,
            handle: ManuallyDrop::new(handle),
            fatal: AtomicBool::new(false),
        })
    }
}

impl<F: Api> Library<F> {
    /// The resolved function table.
    pub(crate) fn functions(&self) -> &F {
        &self.functions
    }

    /// The model-exchange functions, or the error naming the first missing one.
    pub(crate) fn me(&self) -> Result<&F::Me> {
        self.me
            .as_ref()
            .map_err(|symbol| crate::raw::missing_me_symbol(&self.path, symbol))
    }

    /// Records that a call returned fmi2Fatal.
    pub(crate) fn mark_fatal(&self) {
        self.fatal.store(true, Ordering::SeqCst);
    }

    /// Whether a call returned fmi2Fatal.
    pub(crate) fn is_fatal(&self) -> bool {
        self.fatal.load(Ordering::SeqCst)
    }
}

impl<F: Api> Drop for Library<F> {
    fn drop(&mut self) {
        if self.is_fatal() {
            // A fatal FMU may have left threads or callbacks behind: keep its code mapped.
            return;
        }
        // SAFETY: the handle is dropped exactly once, here; no instance remains, since
        // each holds an `Arc<Library>`.
        unsafe { ManuallyDrop::drop(&mut self.handle) };
    }
}
