//! SSP on the command line: `tether ssp export` / `tether ssp import`
//! (docs/ssp.md). `tether run` and `tether fmu export` read `.ssp`, `.ssd` and
//! SSP folders through [`tether_ssp::load`].

use std::path::PathBuf;

use anyhow::{Context, Result};
use tether_master::SystemSpec;

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
            let loaded = tether_ssp::read(&ssp, step, stop)?;
            for note in &loaded.notes {
                crate::say!("note: {note}");
            }
            tether_ssp::write_toml(&loaded, &out)
                .with_context(|| format!("importing {}", ssp.display()))?;
        }
    }
    Ok(())
}
