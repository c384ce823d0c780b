//! Evaluating coupling rows: where the values come from ([`View`]), which
//! level a row evaluates ([`RowLevel`]) and linear rows ([`Level`]).

/// Where row values come from: the coupled outputs of every instance at the
/// point evaluated and the unknowns `u`; for a finite-difference column, the
/// instances one perturbed run stepped read that run's outputs, and one
/// unknown is bumped.
#[derive(Clone, Copy)]
pub(crate) struct View<'a> {
    /// Coupled outputs of each instance (slots as the instance registered them).
    pub outputs: &'a [Vec<f64>],
    pub u: &'a [f64],
    pub column: Option<Column<'a>>,
}

/// A finite-difference column: unknown `unknown` bumped by `delta`; the
/// instances marked `live` read `perturbed` instead of the view's outputs.
#[derive(Clone, Copy)]
pub(crate) struct Column<'a> {
    pub unknown: usize,
    pub delta: f64,
    pub live: &'a [bool],
    pub perturbed: &'a [Vec<f64>],
}

impl<'a> View<'a> {
    /// The rows at `outputs` and `u`, nothing perturbed.
    pub fn at(outputs: &'a [Vec<f64>], u: &'a [f64]) -> View<'a> {
        View {
            outputs,
            u,
            column: None,
        }
    }

    /// Output `slot` of instance `s`.
    #[inline]
    pub fn value(&self, s: usize, slot: usize) -> f64 {
        match self.column {
            Some(c) if c.live[s] => c.perturbed[s][slot],
            _ => self.outputs[s][slot],
        }
    }

    /// Unknown `m`, bumped if it is the perturbed one.
    #[inline]
    pub fn unknown(&self, m: usize) -> f64 {
        match self.column {
            Some(c) if c.unknown == m => self.u[m] + c.delta,
            _ => self.u[m],
        }
    }
}

/// Which condition a row evaluates: one level, or the explicit method's
/// stabilised acceleration condition `g̈ + 2ġ/μ + g/μ²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum RowLevel {
    Position,
    Velocity,
    Acceleration,
    Stabilised(f64),
}

impl RowLevel {
    /// Pick or combine the three levels of a condition.
    #[inline]
    pub fn combine(self, g: f64, g_dot: f64, g_ddot: f64) -> f64 {
        match self {
            RowLevel::Position => g,
            RowLevel::Velocity => g_dot,
            RowLevel::Acceleration => g_ddot,
            RowLevel::Stabilised(mu) => g_ddot + (2.0 * g_dot / mu + g / (mu * mu)),
        }
    }
}

/// One level (position, velocity or acceleration) of a linear constraint:
/// `Σ coefficient · output` over `(instance, slot, coefficient)` terms.
#[derive(Debug, Clone, Default)]
pub(crate) struct Level {
    pub terms: Vec<(usize, usize, f64)>,
}

impl Level {
    pub fn eval(&self, view: &View) -> f64 {
        self.terms
            .iter()
            .map(|&(s, slot, c)| c * view.value(s, slot))
            .sum()
    }
}
