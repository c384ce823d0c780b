//! SSP on the command line: `tether run` of `.ssp`, `.ssd` and SSP folders,
//! and `tether ssp export` / `tether ssp import` (docs/ssp.md).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use tether_master::SystemSpec;
use tether_ssp::Loaded;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Write a system file as an SSP archive (FMUs under resources/,
    /// constraints and the method in Tether's annotation).
    Export {
        /// The system file (TOML).
        system: PathBuf,
        /// The .ssp archive to write.
        #[arg(long, short)]
        out: PathBuf,
    },
    /// Write an SSP system (.ssp, .ssd or folder) as a system file, its FMUs
    /// copied to resources/ next to it.
    Import {
        /// The .ssp archive, SystemStructure.ssd or unpacked folder.
        ssp: PathBuf,
        /// The system file (TOML) to write.
        #[arg(long, short)]
        out: PathBuf,
        /// Macro-step size H, if the SSP has no Tether annotation giving it.
        #[arg(long)]
        step: Option<f64>,
        /// Stop time, if the SSP's DefaultExperiment has none.
        #[arg(long)]
        stop: Option<f64>,
    },
}

/// Whether `path` is SSP rather than a system file: a folder, `.ssp` or `.ssd`.
pub fn is_ssp(path: &Path) -> bool {
    path.is_dir()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ssp") || e.eq_ignore_ascii_case("ssd"))
}

/// Read a system file or SSP (the latter kept alive by the returned
/// [`Loaded`], which owns an extracted archive). Skipped annotations of
/// other tools are logged (`-v`).
pub fn load(
    path: &Path,
    step: Option<f64>,
    stop: Option<f64>,
) -> Result<(SystemSpec, Option<Loaded>)> {
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

fn read(path: &Path, step: Option<f64>, stop: Option<f64>) -> Result<Loaded> {
    let loaded = tether_ssp::read(path, step, stop)?;
    for skipped in &loaded.skipped {
        log::info!("skipped another tool's annotation {skipped}");
    }
    Ok(loaded)
}

pub fn main(args: Args) -> Result<()> {
    match args.command {
        Command::Export { system, out } => {
            crate::output::not_an_input(&out, std::iter::once(system.as_path()))?;
            let spec = SystemSpec::from_file(&system)?;
            tether_ssp::write(&spec, &out)
                .with_context(|| format!("exporting {}", system.display()))?;
        }
        Command::Import {
            ssp,
            out,
            step,
            stop,
        } => {
            crate::output::not_an_input(&out, std::iter::once(ssp.as_path()))?;
            let loaded = read(&ssp, step, stop)?;
            tether_ssp::write_toml(&loaded, &out)
                .with_context(|| format!("importing {}", ssp.display()))?;
        }
    }
    Ok(())
}
