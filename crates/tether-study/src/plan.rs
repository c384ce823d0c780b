//! A study cut into independent jobs, to run them anywhere.
//!
//! Every job is one run: a cell of a stability map, a convergence run at one
//! H, a variant of a series. A job depends on nothing but the [`Plan`] and
//! its index, so it gives the same result bit for bit on this machine's cores
//! ([`Study::run`] runs the same functions through rayon) or in another
//! process or on another machine with the same FMUs (the Python package hands
//! jobs to `concurrent.futures` executors and Dask clusters). The results are
//! put together by the same code as a local study's: [`Plan::results`].
//!
//! A plan travels as TOML ([`Plan::to_toml`]): the variants' systems fully
//! resolved (absolute FMU paths, every setting applied) and the study.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::convergence::{
    convergence_check, convergence_curves, convergence_jobs, convergence_run,
};
use crate::runner::RunResult;
use crate::series::{series_finish, series_run};
use crate::stability::{stability_cell, stability_check, stability_jobs, stability_maps, Cell};
use crate::study::{create_dir, StudyReport, StudyResults};
use crate::{runner, Kind, Study, StudyError, Variant};

/// A study's variants and what to do with them, ready to be cut into jobs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Plan {
    /// The folder a reference CSV of a convergence study is relative to.
    pub base: PathBuf,
    /// The variants, each with every setting applied.
    pub variants: Vec<Variant>,
    /// The study.
    pub kind: Kind,
}

/// The result of one job.
#[derive(Debug, Clone)]
pub enum JobResult {
    /// A classified cell of a stability map.
    Cell(Cell),
    /// A whole run (convergence, series).
    Run(RunResult),
}

/// What one job does.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Job {
    Cell { variant: usize, x: f64, y: f64 },
    Converge { variant: usize, step: f64 },
    Series { variant: usize },
}

impl Plan {
    /// The plan of `study` with its variants from `system` (see
    /// [`Study::variants_of`]); nothing is checked against the FMUs yet.
    pub fn new(study: &Study, variants: Vec<Variant>) -> Plan {
        Plan {
            base: std::path::absolute(&study.base).unwrap_or_else(|_| study.base.clone()),
            variants,
            kind: study.kind.clone(),
        }
    }

    /// Check the study and every variant against its FMUs (the checks a
    /// local study makes before its first run); returns the number of jobs.
    pub fn check(&self) -> Result<usize, StudyError> {
        match &self.kind {
            Kind::Series(_) => {
                for v in &self.variants {
                    runner::check(&v.spec)?;
                }
            }
            Kind::Convergence(c) => convergence_check(&self.variants, c)?,
            Kind::Stability(s) => stability_check(&self.variants, s)?,
        }
        Ok(self.jobs()?.len())
    }

    fn jobs(&self) -> Result<Vec<Job>, StudyError> {
        let n = self.variants.len();
        Ok(match &self.kind {
            Kind::Series(_) => (0..n).map(|variant| Job::Series { variant }).collect(),
            Kind::Convergence(c) => convergence_jobs(n, c)
                .into_iter()
                .map(|(variant, step)| Job::Converge { variant, step })
                .collect(),
            Kind::Stability(s) => stability_jobs(n, s)?
                .into_iter()
                .map(|(variant, x, y)| Job::Cell { variant, x, y })
                .collect(),
        })
    }

    /// Run every job in parallel over the cores (rayon) and put the results
    /// together: what [`Study::run`] computes. `progress` is called after
    /// each finished run; once it returns false no further run starts and
    /// the study ends with [`StudyError::Interrupted`].
    pub fn run_all(
        &self,
        progress: &(dyn Fn() -> bool + Sync),
    ) -> Result<StudyResults, StudyError> {
        let total = self.check()?;
        let jobs = self.jobs()?;
        let stop = AtomicBool::new(false);
        let done = AtomicUsize::new(0);
        let results: Vec<Option<JobResult>> = jobs
            .par_iter()
            .map(|&job| {
                if stop.load(Ordering::Relaxed) {
                    return Ok(None);
                }
                let result = self.run(job)?;
                done.fetch_add(1, Ordering::Relaxed);
                if !progress() {
                    stop.store(true, Ordering::Relaxed);
                }
                Ok(Some(result))
            })
            .collect::<Result<_, StudyError>>()?;
        let results: Option<Vec<JobResult>> = results.into_iter().collect();
        match results {
            Some(results) => self.results(results),
            None => Err(StudyError::Interrupted {
                done: done.into_inner(),
                total,
            }),
        }
    }

