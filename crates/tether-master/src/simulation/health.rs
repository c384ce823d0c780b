//! The run's health: divergence limits on every column, the largest
//! residuals so far, and the error that stopped the run.

use crate::state_bytes::{Pass, Passed};
use crate::stats::Failure;
use crate::MasterError;

/// What is checked at every accepted point, and how the run failed.
#[derive(Debug, Clone)]
pub(crate) struct Health {
    /// Per column, the magnitude beyond which the run has diverged.
    limits: Vec<f64>,
    /// The first residual column's index in the row.
    first_residual: usize,
    /// Per residual column, the largest |g| over the points so far.
    max_residuals: Vec<f64>,
    /// `[coupling] residual_warning`, for the summary.
    residual_warning: f64,
    /// `[coupling] residual_limit`: a larger |g| fails the run.
    residual_limit: Option<f64>,
    /// The error that stopped the run, if any.
    failure: Option<Failure>,
}

impl Health {
    /// Limits `factor`·max(|v|, 1) around the initial row `initial` (finite:
    /// the factor is finite and > 1, so that ±∞ is always beyond them).
    pub(crate) fn new(
        initial: &[f64],
        first_residual: usize,
        factor: f64,
        residual_warning: f64,
        residual_limit: Option<f64>,
    ) -> Health {
        Health {
            limits: initial
                .iter()
                .map(|v| (factor * v.abs().max(1.0)).min(f64::MAX))
                .collect(),
            first_residual,
            max_residuals: vec![0.0; initial.len() - first_residual],
            residual_warning,
            residual_limit,
            failure: None,
        }
    }

    /// Take in an accepted point's row: track the residuals, and an error
    /// naming the first value that is not finite or beyond its divergence
    /// limit, else the first residual beyond `residual_limit`.
    pub(crate) fn check(
        &mut self,
        row: &[f64],
        columns: &[String],
        time: f64,
    ) -> Result<(), MasterError> {
        for (max, residual) in self
            .max_residuals
            .iter_mut()
            .zip(&row[self.first_residual..])
        {
            *max = max.max(residual.abs());
        }
        let beyond = |(&value, &limit): (&f64, &f64)| value.is_nan() || value.abs() > limit;
        if let Some(i) = row.iter().zip(&self.limits).position(beyond) {
            return Err(MasterError::Diverged {
                time,
                quantity: columns[i].clone(),
                value: row[i],
                limit: self.limits[i],
            });
        }
        let Some(limit) = self.residual_limit else {
            return Ok(());
        };
        match row[self.first_residual..]
            .iter()
            .position(|g| g.abs() > limit)
        {
            None => Ok(()),
            Some(i) => Err(MasterError::ResidualLimit {
                time,
                condition: columns[self.first_residual + i].clone(),
                value: row[self.first_residual + i].abs(),
                limit,
            }),
        }
    }

    /// The largest |g| of each residual column so far.
    pub(crate) fn residuals<'a>(
        &'a self,
        columns: &'a [String],
    ) -> impl Iterator<Item = (String, f64)> + 'a {
        columns[self.first_residual..]
            .iter()
            .cloned()
            .zip(self.max_residuals.iter().copied())
    }

    /// `[coupling] residual_warning`.
    pub(crate) fn residual_warning(&self) -> f64 {
        self.residual_warning
    }

    /// The error that stopped the run, if any.
    pub(crate) fn failure(&self) -> Option<&Failure> {
        self.failure.as_ref()
    }

    /// `[coupling] residual_limit`.
    pub(crate) fn residual_limit(&self) -> Option<f64> {
        self.residual_limit
    }

    /// Note the error that stopped the run.
    pub(crate) fn fail(&mut self, error: &MasterError) {
        self.failure = Some(Failure::from(error));
    }
}

impl Health {
    /// Its numbers through `p`, for the saved state's bytes; a run that has
    /// failed has no state to write.
    pub(crate) fn pass(&mut self, p: &mut Pass) -> Passed {
        if let (Pass::Write(_), Some(failure)) = (&p, &self.failure) {
            return Err(format!("the run has stopped: {failure:?}"));
        }
        self.failure = None;
        p.f64s(&mut self.limits, "the divergence limits")?;
        p.same(self.first_residual, "the first residual column")?;
        p.f64s(&mut self.max_residuals, "the residual columns")?;
        p.f64(&mut self.residual_warning)?;
        p.option(
            &mut self.residual_limit,
            "[coupling] residual_limit",
            Pass::f64,
        )
    }
}
