//! Time series of several variants side by side (the paper's Fig. 5, 10, 16–20).

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tether_master::expr::LinearExpr;

use crate::runner::{self, RunResult};
use crate::{StudyError, Table, Variant};

/// Which columns to show, and columns derived from them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Series {
    /// Columns to plot, one panel each (default: every column). `*` matches
    /// any text: `"*.lambda"` is every multiplier.
    #[serde(default)]
    pub columns: Vec<String>,
    /// New columns as linear combinations of existing ones, by name:
    /// `{ energy = "crank.E + rocker.E" }`, or `"sum(PATTERN)"`, the sum of
    /// every column matching a `*` pattern. They may be listed in `columns`.
    #[serde(default)]
    pub derived: BTreeMap<String, String>,
}

/// Run every variant in parallel; add derived columns; check the columns exist.
pub fn series(
    variants: &[Variant],
    study: &Series,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<RunResult>, StudyError> {
    for v in variants {
        runner::check(&v.spec)?;
    }
    let runs: Vec<RunResult> = variants
        .par_iter()
        .map(|v| {
            let r = series_run(v);
            progress();
            r
        })
        .collect();
    series_finish(study, runs)
}

/// One run of a series: the variant as it is.
pub fn series_run(variant: &Variant) -> RunResult {
    runner::run(&variant.spec, &variant.label)
}

/// Add the derived columns to the runs (one per variant, in order) and
/// check that the columns shown exist.
pub fn series_finish(
    study: &Series,
    mut runs: Vec<RunResult>,
) -> Result<Vec<RunResult>, StudyError> {
    for run in &mut runs {
        for (name, text) in &study.derived {
            add_derived(&mut run.table, name, text)?;
        }
        expand_columns(&run.table, &study.columns)?;
    }
    Ok(runs)
}

/// Whether `name` matches `pattern`, where `*` matches any text.
pub fn matches(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !name.starts_with(first) || name.len() < first.len() + last.len() || !name.ends_with(last) {
        return false;
    }
    let mut rest = &name[first.len()..name.len() - last.len()];
    for part in &parts[1..parts.len() - 1] {
        match rest.find(part) {
            Some(i) => rest = &rest[i + part.len()..],
            None => return false,
        }
    }
    true
}

/// The columns named by `patterns`, in table order per pattern; a pattern
/// that matches nothing is an error listing the columns.
pub fn expand_columns(table: &Table, patterns: &[String]) -> Result<Vec<String>, StudyError> {
    let mut out = Vec::new();
    for p in patterns {
        let found: Vec<&String> = table.columns.iter().filter(|c| matches(p, c)).collect();
        if found.is_empty() {
            return Err(StudyError::unknown_column(p, &table.source, &table.columns));
        }
        out.extend(found.into_iter().cloned());
    }
    Ok(out)
}

/// Append column `name` = the linear expression `text` of existing columns
/// (terms written `instance.variable`, as in constraint expressions).
pub fn add_derived(table: &mut Table, name: &str, text: &str) -> Result<(), StudyError> {
    if let Some(pattern) = text
        .trim()
        .strip_prefix("sum(")
        .and_then(|t| t.strip_suffix(')'))
    {
        let cols = expand_columns(table, &[pattern.trim().to_string()])?;
        let mut values = vec![0.0; table.times.len()];
        for c in cols {
            let c = table.column(&c)?;
            for (v, x) in values.iter_mut().zip(&table.values[c]) {
                *v += x;
            }
        }
        table.columns.push(name.to_string());
        table.values.push(values);
        return Ok(());
    }
    let expr = LinearExpr::parse(text)
        .map_err(|e| StudyError::Invalid(format!("derived column '{name}': {e}")))?;
    let mut values = vec![0.0; table.times.len()];
    for term in &expr.terms {
        if term.derivative_order != 0 {
            return Err(StudyError::Invalid(format!(
                "derived column '{name}': der() is not available on results"
            )));
        }
        let col = table.column(&format!("{}.{}", term.instance, term.variable))?;
        for (v, x) in values.iter_mut().zip(&table.values[col]) {
            *v += term.coefficient * x;
        }
    }
    table.columns.push(name.to_string());
    table.values.push(values);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Table {
        Table {
            source: "t".into(),
            columns: vec!["a.E".into(), "b.E".into(), "link.lambda".into()],
            times: vec![0.0, 1.0],
            values: vec![vec![1.0, 2.0], vec![10.0, 20.0], vec![0.5, 0.5]],
            incomplete: None,
        }
    }

    #[test]
    fn series_patterns_select_columns_and_derived_columns_compute() {
        let mut t = table();
        assert!(matches("*.E", "a.E") && !matches("*.E", "link.lambda"));
        assert!(matches("a*", "a.E") && matches("*lam*", "link.lambda"));
        assert_eq!(expand_columns(&t, &["*.E".into()]).unwrap(), ["a.E", "b.E"]);
        assert!(expand_columns(&t, &["*.phi".into()]).is_err());
        add_derived(&mut t, "total", "sum(*.E)").unwrap();
        add_derived(&mut t, "diff", "b.E - 2*a.E").unwrap();
        assert_eq!(t.series("total").unwrap(), [11.0, 22.0]);
        assert_eq!(t.series("diff").unwrap(), [8.0, 16.0]);
        assert!(add_derived(&mut t, "bad", "c.E").is_err());
    }
}
