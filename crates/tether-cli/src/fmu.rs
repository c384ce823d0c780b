//! `tether fmu export`: the coupled system as one FMI 2.0 co-simulation FMU
//! (docs/fmu-export.md). The FMU's binary is the `tether-fmu-export`
//! cdylib, found next to the `tether` binary; the system file and the member
//! FMUs go to `resources/`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use tether_master::SystemSpec;

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
    let spec = SystemSpec::from_file(system)?;
    let runtime = runtime_library()?;
    let source = system.display().to_string();
    let packaged = tether_fmu_export::package::package(spec, &source, &runtime, out)
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
