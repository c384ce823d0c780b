//! `tether run SYSTEM.toml`: the coupled co-simulation.

use std::fs::File;
use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use tether_master::{CsvRecorder, Method, Simulation, SystemSpec};

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// The system file (TOML), see docs/system-file.md.
    system: PathBuf,
    /// Stop time (overrides [experiment] stop).
    #[arg(long)]
    stop: Option<f64>,
    /// Macro-step size H (overrides [experiment] step).
    #[arg(long)]
    step: Option<f64>,
    /// Coupling method (overrides [method] kind).
    #[arg(long, value_parser = ["baumgarte", "weighted", "explicit"])]
    method: Option<String>,
    /// Baumgarte velocity weight β (method baumgarte).
    #[arg(long)]
    beta: Option<f64>,
    /// Baumgarte acceleration weight γ (method baumgarte).
    #[arg(long)]
    gamma: Option<f64>,
    /// Velocity-level weight a (method weighted).
    #[arg(long)]
    a: Option<f64>,
    /// Acceleration-level weight b (method weighted).
    #[arg(long)]
    b: Option<f64>,
    /// Stabilisation constant μ_B (method explicit).
    #[arg(long)]
    mu: Option<f64>,
    /// Degree k of the coupling polynomials: 0, 1 or 2.
    #[arg(long)]
    order: Option<usize>,
    /// Finite-difference increment ε for the interface Jacobian.
    #[arg(long)]
    epsilon: Option<f64>,
    /// Output CSV file (default: the system file's name with .csv, in the current directory).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Do not print the run summary.
    #[arg(long, short)]
    quiet: bool,
}

pub fn main(args: Args) -> Result<()> {
    crate::interrupt::install()?;
    let mut spec = SystemSpec::from_file(&args.system)?;
    apply_overrides(&mut spec, &args)?;
    let out = match &args.out {
        Some(p) => p.clone(),
        None => PathBuf::from(
            args.system
                .file_stem()
                .map(|s| format!("{}.csv", s.to_string_lossy()))
                .unwrap_or_else(|| "results.csv".into()),
        ),
    };
    let mut sim = Simulation::new(&spec)?;
    let file = File::create(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut recorder = CsvRecorder::new(file);
    let steps = sim.total_steps();
    let bar = (std::io::stderr().is_terminal() && steps >= 20_000 && !args.quiet).then(|| {
        let bar = indicatif::ProgressBar::new(steps);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {eta} left")
                .expect("valid template"),
        );
        bar
    });
    let mut progress = |n: u64, _total: u64| {
        if let Some(bar) = &bar {
            if n.is_multiple_of(256) {
                bar.set_position(n);
            }
        }
    };
    let outcome = sim.run(
        &mut [&mut recorder, &mut crate::interrupt::Watch],
        &mut progress,
    );
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    if !args.quiet {
        let name = spec.name.as_deref().unwrap_or("system");
        eprintln!(
            "{name}: {} with k = {}, H = {}, t = {} … {}",
            spec.method,
            spec.coupling.order,
            spec.experiment.step,
            spec.experiment.start,
            sim.time()
        );
        eprintln!("{}", sim.stats());
    }
    match outcome {
        Ok(_) => {
            if !args.quiet {
                eprintln!("results: {}", out.display());
            }
            Ok(())
        }
        Err(e) => Err(anyhow::Error::new(e).context(format!(
            "run stopped; results up to t = {} kept in {} (marked incomplete)",
            sim.time(),
            out.display()
        ))),
    }
}

fn apply_overrides(spec: &mut SystemSpec, args: &Args) -> Result<()> {
    if let Some(stop) = args.stop {
        spec.experiment.stop = stop;
    }
    if let Some(step) = args.step {
        spec.experiment.step = step;
    }
    if let Some(order) = args.order {
        spec.coupling.order = order;
    }
    if let Some(eps) = args.epsilon {
        spec.coupling.epsilon = eps;
    }
    let kind = args.method.as_deref().unwrap_or(spec.method.name());
    let current = spec.method;
    spec.method = match kind {
        "baumgarte" => {
            let (beta, gamma) = match current {
                Method::Baumgarte { beta, gamma } => (beta, gamma),
                _ => (0.0, 0.0),
            };
            Method::Baumgarte {
                beta: args.beta.unwrap_or(beta),
                gamma: args.gamma.unwrap_or(gamma),
            }
        }
        "weighted" => {
            let (a, b) = match current {
                Method::Weighted { a, b } => (a, b),
                _ => (0.0, 0.0),
            };
            Method::Weighted {
                a: args.a.unwrap_or(a),
                b: args.b.unwrap_or(b),
            }
        }
        _ => {
            let mu = match current {
                Method::Explicit { mu } => Some(mu),
                _ => None,
            };
            match args.mu.or(mu) {
                Some(mu) => Method::Explicit { mu },
                None => bail!("method explicit needs --mu (or mu in [method])"),
            }
        }
    };
    let misplaced = [
        ("--beta", args.beta.is_some(), "baumgarte"),
        ("--gamma", args.gamma.is_some(), "baumgarte"),
        ("--a", args.a.is_some(), "weighted"),
        ("--b", args.b.is_some(), "weighted"),
        ("--mu", args.mu.is_some(), "explicit"),
    ];
    for (flag, given, method) in misplaced {
        if given && spec.method.name() != method {
            bail!(
                "{flag} applies to method {method}, but the method is {}",
                spec.method.name()
            );
        }
    }
    Ok(())
}
