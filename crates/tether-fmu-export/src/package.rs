//! Writing the `.fmu` (`tether fmu export`, `tether.export_fmu`): the model
//! description, the runtime library as `binaries/linux64/MODEL.so` (FMI 2.0)
//! or `binaries/x86_64-linux/MODEL.so` (FMI 3.0), the system file and each
//! member FMU in `resources/`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use tether_fmi::remote::HOST_NAME;
use tether_master::spec::Isolation;
use tether_master::{Simulation, SystemSpec};

use crate::description::{model_description, model_description_fmi3, Capabilities};
use crate::SYSTEM_FILE;

/// The FMI version of an exported FMU. One runtime library serves both: it
/// has the fmi2 and the fmi3 functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FmiVersion {
    #[default]
    Fmi2,
    Fmi3,
}

impl FmiVersion {
    /// `2` or `3`; anything else is one line saying so.
    pub fn from_number(n: u32) -> Result<FmiVersion, String> {
        match n {
            2 => Ok(FmiVersion::Fmi2),
            3 => Ok(FmiVersion::Fmi3),
            _ => Err(format!(
                "FMI version {n}: an exported FMU is FMI 2 (2.0) or FMI 3 (3.0)"
            )),
        }
    }

    /// The folder of the binary for 64-bit Linux.
    fn platform(self) -> &'static str {
        match self {
            FmiVersion::Fmi2 => "linux64",
            FmiVersion::Fmi3 => "x86_64-linux",
        }
    }
}

/// What an export wrote.
pub struct Packaged {
    pub parameters: usize,
    pub inputs: usize,
    pub outputs: usize,
    /// Member FMU files in `resources/`.
    pub members: usize,
}

/// The programs an exported FMU carries: the runtime library (its binary)
/// and, for a system with isolated members, the host program
/// (`tether-fmi-host`, which goes to `resources/`).
pub struct Programs<'a> {
    pub runtime: &'a Path,
    pub host: Option<&'a Path>,
}

/// Export `spec` (read from `source`, named in messages) with its `[export]`
/// table as one FMU of version `fmi` at `out` carrying `programs`; one line
/// saying what is wrong otherwise.
pub fn package(
    mut spec: SystemSpec,
    source: &str,
    programs: &Programs,
    out: &Path,
    fmi: FmiVersion,
) -> Result<Packaged, String> {
    let runtime = programs.runtime;
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
    // Isolated members run in the host program, which travels in resources/.
    let isolated = spec
        .instances
        .iter()
        .find(|i| i.isolation == Isolation::Process && i.host.is_none());
    let host = match (isolated, programs.host) {
        (None, _) => None,
        (Some(_), Some(host)) => Some(
            std::fs::read(host)
                .map_err(|e| format!("cannot read the host program {}: {e}", host.display()))?,
        ),
        (Some(instance), None) => {
            return Err(format!(
                "instance '{}' runs isolated (isolation = \"process\"): the exported FMU carries the host \
                 program {HOST_NAME}, which was not found (`tether fmu export` takes it from the tether \
                 binary's folder: `cargo build --release -p tether-fmi-host`; `tether.export_fmu` from the \
                 package, installed by tools/install-python.sh)",
                instance.name
            ))
        }
    };
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
    let capabilities = Capabilities {
        state,
        dependencies,
    };
    let xml = match fmi {
        FmiVersion::Fmi2 => model_description(&spec, &text, &variables, &capabilities),
        FmiVersion::Fmi3 => model_description_fmi3(&spec, &text, &variables, &capabilities),
    };
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
        let name = format!("binaries/{}/{}.so", fmi.platform(), export.model_name);
        add(name, &binary, 0o755)?;
        add(format!("resources/{SYSTEM_FILE}"), text.as_bytes(), 0o644)?;
        if let Some(host) = &host {
            add(format!("resources/{HOST_NAME}"), host, 0o755)?;
        }
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
