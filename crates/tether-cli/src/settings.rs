//! Flags that change a system file's time grid and coupling method, shared by
//! `tether run` and `tether sweep`.

use anyhow::{bail, Result};
use tether_master::{Method, SystemSpec};

#[derive(clap::Args, Debug, Clone)]
pub struct Settings {
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
    /// Perturbed runs on other threads: auto (only when it pays), on or off
    /// (overrides [coupling] parallel).
    #[arg(long, value_parser = ["auto", "on", "off"])]
    parallel: Option<String>,
}

impl Settings {
    /// Apply the flags that were given to a system.
    pub fn apply(&self, spec: &mut SystemSpec) -> Result<()> {
        let args = self;
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
        if let Some(parallel) = &args.parallel {
            spec.coupling.parallel = parallel.parse().map_err(anyhow::Error::msg)?;
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
}
