//! Workspace tasks.
//!
//! - `cargo xtask fmus`: build and package every FMU under `fmus/`; prints the paths.
//! - `cargo xtask tether <args…>` (alias `cargo tether <args…>`): package the FMUs,
//!   then `cargo run --release -q -p tether-cli -- <args…>` in the caller's directory;
//!   the first time (no `target/release/tether` or FMU yet) it says so and shows
//!   cargo's progress.
//! - `cargo xtask figures`: package the FMUs, then run every study file in
//!   `docs/figures/studies/` with `tether study`, writing `docs/figures/`
//!   (the analogues of the paper's figures; docs/paper-reproduction.md).

use std::process::Command;

use anyhow::{bail, Context, Result};

/// The first build's duration on 2 cores with a warm crates.io cache (the
/// tether command in release mode and the workspace FMUs), for the message
/// before it: the README's run command took 169 s from a fresh clone on an
/// idle machine (`tools/clean-clone.sh run`).
const FIRST_BUILD: &str = "about 3 minutes on 2 cores";

/// `cargo run --release -p tether-cli -- <args>`, in `dir` if given; the exit
/// code. Quiet once the tether command is built; its first build shows cargo's
/// progress.
fn tether(args: &[String], dir: Option<&std::path::Path>, first: bool) -> Result<i32> {
    let root = tether_fmu_build::workspace_root()?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut command = Command::new(&cargo);
    command
        .arg("run")
        .arg("--manifest-path")
        .arg(root.join("Cargo.toml"))
        .args(["--release", "-p", "tether-cli"]);
    if !first {
        command.arg("-q");
    }
    command.arg("--").args(args);
    if let Some(dir) = dir {
        command.current_dir(dir);
    }
    let status = command
        .status()
        .context("running `cargo run -p tether-cli`")?;
    Ok(status.code().unwrap_or(1))
}

/// Whether the tether command or a workspace FMU is not built yet.
fn first_build() -> Result<bool> {
    let root = tether_fmu_build::workspace_root()?;
    Ok(first_build_in(
        &root,
        &tether_fmu_build::workspace_fmu_names()?,
    ))
}

/// Whether `root/target` lacks the release tether command or one of the FMUs.
fn first_build_in(root: &std::path::Path, fmus: &[String]) -> bool {
    let exe = root
        .join("target/release")
        .join(format!("tether{}", std::env::consts::EXE_SUFFIX));
    let packaged = fmus
        .iter()
        .all(|n| root.join("target/fmus").join(format!("{n}.fmu")).is_file());
    !exe.is_file() || !packaged
}

/// What `cargo tether` says before its first build.
fn first_build_notice() -> String {
    format!(
        "cargo tether: building the tether command and the workspace FMUs in release mode, \
         once ({FIRST_BUILD}); cargo's progress follows, later runs start at once"
    )
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
            let first = first_build()?;
            if first {
                eprintln!("{}", first_build_notice());
                tether_fmu_build::show_build_progress(true);
            }
            tether_fmu_build::workspace_fmus().context("packaging the workspace FMUs")?;
            std::process::exit(tether(&args[1..], None, first)?);
        }
        Some("figures") => {
            tether_fmu_build::show_build_progress(first_build()?);
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
            let first = first_build()?;
            std::process::exit(tether(&tether_args, Some(&root), first)?);
        }
        _ => bail!(
            "usage: cargo xtask fmus | cargo xtask figures [STUDY…] | cargo tether <tether arguments…>"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_build_is_announced_until_the_command_and_the_fmus_are_built() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        let fmus = vec!["oscillator".to_string()];
        assert!(first_build_in(root, &fmus));
        std::fs::create_dir_all(root.join("target/release")).unwrap();
        std::fs::write(root.join("target/release/tether"), b"").unwrap();
        assert!(first_build_in(root, &fmus), "the FMUs are missing");
        std::fs::create_dir_all(root.join("target/fmus")).unwrap();
        std::fs::write(root.join("target/fmus/oscillator.fmu"), b"").unwrap();
        assert!(!first_build_in(root, &fmus));
        assert_eq!(
            first_build_notice(),
            "cargo tether: building the tether command and the workspace FMUs in release mode, \
             once (about 3 minutes on 2 cores); cargo's progress follows, later runs start at once"
        );
    }
}
