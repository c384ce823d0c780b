//! A study file: a system file, variants of it, and one study over them.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use tether_master::SystemSpec;

use crate::convergence::{Convergence, ConvergenceCurve};
use crate::output;
use crate::runner::RunResult;
use crate::series::Series;
use crate::stability::{Stability, StabilityMap};
use crate::{Overrides, StudyError};

/// One variant of the system: a label and the settings that differ.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantSpec {
    /// Name in legends and CSV files (default: the method and k).
    #[serde(default)]
    pub label: Option<String>,
    /// The settings this variant changes (the keys of `[set]`).
    #[serde(flatten)]
    pub set: Overrides,
}

/// A system ready to run, with its label.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Variant {
    /// Name in legends and CSV files.
    pub label: String,
    /// The system with the variant's settings applied.
    pub spec: SystemSpec,
}

/// What a study does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// Time series of every variant.
    Series(Series),
    /// Error over H.
    Convergence(Convergence),
    /// Stable/unstable over a grid of two quantities.
    Stability(Box<Stability>),
}

/// A whole study, as read from a study file or built from command-line flags.
#[derive(Debug, Clone)]
pub struct Study {
    /// Title of the figure.
    pub title: String,
    /// The system file (resolved).
    pub system: PathBuf,
    /// Folder that relative paths in the study are relative to.
    pub base: PathBuf,
    /// File stem of the outputs.
    pub output: String,
    /// Skip (rather than fail) when the system file does not exist.
    pub skip_if_missing: bool,
    /// Plot formats to write: `svg`, `png`.
    pub formats: Vec<String>,
    /// Settings for every variant.
    pub set: Overrides,
    /// The variants (none: the system as it is, with `set`).
    pub variants: Vec<VariantSpec>,
    /// The study.
    pub kind: Kind,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StudyFile {
    #[serde(default)]
    title: Option<String>,
    system: PathBuf,
    #[serde(default)]
    output: Option<String>,
    #[serde(default)]
    skip_if_missing: bool,
    #[serde(default)]
    formats: Option<Vec<String>>,
    #[serde(default)]
    set: Overrides,
    #[serde(rename = "variant", default)]
    variants: Vec<VariantSpec>,
    #[serde(default)]
    series: Option<Series>,
    #[serde(default)]
    convergence: Option<Convergence>,
    #[serde(default)]
    stability: Option<Stability>,
}

/// What a finished study wrote, and a text summary of its results.
#[derive(Debug, Clone)]
pub struct StudyReport {
    /// Files written.
    pub files: Vec<PathBuf>,
    /// Human-readable results (tables, orders, maps).
    pub summary: String,
}

impl Study {
    /// Read a study file; the system path is relative to it.
    pub fn from_file(path: &Path) -> Result<Study, StudyError> {
        let bad = |reason: String| StudyError::StudyFile {
            path: path.to_path_buf(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let file: StudyFile =
            toml::from_str(&text).map_err(|e| bad(tether_master::spec::toml_error(&text, &e)))?;
        let kind = match (file.series, file.convergence, file.stability) {
            (Some(s), None, None) => Kind::Series(s),
            (None, Some(c), None) => Kind::Convergence(c),
            (None, None, Some(s)) => Kind::Stability(Box::new(s)),
            _ => {
                return Err(bad(
                    "give exactly one of [series], [convergence], [stability]".into(),
                ))
            }
        };
        let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "study".into());
        let study = Study {
            title: file.title.unwrap_or_else(|| stem.clone()),
            system: base.join(&file.system),
            output: file.output.unwrap_or(stem),
            skip_if_missing: file.skip_if_missing,
            formats: file.formats.unwrap_or_else(|| vec!["svg".into()]),
            set: file.set,
            variants: file.variants,
            base,
            kind,
        };
        study.validate().map_err(|e| bad(e.to_string()))?;
        Ok(study)
    }

    /// The study of `tether sweep`: `kind` over the system file `system`,
    /// whose settings `set` hold for every run; `spec` is the system with
    /// them applied (for the title). The results go to `<name>.*` (default:
    /// `convergence` / `stability`) in the plot `formats`.
    pub fn sweep(
        system: PathBuf,
        spec: &SystemSpec,
        set: Overrides,
        kind: Kind,
        name: Option<String>,
        formats: Vec<String>,
    ) -> Result<Study, StudyError> {
        let name = name.unwrap_or_else(|| {
            match kind {
                Kind::Convergence(_) => "convergence",
                Kind::Stability(_) => "stability",
                Kind::Series(_) => "series",
            }
            .to_string()
        });
        let study = Study {
            title: format!(
                "{}: {}, k = {}",
                spec.name.as_deref().unwrap_or(&name),
                spec.method,
                spec.coupling.order
            ),
            system,
            base: PathBuf::from("."),
            output: name,
            skip_if_missing: false,
            formats,
            set,
            variants: Vec::new(),
            kind,
        };
        study.validate()?;
        Ok(study)
    }

    fn validate(&self) -> Result<(), StudyError> {
        for f in &self.formats {
            if f != "svg" && f != "png" {
                return Err(StudyError::Invalid(format!(
                    "format '{f}': expected \"svg\" or \"png\""
                )));
            }
        }
        match &self.kind {
            Kind::Series(_) => Ok(()),
            Kind::Convergence(c) => c.validate(),
            Kind::Stability(s) => s.validate().map(drop),
        }
    }

    /// Read the system file and apply the settings of every variant.
    pub fn variants(&self) -> Result<Vec<Variant>, StudyError> {
        self.variants_of(&SystemSpec::from_file(&self.system)?)
    }

    /// Apply the settings of every variant to `system` (the study's system,
    /// given rather than read from [`Study::system`]).
    pub fn variants_of(&self, system: &SystemSpec) -> Result<Vec<Variant>, StudyError> {
        let specs = if self.variants.is_empty() {
            vec![VariantSpec::default()]
        } else {
            self.variants.clone()
        };
        specs
            .iter()
            .map(|v| {
                let mut spec = system.clone();
                self.set.merged(&v.set).apply(&mut spec)?;
                let label = v
                    .label
                    .clone()
                    .unwrap_or_else(|| format!("{}, k = {}", spec.method, spec.coupling.order));
                Ok(Variant { label, spec })
            })
            .collect()
    }

    /// Number of runs the study makes (for a progress bar).
    pub fn runs(&self) -> Result<u64, StudyError> {
        let n = self.variants.len().max(1);
        let per = match &self.kind {
            Kind::Series(_) => 1,
            Kind::Convergence(c) => c.steps.len(),
            Kind::Stability(s) => {
                let (x, y) = s.validate()?;
                x.len() * y.len()
            }
        };
        Ok((n * per) as u64)
    }

    /// The text summary of a study's results and, with `out_dir`, the files
    /// `<output>.csv`, `<output>.txt` and the plots written into it.
    pub fn report(
        &self,
        results: &StudyResults,
        out_dir: Option<&Path>,
    ) -> Result<StudyReport, StudyError> {
        let mut summary = format!("{}\n", self.title);
        // Where the CSV and the plots go, if anywhere.
        let out = match out_dir {
            Some(dir) => {
                create_dir(dir)?;
                let stem = dir.join(&self.output);
                let plots: Vec<PathBuf> = self
                    .formats
                    .iter()
                    .map(|f| stem.with_extension(f))
                    .collect();
                Some((stem, plots))
            }
            None => None,
        };
        let csv = out.as_ref().map(|(stem, _)| stem.with_extension("csv"));
        let plots = out.as_ref().map_or(&[][..], |(_, plots)| plots.as_slice());
        match (&self.kind, results) {
            (Kind::Series(s), StudyResults::Series(runs)) => {
                for run in runs {
                    let _ = writeln!(
                        summary,
                        "  {}: {}",
                        run.table.source,
                        match run.outcome.message() {
                            None => "completed".to_string(),
                            Some(m) => format!("stopped: {m}"),
                        }
                    );
                }
                if let Some(csv) = &csv {
                    output::write_series(csv, runs)?;
                }
                for p in plots {
                    output::plot_series(p, &self.title, s, runs)?;
                }
            }
            (Kind::Convergence(c), StudyResults::Convergence(curves)) => {
                summary += &output::convergence_table(c, curves);
                if let Some(csv) = &csv {
                    output::write_convergence(csv, c, curves)?;
                }
                for p in plots {
                    output::plot_convergence(p, &self.title, c, curves)?;
                }
            }
            (Kind::Stability(s), StudyResults::Stability(maps)) => {
                summary += &output::stability_text(s, maps)?;
                if let Some(csv) = &csv {
                    output::write_stability(csv, s, maps)?;
                }
                for p in plots {
                    output::plot_stability(p, &self.title, s, maps)?;
                }
            }
            _ => {
                return Err(StudyError::Invalid(
                    "the results are of another kind of study".into(),
                ))
            }
        }
        let (Some((stem, plots)), Some(csv)) = (out, csv) else {
            return Ok(StudyReport {
                files: Vec::new(),
                summary,
            });
        };
        let txt = stem.with_extension("txt");
        std::fs::write(&txt, &summary).map_err(|e| StudyError::Io {
            path: txt.clone(),
            source: e,
        })?;
        let mut files = vec![csv, txt];
        files.extend(plots);
        Ok(StudyReport { files, summary })
    }
}

pub(crate) fn create_dir(dir: &Path) -> Result<(), StudyError> {
    std::fs::create_dir_all(dir).map_err(|e| StudyError::Io {
        path: dir.to_path_buf(),
        source: e,
    })
}

/// The results of a study, before they are written.
#[derive(Debug, Clone)]
pub enum StudyResults {
    /// One run per variant.
    Series(Vec<RunResult>),
    /// One curve per variant.
    Convergence(Vec<ConvergenceCurve>),
    /// One map per variant.
    Stability(Vec<StabilityMap>),
}

#[cfg(test)]
mod tests {
    use tether_master::{Method, StartValue};

