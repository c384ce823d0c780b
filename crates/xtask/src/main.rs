//! Workspace tasks.
//!
//! - `cargo xtask fmus`: build and package every FMU under `fmus/`; prints the paths.
//! - `cargo xtask tether <args…>` (alias `cargo tether <args…>`): package the FMUs,
//!   then `cargo run --release -q -p tether-cli -- <args…>` in the caller's directory.

use std::process::Command;

use anyhow::{bail, Context, Result};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("fmus") => {
            for fmu in tether_fmu_build::workspace_fmus().context("packaging the workspace FMUs")? {
                println!("{}", fmu.display());
            }
            Ok(())
        }
        Some("tether") => {
            tether_fmu_build::workspace_fmus().context("packaging the workspace FMUs")?;
            let root = tether_fmu_build::workspace_root()?;
            let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
            let manifest = root.join("Cargo.toml");
            let status = Command::new(&cargo)
                .arg("run")
                .arg("--manifest-path")
                .arg(&manifest)
                .args(["--release", "-q", "-p", "tether-cli", "--"])
                .args(&args[1..])
                .status()
                .context("running `cargo run -p tether-cli`")?;
            std::process::exit(status.code().unwrap_or(1));
        }
        _ => bail!("usage: cargo xtask fmus | cargo tether <tether arguments…>"),
    }
}
