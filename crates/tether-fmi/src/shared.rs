//! What sits below the raw layer and is shared upwards: [`FmuShared`], the parts every
//! instance of an FMU holds on to, and [`OnceGuard`], the process-wide registry of
//! `canBeInstantiatedOnlyOncePerProcess` instances that a raw component keeps alive.
//!
//! Nothing here calls into the FMU, so [`crate::raw`], [`crate::instance`] and
//! [`crate::fmu`] can all depend on it without a circle.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use crate::archive::FmuDir;
use crate::error::{Error, Result};
use crate::library::Library;
use crate::model_description::ModelDescription;
use crate::raw::fmi3::Fmi3Functions;

/// What every instance of an FMU shares: the files, the description, the code.
#[derive(Debug)]
pub(crate) struct FmuShared {
    pub origin: PathBuf,
    pub dir: Arc<FmuDir>,
    pub model_description: ModelDescription,
    /// `binaries/linux64/<modelIdentifier>.so` (FMI 3.0: `binaries/x86_64-linux/…`).
    pub so: PathBuf,
    /// The loaded library; `None` until the first instance in this process
    /// when opened with [`Fmu::open_unloaded`](crate::Fmu::open_unloaded).
    pub library: Mutex<Option<Arc<Library>>>,
    /// The loaded library of an FMI 3.0 FMU, as `library` for FMI 2.0.
    pub library3: Mutex<Option<Arc<Library<Fmi3Functions>>>>,
}

impl FmuShared {
    /// The library, loaded now if it was not yet.
    pub(crate) fn library(&self) -> Result<Arc<Library>> {
        let mut library = self
            .library
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(library) = &*library {
            return Ok(Arc::clone(library));
        }
        let co_simulation = self.model_description.co_simulation.is_some();
        let loaded = Arc::new(Library::load(&self.so, co_simulation)?);
        *library = Some(Arc::clone(&loaded));
        Ok(loaded)
    }

    /// The FMI 3.0 library, loaded now if it was not yet.
    pub(crate) fn library3(&self) -> Result<Arc<Library<Fmi3Functions>>> {
        let mut library = self
            .library3
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(library) = &*library {
            return Ok(Arc::clone(library));
        }
        let co_simulation = self.model_description.co_simulation.is_some();
        let loaded = Arc::new(Library::<Fmi3Functions>::load(&self.so, co_simulation)?);
        *library = Some(Arc::clone(&loaded));
        Ok(loaded)
    }

    /// Loads the library of the FMU's standard (checks it, once).
    pub(crate) fn load(&self) -> Result<()> {
        match self.model_description.standard {
            crate::model_description::FmiStandard::Fmi2 => self.library().map(drop),
            crate::model_description::FmiStandard::Fmi3 => self.library3().map(drop),
        }
    }
}

/// The live instances of models declaring `canBeInstantiatedOnlyOncePerProcess`:
/// GUID → instance name.
static ONCE_PER_PROCESS: Mutex<Vec<(String, String)>> = Mutex::new(Vec::new());

/// Marks the one live instance of a once-per-process model; released on drop.
#[derive(Debug)]
pub(crate) struct OnceGuard {
    guid: String,
}

impl OnceGuard {
    pub(crate) fn acquire(guid: &str, model: &str, instance: &str) -> Result<OnceGuard> {
        let mut live = ONCE_PER_PROCESS
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, existing)) = live.iter().find(|(g, _)| g == guid) {
            return Err(Error::OnlyOncePerProcess {
                model: model.to_owned(),
                instance: instance.to_owned(),
                existing: existing.clone(),
            });
        }
        live.push((guid.to_owned(), instance.to_owned()));
        Ok(OnceGuard {
            guid: guid.to_owned(),
        })
    }
}

impl Drop for OnceGuard {
    fn drop(&mut self) {
        let mut live = ONCE_PER_PROCESS
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(i) = live.iter().position(|(g, _)| *g == self.guid) {
            live.swap_remove(i);
        }
    }
}