    use super::*;

    fn study_file(variant: &str) -> Result<Study, StudyError> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("study.toml");
        let text = format!(
            "system = 'osc.toml'\n[set]\nstop = 0.5\n[[variant]]\n{variant}\n[series]\ncolumns = ['mass1.x']\n"
        );
        std::fs::write(&path, text).unwrap();
        Study::from_file(&path)
    }

    #[test]
    fn a_variant_is_a_label_and_the_keys_of_set() {
        let study = study_file(
            "label = 'w'\nmethod = { kind = 'weighted', a = 1.0 }\norder = 1\nparameters = { 'mass1.c' = 5 }",
        )
        .unwrap();
        assert_eq!(study.set.stop, Some(0.5));
        let v = &study.variants[0];
        assert_eq!(v.label.as_deref(), Some("w"));
        assert_eq!(v.set.method, Method::Weighted { a: 1.0, b: 0.0 }.into());
        assert_eq!(v.set.order, Some(1));
        assert_eq!(v.set.parameters["mass1.c"], StartValue::Integer(5));
    }

    /// A study file nested 10⁵ deep: one line with the line, the column and
    /// the TOML reader's limit, not a stack overflow.
    #[test]
    fn a_deeply_nested_study_file_is_one_error_line() {
        let n = 100_000;
        let e = study_file(&format!("deep = {}{}", "[".repeat(n), "]".repeat(n)))
            .unwrap_err()
            .to_string();
        assert!(
            e.ends_with(
                "study.toml: line 5, column 88: arrays and inline tables nested more than 80 \
                 deep (the limit)"
            ),
            "{e}"
        );
    }

    #[test]
    fn a_variant_with_an_unknown_key_is_refused() {
        let e = study_file("label = 'w'\nordre = 1")
            .unwrap_err()
            .to_string();
        assert!(e.contains("ordre"), "{e}");
    }
}
