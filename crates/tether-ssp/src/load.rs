//! One loader for a system given by path, a system file or SSP: `tether
//! run`, `tether fmu export` and the Python package (`tether.run`,
//! `tether.Simulation`, `tether.export_fmu`) all read through [`load`].

use std::path::Path;

use tether_master::SystemSpec;

use crate::{read, Loaded, SspError};

/// Whether `path` is SSP rather than a system file: a folder, `.ssp` or `.ssd`.
pub fn is_ssp(path: &Path) -> bool {
    path.is_dir()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ssp") || e.eq_ignore_ascii_case("ssd"))
}

/// Read a system file or SSP (`.ssp`, `.ssd` or a folder). For SSP the
/// returned [`Loaded`] owns an extracted archive: keep it while the system's
/// FMUs are used (the run, the packing of an exported FMU). `step` and `stop`
/// are those of [`read`] (for SSP only: a system file has its own).
pub fn load(
    path: &Path,
    step: Option<f64>,
    stop: Option<f64>,
) -> Result<(SystemSpec, Option<Loaded>), SspError> {
    if !is_ssp(path) {
        return Ok((SystemSpec::from_file(path)?, None));
    }
    let loaded = read(path, step, stop)?;
    Ok((loaded.spec.clone(), Some(loaded)))
}

/// Where an SSP system's names are written, for messages: `SystemStructure.ssd`
/// (a folder or the file itself), `system.ssp, SystemStructure.ssd` (an archive).
pub fn ssd_name(path: &Path) -> String {
    let archive = path.is_file()
        && path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ssp"));
    if archive {
        format!("{}, SystemStructure.ssd", path.display())
    } else if path.is_file() {
        path.display().to_string()
    } else {
        path.join("SystemStructure.ssd").display().to_string()
    }
}
