//! [`Fmu`]: an opened FMU (unpacked files, parsed model description, loaded library).

use std::path::Path;
use std::sync::{Arc, PoisonError, RwLock};

use crate::archive::{self, ExtractLimits, FmuDir};
use crate::error::{Error, Result};
use crate::integrator::Integrator;
use crate::library::binary_path;
use crate::model_description::{self, ModelDescription};
use crate::shared::FmuShared;
use crate::uri::file_uri;

/// Options for [`Fmu::open_with`].
#[derive(Debug, Clone, Default)]
pub struct OpenOptions {
    /// Limits applied when unpacking a `.fmu` archive.
    pub limits: ExtractLimits,
}

/// The FMI interface an instance is made for ([`crate::instantiate`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum Interface {
    /// Co-simulation: the FMU steps itself.
    #[default]
    CoSimulation,
    /// Model exchange: a [`MeInstance`](crate::MeInstance) integrates the
    /// FMU with this integrator where the FMU is loaded (in the host process
    /// for an isolated or remote instance).
    ModelExchange(Integrator),
}

/// Options for [`crate::instantiate`] and [`Fmu::instantiate`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InstanceOptions {
    /// `loggingOn` of `fmi2Instantiate`: whether the FMU sends debug messages.
    pub logging_on: bool,
    /// `visible` of `fmi2Instantiate` (Tether runs FMUs headless: default false).
    pub visible: bool,
    /// The inputs will take polynomials over a step (coupling polynomials of
    /// degree k > 0, [`crate::FmuInstance::set_inputs`] with derivatives). An
    /// FMI 3.0 instance gets the intermediate update callback only then (at
    /// k = 0 its calls would set nothing); FMI 2.0 instances take input
    /// derivatives either way.
    pub polynomial_inputs: bool,
    /// The interface [`crate::instantiate`] makes the instance for (default
    /// co-simulation); [`Fmu::instantiate`] makes a co-simulation instance
    /// whatever it says.
    pub interface: Interface,
}

impl InstanceOptions {
    /// Options with FMU debug logging switched on.
    pub fn with_logging(mut self, logging_on: bool) -> Self {
        self.logging_on = logging_on;
        self
    }

    /// Options for an instance of `interface`.
    pub fn with_interface(mut self, interface: Interface) -> Self {
        self.interface = interface;
        self
    }

    /// Options for inputs that take polynomials over a step (`polynomial_inputs`).
    pub fn with_polynomial_inputs(mut self, polynomial_inputs: bool) -> Self {
        self.polynomial_inputs = polynomial_inputs;
        self
    }
}

/// FMU debug logging for the whole process (`tether --fmu-log`): `None` off,
/// `Some(categories)` on (empty: every category).
static DEBUG_LOGGING: RwLock<Option<Vec<String>>> = RwLock::new(None);

/// Switches FMU debug logging on (`Some`) or off (`None`) for every instance
/// created from now on, whatever its [`InstanceOptions`]: `loggingOn` is true
/// in `fmi2Instantiate`, and with categories `fmi2SetDebugLogging(true, …)`
/// selects them (those the model description does not declare are skipped
/// with a warning, if it declares any). The messages go to the `log` facade
/// with the target `fmu::<instance>`.
pub fn set_debug_logging(categories: Option<Vec<String>>) {
    *DEBUG_LOGGING
        .write()
        .unwrap_or_else(PoisonError::into_inner) = categories;
}

pub(crate) fn debug_logging() -> Option<Vec<String>> {
    DEBUG_LOGGING
        .read()
        .unwrap_or_else(PoisonError::into_inner)
        .clone()
}

/// An opened FMI 2.0 or FMI 3.0 FMU (co-simulation, model exchange or both).
///
/// Dropping the `Fmu` does not invalidate instances made from it: they share the
/// unpacked directory and the loaded library, which go away with the last holder.
#[derive(Debug, Clone)]
pub struct Fmu {
    shared: Arc<FmuShared>,
}

