//! A system exported as one FMU: `tether.export_fmu`.

use super::*;
use crate::system::load_spec;

/// Export a system with an `[export]` table as one FMI 2.0 or 3.0 (`fmi`)
/// co-simulation FMU at `out`, its binary the runtime library `runtime`
/// (shipped in the package) and, for isolated members, the host program
/// `host` (shipped too); returns the numbers of parameters, inputs, outputs
/// and member FMU files.
#[pyfunction]
#[pyo3(signature = (out, runtime, host=None, path=None, text=None, fmi=2))]
pub(crate) fn export_fmu(
    py: Python<'_>,
    out: PathBuf,
    runtime: PathBuf,
    host: Option<PathBuf>,
    path: Option<PathBuf>,
    text: Option<&str>,
    fmi: u32,
) -> PyResult<(usize, usize, usize, usize)> {
    let source = match &path {
        None => "(text)".to_string(),
        Some(p) if tether_ssp::is_ssp(p) => tether_ssp::ssd_name(p),
        Some(p) => p.display().to_string(),
    };
    let fmi = tether_fmu_export::package::FmiVersion::from_number(fmi)
        .map_err(|e| failure("settings", e, None))?;
    // `_ssp` keeps an extracted archive's FMUs until they are packed.
    let (spec, _ssp) = load_spec(path, text, None)?;
    let packaged = py
        .detach(move || {
            let programs = tether_fmu_export::package::Programs {
                runtime: &runtime,
                host: host.as_deref(),
            };
            tether_fmu_export::package::package(spec, &source, &programs, &out, fmi)
        })
        .map_err(|e| failure("settings", e, None))?;
    Ok((
        packaged.parameters,
        packaged.inputs,
        packaged.outputs,
        packaged.members,
    ))
}