    /// Run the jobs `indices` (each in `0..check()`), one after the other.
    pub fn run_jobs(&self, indices: &[usize]) -> Result<Vec<JobResult>, StudyError> {
        let jobs = self.jobs()?;
        indices
            .iter()
            .map(|&i| {
                let job = jobs.get(i).ok_or_else(|| {
                    StudyError::Invalid(format!("job {i} of a plan of {}", jobs.len()))
                })?;
                self.run(*job)
            })
            .collect()
    }

    fn run(&self, job: Job) -> Result<JobResult, StudyError> {
        Ok(match job {
            Job::Cell { variant, x, y } => {
                let Kind::Stability(s) = &self.kind else {
                    return Err(wrong_kind());
                };
                JobResult::Cell(stability_cell(&self.variants[variant], s, x, y)?)
            }
            Job::Converge { variant, step } => {
                JobResult::Run(convergence_run(&self.variants[variant], step))
            }
            Job::Series { variant } => JobResult::Run(series_run(&self.variants[variant])),
        })
    }

    /// The study's results from the results of every job, in job order.
    pub fn results(&self, results: Vec<JobResult>) -> Result<StudyResults, StudyError> {
        let runs = |results: Vec<JobResult>| {
            results
                .into_iter()
                .map(|r| match r {
                    JobResult::Run(r) => Ok(r),
                    JobResult::Cell(_) => Err(wrong_kind()),
                })
                .collect::<Result<Vec<_>, _>>()
        };
        Ok(match &self.kind {
            Kind::Stability(s) => {
                let cells = results
                    .into_iter()
                    .map(|r| match r {
                        JobResult::Cell(c) => Ok(c),
                        JobResult::Run(_) => Err(wrong_kind()),
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                StudyResults::Stability(stability_maps(&self.variants, s, cells)?)
            }
            Kind::Series(s) => StudyResults::Series(series_finish(s, runs(results)?)?),
            Kind::Convergence(c) => {
                let jobs = convergence_jobs(self.variants.len(), c);
                StudyResults::Convergence(convergence_curves(
                    &self.variants,
                    c,
                    &self.base,
                    &jobs,
                    &runs(results)?,
                )?)
            }
        })
    }

    /// The plan as TOML text; [`Plan::from_toml`] reads it back exactly
    /// (numbers are written in their shortest round-trip form).
    pub fn to_toml(&self) -> Result<String, StudyError> {
        toml::to_string(self).map_err(|e| StudyError::Invalid(format!("plan: {e}")))
    }

    /// Read a plan written by [`Plan::to_toml`].
    pub fn from_toml(text: &str) -> Result<Plan, StudyError> {
        toml::from_str(text).map_err(|e| {
            StudyError::Invalid(format!(
                "plan: {}",
                tether_master::spec::toml_error(text, &e)
            ))
        })
    }
}

fn wrong_kind() -> StudyError {
    StudyError::Invalid("a job of another kind of study".into())
}

impl Study {
    /// Run the study in parallel and write `<output>.csv`, `<output>.txt` and
    /// the plots into `out_dir`. `progress` is called once per finished run.
    pub fn run(
        &self,
        out_dir: &Path,
        progress: &(dyn Fn() + Sync),
    ) -> Result<StudyReport, StudyError> {
        let variants = self.variants()?;
        create_dir(out_dir)?;
        let results = Plan::new(self, variants).run_all(&|| {
            progress();
            true
        })?;
        self.report(&results, Some(out_dir))
    }
}