impl Fmu {
    /// Opens a `.fmu` archive (unpacked into a private temporary directory) or an
    /// already-unpacked FMU directory, with default [`OpenOptions`].
    pub fn open(path: impl AsRef<Path>) -> Result<Fmu> {
        Fmu::open_with(path, &OpenOptions::default())
    }

    /// Opens an FMU with explicit options.
    ///
    /// Checks, in order: the archive is a safe zip (see [`ExtractLimits`]);
    /// `modelDescription.xml` exists; its `fmiVersion` is 2.x (a cheap peek before the full
    /// parse); it is well-formed and valid and declares `CoSimulation` or
    /// `ModelExchange` (the library is named after the co-simulation model
    /// identifier, else the model-exchange one);
    /// `binaries/linux64/<modelIdentifier>.so` exists, loads, exports every FMI 2.0
    /// co-simulation function and reports version "2.0" and platform "default".
    pub fn open_with(path: impl AsRef<Path>, options: &OpenOptions) -> Result<Fmu> {
        let fmu = Fmu::open_unloaded(path, options)?;
        fmu.shared.load()?;
        Ok(fmu)
    }

    /// Opens an FMU as [`open_with`](Self::open_with) does, without loading its
    /// library: that happens with the first [`instantiate`](Self::instantiate)
    /// in this process, if any. For instances in host processes
    /// ([`RemoteInstance`](crate::remote::RemoteInstance)), whose library then
    /// never runs in this process (the host checks and loads it).
    pub fn open_unloaded(path: impl AsRef<Path>, options: &OpenOptions) -> Result<Fmu> {
        let origin = path.as_ref().to_owned();
        let metadata = std::fs::metadata(&origin).map_err(|source| Error::Missing {
            place: Box::new(crate::paths::Missing::new(&origin, None)),
            source,
        })?;
        let dir = if metadata.is_dir() {
            FmuDir::existing(&origin)?
        } else if let Some(kind) = special_file_kind(&metadata) {
            return Err(Error::NotAFile { path: origin, kind });
        } else {
            archive::extract(&origin, &options.limits)?
        };
        let xml_path = dir.root().join("modelDescription.xml");
        if !xml_path.is_file() {
            return Err(Error::MissingModelDescription { path: origin });
        }
        let bytes = std::fs::read(&xml_path).map_err(|source| Error::Io {
            path: xml_path.clone(),
            source,
        })?;
        // Errors name the file as the user sees it: inside the archive or the directory.
        let shown = origin.join("modelDescription.xml");
        let model_description = model_description::parse_bytes(&bytes, &shown, &origin)?;
        report_quirks(&origin, &model_description);
        let so = binary_path(
            dir.root(),
            model_description.model_identifier(),
            model_description.standard,
        );
        if !so.is_file() {
            let expected = if metadata.is_dir() {
                so
            } else {
                origin.join(so.strip_prefix(dir.root()).unwrap_or(&so))
            };
            return Err(Error::MissingBinary {
                model: model_description.model_name.clone(),
                expected,
            });
        }
        let needs_tool = model_description.cs().needs_execution_tool
            || model_description
                .model_exchange
                .as_ref()
                .is_some_and(|me| me.needs_execution_tool);
        if needs_tool {
            log::warn!(
                "FMU '{}' declares needsExecutionTool=\"true\": it needs an external tool that Tether does not provide or check; it may fail to instantiate",
                origin.display()
            );
        }
        Ok(Fmu {
            shared: Arc::new(FmuShared {
                origin,
                dir: Arc::new(dir),
                model_description,
                so,
                library: Default::default(),
                library3: Default::default(),
            }),
        })
    }

    /// What every instance of this FMU shares.
    pub(crate) fn shared(&self) -> &Arc<FmuShared> {
        &self.shared
    }

    /// The parsed model description.
    pub fn model_description(&self) -> &ModelDescription {
        &self.shared.model_description
    }

