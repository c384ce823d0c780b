//! Workspace tasks.
//!
//! - `cargo xtask fmus`: build and package every FMU under `fmus/`; prints the paths.
//! - `cargo xtask tether <args…>` (alias `cargo tether <args…>`): package the FMUs,
//!   then `cargo run --release -q -p tether-cli -- <args…>` in the caller's directory.
//! - `cargo xtask figures`: package the FMUs, then run every study file in
//!   `docs/figures/studies/` with `tether study`, writing `docs/figures/`
//!   (the analogues of the paper's figures; docs/paper-reproduction.md).

use std::process::Command;

use anyhow::{bail, Context, Result};

/// `cargo run --release -q -p tether-cli -- <args>`, in `dir` if given; the exit code.
fn tether(args: &[String], dir: Option<&std::path::Path>) -> Result<i32> {
    let root = tether_fmu_build::workspace_root()?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut command = Command::new(&cargo);
    command
        .arg("run")
        .arg("--manifest-path")
        .arg(root.join("Cargo.toml"))
        .args(["--release", "-q", "-p", "tether-cli", "--"])
        .args(args);
    if let Some(dir) = dir {
        command.current_dir(dir);
    }
    let status = command
        .status()
        .context("running `cargo run -p tether-cli`")?;
    Ok(status.code().unwrap_or(1))
}

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
            std::process::exit(tether(&args[1..], None)?);
        }
        Some("figures") => {
            tether_fmu_build::workspace_fmus().context("packaging the workspace FMUs")?;
            let root = tether_fmu_build::workspace_root()?;
            let dir = root.join("docs/figures/studies");
            let mut studies: Vec<String> = std::fs::read_dir(&dir)
                .with_context(|| format!("reading {}", dir.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "toml"))
                .map(|p| p.display().to_string())
                .collect();
            studies.sort();
            // Only the named studies when given: `cargo xtask figures fig05 fig07`.
            let only = &args[1..];
            if !only.is_empty() {
                studies.retain(|s| only.iter().any(|o| s.ends_with(&format!("/{o}.toml"))));
                if studies.is_empty() {
                    bail!("no study file in {} matches {only:?}", dir.display());
                }
            }
            let mut tether_args = vec!["study".to_string(), "--out-dir".to_string()];
            tether_args.push(root.join("docs/figures").display().to_string());
            tether_args.extend(studies);
            std::process::exit(tether(&tether_args, Some(&root))?);
        }
        _ => bail!(
            "usage: cargo xtask fmus | cargo xtask figures [STUDY…] | cargo tether <tether arguments…>"
        ),
    }
}
