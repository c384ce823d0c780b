//! Writing the `.fmu` (`tether fmu export`, `tether.export_fmu`): the model
//! description, the runtime library as `binaries/linux64/MODEL.so`, the
//! system file and each member FMU in `resources/`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use tether_master::{Simulation, SystemSpec};

use crate::description::{model_description, Capabilities};
use crate::SYSTEM_FILE;

/// What an export wrote.
pub struct Packaged {
    pub parameters: usize,
    pub inputs: usize,
    pub outputs: usize,
    /// Member FMU files in `resources/`.
    pub members: usize,
}

/// Export `spec` (read from `source`, named in messages) with its `[export]`
/// table as one FMU at `out`, whose binary is `runtime`; one line saying
/// what is wrong otherwise.
pub fn package(
    mut spec: SystemSpec,
    source: &str,
    runtime: &Path,
    out: &Path,
) -> Result<Packaged, String> {
    let Some(export) = spec.export.clone() else {
        return Err(format!(
            "system file {source}: no [export] table: it declares the exported FMU's model_name and variables (docs/fmu-export.md)"
        ));
    };
    // Resolve the interface against the FMUs, as the FMU's binary will.
    let sim = Simulation::new(&spec).map_err(|e| e.to_string())?;
    let variables = sim.export_interface(&spec).map_err(|e| e.to_string())?;
    let state = sim.can_save_state();
    let dependencies = sim.export_dependencies(&variables);
    drop(sim);
    // Member FMUs travel in resources/ under their file names (one copy of
    // each file; a name taken by another file gets a number).
    let mut members: BTreeMap<PathBuf, String> = BTreeMap::new();
    for instance in &mut spec.instances {
        if !instance.fmu.is_file() {
            return Err(format!(
                "instance '{}': {} is not an .fmu file (unpacked FMU folders are not exported)",
                instance.name,
                instance.fmu.display()
            ));
        }
        let path = instance.fmu.canonicalize().unwrap_or(instance.fmu.clone());
        let taken = members.len();
        let name = members
            .entry(path.clone())
            .or_insert_with(|| {
                let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
                let stem = stem.unwrap_or_else(|| "member".into());
                format!("{taken}_{stem}.fmu")
            })
            .clone();
        instance.fmu = PathBuf::from(name);
    }
    spec.source = None;
    let text = toml::to_string(&spec).map_err(|e| format!("cannot write the system file: {e}"))?;
    let xml = model_description(
        &spec,
        &text,
        &variables,
        &Capabilities {
            state,
            dependencies,
        },
    );
    let write = || -> Result<(), String> {
        let file = std::fs::File::create(out).map_err(|e| e.to_string())?;
        let mut zip = zip::ZipWriter::new(file);
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        let mut add = |name: String, bytes: &[u8], mode: u32| -> Result<(), String> {
            zip.start_file(name, options.unix_permissions(mode))
                .map_err(|e| e.to_string())?;
            zip.write_all(bytes).map_err(|e| e.to_string())
        };
        add("modelDescription.xml".into(), xml.as_bytes(), 0o644)?;
        let binary = std::fs::read(runtime)
            .map_err(|e| format!("cannot read the FMU runtime {}: {e}", runtime.display()))?;
        let name = format!("binaries/linux64/{}.so", export.model_name);
        add(name, &binary, 0o755)?;
        add(format!("resources/{SYSTEM_FILE}"), text.as_bytes(), 0o644)?;
        for (path, name) in &members {
            let bytes =
                std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
            add(format!("resources/{name}"), &bytes, 0o644)?;
        }
        zip.finish().map_err(|e| e.to_string())?;
        Ok(())
    };
    write().map_err(|e| format!("cannot write {}: {e}", out.display()))?;
    Ok(Packaged {
        parameters: export.parameters.len(),
        inputs: export.inputs.len(),
        outputs: export.outputs.len(),
        members: members.len(),
    })
}