    /// [`Error::NotCoSimulation`] if the FMU has no co-simulation interface:
    /// every co-simulation path asks this before it instantiates.
    pub fn require_co_simulation(&self) -> Result<()> {
        let md = self.model_description();
        if md.co_simulation.is_some() {
            return Ok(());
        }
        Err(Error::NotCoSimulation {
            path: self.path().to_owned(),
            model: md.model_name.clone(),
        })
    }

    /// [`Error::Unsupported`] if the FMU has no model-exchange interface (no
    /// `ModelExchange` element): [`crate::instantiate`] asks this before it
    /// makes a model-exchange instance in any placement.
    pub fn require_model_exchange(&self) -> Result<()> {
        let md = self.model_description();
        if md.model_exchange.is_some() {
            return Ok(());
        }
        Err(Error::Unsupported {
            model: md.model_name.clone(),
            reason: "it has no model-exchange interface (no <ModelExchange> element)".into(),
        })
    }

    /// The path the FMU was opened from.
    pub fn path(&self) -> &Path {
        &self.shared.origin
    }

    /// The directory holding the unpacked FMU.
    pub fn directory(&self) -> &Path {
        self.shared.dir.root()
    }

    /// The shared library's path.
    pub fn library_path(&self) -> &Path {
        &self.shared.so
    }

    /// The `fmuResourceLocation` passed to `fmi2Instantiate`: a percent-encoded
    /// `file://` URI of the FMU's `resources/` directory.
    pub fn resource_location(&self) -> String {
        file_uri(&self.shared.dir.resources())
    }
}

/// What a path that is neither a regular file nor a folder is (`FIFO`,
/// `character device`, `block device`, `socket`, `special file`), for the one
/// line that refuses it before it is opened: opening a FIFO waits for a writer
/// that may never come. `None` for a regular file or a folder.
pub fn special_file_kind(metadata: &std::fs::Metadata) -> Option<&'static str> {
    if metadata.is_file() || metadata.is_dir() {
        return None;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = metadata.file_type();
        if t.is_fifo() {
            return Some("FIFO");
        }
        if t.is_char_device() {
            return Some("character device");
        }
        if t.is_block_device() {
            return Some("block device");
        }
        if t.is_socket() {
            return Some("socket");
        }
    }
    Some("special file")
}

/// The log target of the model descriptions' quirks: a host process of
/// isolated instances leaves them to the master, which opened the FMU first.
pub const QUIRKS_TARGET: &str = "tether_fmi::quirks";

/// The model description's quirks as warnings, once per FMU file in this
/// process however often it is opened: one line per kind, the first
/// occurrence with the FMU's file name and the line, and how many more
/// (`warning: FourVarsFeedThrough.fmu: modelDescription.xml:108: variable
/// 'InBool' declares initial=Exact, … (and 3 more variables)`).
fn report_quirks(origin: &Path, md: &crate::ModelDescription) {
    static REPORTED: std::sync::Mutex<Vec<std::path::PathBuf>> = std::sync::Mutex::new(Vec::new());
    if md.quirks.is_empty() {
        return;
    }
    let key = origin.canonicalize().unwrap_or_else(|_| origin.to_owned());
    {
        let mut reported = REPORTED.lock().unwrap_or_else(|e| e.into_inner());
        if reported.contains(&key) {
            return;
        }
        reported.push(key);
    }
    let file = origin.file_name().map_or_else(
        || origin.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let mut seen: Vec<&str> = Vec::new();
    for kind in md.quirks.iter().map(|q| q.kind) {
        if seen.contains(&kind) {
            continue;
        }
        seen.push(kind);
        let mut of_kind = md.quirks.iter().filter(|q| q.kind == kind);
        let first = of_kind.next().expect("a quirk of this kind");
        let more = match of_kind.count() {
            0 => String::new(),
            1 => " (and 1 more variable)".to_string(),
            n => format!(" (and {n} more variables)"),
        };
        log::warn!(
            target: QUIRKS_TARGET,
            "{file}: modelDescription.xml:{}: {}{more}",
            first.line,
            first.message
        );
    }
}
