//! [`Fmu`]: an opened FMU (unpacked files, parsed model description, loaded library).

use std::path::Path;
use std::sync::{Arc, PoisonError, RwLock};

use crate::archive::{self, ExtractLimits, FmuDir};
use crate::error::{Error, Result};
use crate::instance::Instance;
use crate::library::binary_path;
use crate::model_description::{self, ModelDescription};
use crate::raw::component::{InstantiateArgs, RawComponent};
use crate::shared::{FmuShared, OnceGuard};
use crate::uri::file_uri;

/// Options for [`Fmu::open_with`].
#[derive(Debug, Clone, Default)]
pub struct OpenOptions {
    /// Limits applied when unpacking a `.fmu` archive.
    pub limits: ExtractLimits,
}

/// Options for [`Fmu::instantiate`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
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
}

impl InstanceOptions {
    /// Options with FMU debug logging switched on.
    pub fn with_logging(mut self, logging_on: bool) -> Self {
        self.logging_on = logging_on;
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

/// An opened FMI 2.0 co-simulation FMU.
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
    /// parse); it is well-formed and valid and declares `CoSimulation`;
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
        } else if !metadata.is_file() {
            return Err(Error::NotAFile {
                path: origin,
                kind: file_kind(&metadata),
            });
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
        let so = binary_path(
            dir.root(),
            &model_description.co_simulation.model_identifier,
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
        if model_description.co_simulation.needs_execution_tool {
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

    /// Creates a co-simulation instance (`fmi2Instantiate` with the model description's
    /// GUID). The instance is in the *instantiated* state; call
    /// [`Instance::setup_experiment`] and the initialization-mode functions next.
    ///
    /// A model that declares `canBeInstantiatedOnlyOncePerProcess="true"` gets at most one
    /// live instance per process, counted by GUID over every opened copy of it
    /// ([`Error::OnlyOncePerProcess`] otherwise).
    pub fn instantiate(&self, instance_name: &str, options: InstanceOptions) -> Result<Instance> {
        let md = &self.shared.model_description;
        if md.standard != crate::model_description::FmiStandard::Fmi2 {
            return Err(Error::InvalidArgument {
                function: "fmi2Instantiate",
                instance: instance_name.to_owned(),
                message: format!(
                    "model '{}' is an FMI {} FMU: instantiate it with tether_fmi::instantiate",
                    md.model_name, md.fmi_version
                ),
            });
        }
        let once = if md.co_simulation.can_be_instantiated_only_once_per_process {
            Some(OnceGuard::acquire(&md.guid, &md.model_name, instance_name)?)
        } else {
            None
        };
        let debug = debug_logging();
        let mut raw = RawComponent::fmi2Instantiate(
            self.shared.library()?,
            Arc::clone(&self.shared.dir),
            &InstantiateArgs {
                model: &md.model_name,
                instance_name,
                guid: &md.guid,
                resource_location: &self.resource_location(),
                visible: options.visible,
                logging_on: options.logging_on || debug.is_some(),
            },
        )?;
        raw.once = once;
        let mut instance = Instance::new(raw, Arc::clone(&self.shared));
        if let Some(wanted) = debug.filter(|c| !c.is_empty()) {
            let declared = &md.log_categories;
            let mut categories = Vec::new();
            for category in &wanted {
                if declared.is_empty() || declared.iter().any(|c| c.name == *category) {
                    categories.push(category.as_str());
                } else {
                    let names: Vec<&str> = declared.iter().map(|c| c.name.as_str()).collect();
                    log::warn!(
                        "model '{}' declares no log category '{category}' (it declares: {}); \
                         not asked of instance '{instance_name}'",
                        md.model_name,
                        names.join(", ")
                    );
                }
            }
            if !categories.is_empty() {
                instance.set_debug_logging(true, &categories)?;
            }
        }
        Ok(instance)
    }
}

/// What a path that is neither a regular file nor a folder is, for errors.
fn file_kind(metadata: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = metadata.file_type();
        if t.is_fifo() {
            return "FIFO";
        }
        if t.is_char_device() {
            return "character device";
        }
        if t.is_block_device() {
            return "block device";
        }
        if t.is_socket() {
            return "socket";
        }
    }
    let _ = metadata;
    "special file"
}
