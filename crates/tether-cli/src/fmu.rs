//! `tether fmu export`: the coupled system as one FMI 2.0 co-simulation FMU
//! (docs/fmu-export.md). The FMU's binary is the `tether-fmu-export`
//! cdylib, found next to the `tether` binary; the system file and the member
//! FMUs go to `resources/`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use tether_master::{Simulation, SystemSpec};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Export a system file as one FMI 2.0 co-simulation FMU (linux64), its
    /// interface declared by the file's [export] table.
    Export {
        /// The system file (TOML) with an [export] table.
        system: PathBuf,
        /// The .fmu file to write.
        #[arg(long, short)]
        out: PathBuf,
    },
}

pub fn main(args: Args) -> Result<()> {
    match args.command {
        Command::Export { system, out } => export(&system, &out),
    }
}

/// The runtime library, built by the workspace next to the `tether` binary.
fn runtime_library() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find the tether binary's folder")?;
    let dir = exe.parent().unwrap_or(Path::new("."));
    let name = "libtether_fmu_export.so";
    [dir.join(name), dir.join("deps").join(name)]
        .into_iter()
        .find(|p| p.is_file())
        .with_context(|| {
            format!(
                "the FMU runtime {name} is not next to the tether binary in {} \
                 (build it with `cargo build --release -p tether-fmu-export`)",
                dir.display()
            )
        })
}

fn export(system: &Path, out: &Path) -> Result<()> {
    let mut spec = SystemSpec::from_file(system)?;
    let Some(export) = spec.export.clone() else {
        bail!(
            "system file {}: no [export] table: it declares the exported FMU's model_name and variables (docs/fmu-export.md)",
            system.display()
        );
    };
    if spec.step_control.is_some() {
        bail!(
            "system file {}: [step_control]: systems with adaptive steps are not exported (fixed macro steps only)",
            system.display()
        );
    }
    let runtime = runtime_library()?;
    // Resolve the interface against the FMUs, as the FMU's binary will.
    let sim = Simulation::new(&spec)?;
    let variables = sim.export_interface(&spec)?;
    let can_save = sim.can_save_state();
    drop(sim);
    // Member FMUs travel in resources/ under their file names (one copy of
    // each file; a name taken by another file gets a number).
    let mut members: BTreeMap<PathBuf, String> = BTreeMap::new();
    for instance in &mut spec.instances {
        if !instance.fmu.is_file() {
            bail!(
                "instance '{}': {} is not an .fmu file (unpacked FMU folders are not exported)",
                instance.name,
                instance.fmu.display()
            );
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
    let text = toml::to_string(&spec).context("cannot write the system file")?;
    let xml = tether_fmu_export::description::model_description(
        &spec,
        &text,
        &variables,
        &tether_fmu_export::description::Capabilities { state: can_save },
    );
    let write = || -> Result<()> {
        let file = std::fs::File::create(out)?;
        let mut zip = zip::ZipWriter::new(file);
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        zip.start_file("modelDescription.xml", options)?;
        zip.write_all(xml.as_bytes())?;
        let binary = format!("binaries/linux64/{}.so", export.model_name);
        zip.start_file(binary, options.unix_permissions(0o755))?;
        zip.write_all(&std::fs::read(&runtime)?)?;
        zip.start_file(
            format!("resources/{}", tether_fmu_export::SYSTEM_FILE),
            options,
        )?;
        zip.write_all(text.as_bytes())?;
        for (path, name) in &members {
            let bytes =
                std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
            zip.start_file(format!("resources/{name}"), options)?;
            zip.write_all(&bytes)?;
        }
        zip.finish()?;
        Ok(())
    };
    write().with_context(|| format!("cannot write {}", out.display()))?;
    crate::say!(
        "wrote {} ({} parameters, {} inputs, {} outputs; {} member FMU files)",
        out.display(),
        export.parameters.len(),
        export.inputs.len(),
        export.outputs.len(),
        members.len()
    );
    Ok(())
}
