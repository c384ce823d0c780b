//! `tether fmu export`: the coupled system as one FMI 2.0 or FMI 3.0
//! co-simulation FMU (docs/fmu-export.md). The FMU's binary is the
//! `tether-fmu-export` cdylib, found next to the `tether` binary; the system
//! file and the member FMUs go to `resources/`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use tether_fmu_export::package::{FmiVersion, Programs};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Export a system as one FMI 2.0 or 3.0 co-simulation FMU (64-bit
    /// Linux), its interface declared by the file's [export] table (an SSP
    /// system without one: its top-level connectors).
    Export {
        /// The system file (TOML) with an [export] table, or SSP (.ssp, .ssd
        /// or a folder).
        system: PathBuf,
        /// The .fmu file to write.
        #[arg(long, short)]
        out: PathBuf,
        /// The FMI version of the FMU: 2 (FMI 2.0) or 3 (FMI 3.0).
        #[arg(long, default_value_t = 2)]
        fmi: u32,
    },
}

pub fn main(args: Args) -> Result<()> {
    match args.command {
        Command::Export { system, out, fmi } => export(&system, &out, fmi),
    }
}

/// The runtime library, built by the workspace next to the `tether` binary.
fn runtime_library() -> Result<PathBuf> {
    let name = "libtether_fmu_export.so";
    let dir = tether_folder()?;
    beside_tether(name)?.with_context(|| {
        format!(
            "the FMU runtime {name} is not next to the tether binary in {} \
                 (build it with `cargo build --release -p tether-fmu-export`)",
            dir.display()
        )
    })
}

/// The folder of the `tether` binary.
fn tether_folder() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find the tether binary's folder")?;
    Ok(exe.parent().unwrap_or(Path::new(".")).to_path_buf())
}

/// The file `name` next to the `tether` binary or in `deps/` there (where
/// cargo builds a library a test binary depends on), the newer of the two,
/// if it is there.
fn beside_tether(name: &str) -> Result<Option<PathBuf>> {
    let dir = tether_folder()?;
    let modified = |p: &PathBuf| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    Ok([dir.join(name), dir.join("deps").join(name)]
        .into_iter()
        .filter(|p| p.is_file())
        .max_by_key(modified))
}

fn export(system: &Path, out: &Path, fmi: u32) -> Result<()> {
    let fmi = FmiVersion::from_number(fmi).map_err(anyhow::Error::msg)?;
    crate::output::not_an_input(out, std::iter::once(system))?;
    // `_ssp` keeps an extracted archive's FMUs until they are packed.
    let (spec, _ssp) = tether_ssp::load(system, None, None)?;
    let runtime = runtime_library()?;
    let source = match &_ssp {
        Some(_) => tether_ssp::ssd_name(system),
        None => system.display().to_string(),
    };
    // The host program of isolated members: the dedicated one built with the
    // workspace, unless it is older than this binary (then perhaps of
    // another protocol version): this binary itself, which serves as a host
    // under that name.
    let exe = std::env::current_exe().context("cannot find the tether binary")?;
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    let host = beside_tether(tether_fmi::remote::HOST_NAME)?
        .filter(|h| modified(h) >= modified(&exe))
        .unwrap_or(exe);
    let programs = Programs {
        runtime: &runtime,
        host: Some(&host),
    };
    let packaged = tether_fmu_export::package::package(spec, &source, &programs, out, fmi)
        .map_err(anyhow::Error::msg)?;
    crate::say!(
        "wrote {} ({} parameters, {} inputs, {} outputs; {} member FMU files)",
        out.display(),
        packaged.parameters,
        packaged.inputs,
        packaged.outputs,
        packaged.members
    );
    Ok(())
}
