//! The settings of a model-exchange instance's built-in integrator
//! ([`crate::MeInstance`]): its method and tolerances, plain data that
//! instantiation options carry (also to a host process).

/// The integration method of a model-exchange instance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Variable-order BDF (NDF) with a Newton iteration, for stiff models
    /// (`diffsol::Bdf`).
    #[default]
    Bdf,
    /// The ESDIRK34 singly diagonally implicit Runge–Kutta method, order 3
    /// with an embedded error estimate (`diffsol::Sdirk`).
    Esdirk,
    /// Dormand–Prince 5(4) with error control (`ode_solvers::Dopri5`).
    Rk45,
    /// Dormand–Prince 8(5,3) with error control (`ode_solvers::Dop853`).
    Dop853,
}

impl Method {
    /// Every method by its key name.
    pub const ALL: [(&'static str, Method); 4] = [
        ("bdf", Method::Bdf),
        ("esdirk", Method::Esdirk),
        ("rk45", Method::Rk45),
        ("dop853", Method::Dop853),
    ];

    /// The method called `name` (`bdf`, `esdirk`, `rk45`, `dop853`).
    pub fn parse(name: &str) -> Option<Method> {
        Method::ALL
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, m)| m)
    }

    /// The key name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Bdf => "bdf",
            Method::Esdirk => "esdirk",
            Method::Rk45 => "rk45",
            Method::Dop853 => "dop853",
        }
    }
}

/// The integrator settings of a model-exchange instance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Integrator {
    /// The method.
    pub method: Method,
    /// Relative tolerance (default: the experiment's tolerance, else the
    /// model's DefaultExperiment tolerance, else 1e-6).
    pub rtol: Option<f64>,
    /// Absolute tolerance, relative to each state's nominal: state i is held
    /// to `atol · nominal_i` (default: `rtol`).
    pub atol: Option<f64>,
    /// The largest step (default: the communication step).
    pub max_step: Option<f64>,
}

impl Integrator {
    /// Checks the settings: every tolerance and the largest step finite and
    /// positive; the error names the key.
    pub fn check(&self) -> std::result::Result<(), String> {
        for (key, value) in [
            ("rtol", self.rtol),
            ("atol", self.atol),
            ("max_step", self.max_step),
        ] {
            if let Some(v) = value {
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!("{key} = {v}: expected a finite number > 0"));
                }
            }
        }
        Ok(())
    }
}
