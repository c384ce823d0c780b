//! Results as a table of columns over time: from a run in memory or from a
//! CSV written by `tether run` / `tether simulate`.

use std::path::Path;

use tether_master::MemoryRecorder;

use crate::StudyError;

/// Time series of named columns, one row per macro point.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// Where it came from (a file name or a run label), for messages and legends.
    pub source: String,
    /// Column names after `time`.
    pub columns: Vec<String>,
    /// Times of the rows, increasing.
    pub times: Vec<f64>,
    /// One vector per column (column-major).
    pub values: Vec<Vec<f64>>,
    /// The `# incomplete: …` reason, if the run stopped early.
    pub incomplete: Option<String>,
}

impl Table {
    /// Take a run's results.
    pub fn from_recorder(source: &str, rec: &MemoryRecorder) -> Table {
        let values = (0..rec.columns.len())
            .map(|c| rec.rows.iter().map(|r| r[c]).collect())
            .collect();
        Table {
            source: source.to_string(),
            columns: rec.columns.clone(),
            times: rec.times.clone(),
            values,
            incomplete: rec.failure.clone(),
        }
    }

    /// Read a results CSV ([`tether_master::Results`]): a `time` column
    /// first; `# incomplete: …` marks a run that stopped early.
    pub fn read_csv(path: &Path) -> Result<Table, StudyError> {
        let results = tether_master::Results::read(path).map_err(|reason| StudyError::Csv {
            path: path.to_path_buf(),
            reason,
        })?;
        let values = (0..results.columns.len())
            .map(|c| results.rows.iter().map(|row| row[c]).collect())
            .collect();
        Ok(Table {
            source: path.display().to_string(),
            columns: results.columns,
            times: results.times,
            values,
            incomplete: results.incomplete,
        })
    }

    /// Index of a column; an error lists the columns that exist.
    pub fn column(&self, name: &str) -> Result<usize, StudyError> {
        self.columns
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| StudyError::unknown_column(name, &self.source, &self.columns))
    }

    /// All values of a column.
    pub fn series(&self, name: &str) -> Result<&[f64], StudyError> {
        Ok(&self.values[self.column(name)?])
    }

    /// Value of column `c` at time `t`, linear between rows; `None` outside
    /// the table's time range.
    pub fn interpolate(&self, c: usize, t: f64) -> Option<f64> {
        let times = &self.times;
        let (first, last) = (*times.first()?, *times.last()?);
        let slack = 1e-9 * (last - first).abs().max(f64::MIN_POSITIVE);
        if t < first - slack || t > last + slack {
            return None;
        }
        let i = times.partition_point(|&x| x < t);
        let y = &self.values[c];
        if i < times.len() && (times[i] - t).abs() <= slack {
            return Some(y[i]);
        }
        if i > 0 && (times[i - 1] - t).abs() <= slack {
            return Some(y[i - 1]);
        }
        if i == 0 || i >= times.len() {
            return None;
        }
        let w = (t - times[i - 1]) / (times[i] - times[i - 1]);
        Some(y[i - 1] + w * (y[i] - y[i - 1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_csv_with_incomplete_marker_and_interpolates() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.csv");
        std::fs::write(
            &path,
            "time,a.x,link.lambda\n0,0,1\n0.5,1,1\n1,3,1\n# incomplete: coupling diverged\n",
        )
        .unwrap();
        let t = Table::read_csv(&path).unwrap();
        assert_eq!(t.columns, ["a.x", "link.lambda"]);
        assert_eq!(t.incomplete.as_deref(), Some("coupling diverged"));
        let c = t.column("a.x").unwrap();
        assert_eq!(t.interpolate(c, 0.5), Some(1.0));
        assert_eq!(t.interpolate(c, 0.75), Some(2.0));
        assert_eq!(t.interpolate(c, 1.5), None);
        let e = t.column("a.v").unwrap_err().to_string();
        assert!(e.contains("a.v") && e.contains("a.x, link.lambda"), "{e}");
    }

    #[test]
    fn bad_csv_names_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.csv");
        std::fs::write(&path, "time,x\n0,1\n1,oops\n").unwrap();
        let e = Table::read_csv(&path).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("oops"), "{e}");
        std::fs::write(&path, "t,x\n0,1\n").unwrap();
        assert!(Table::read_csv(&path).is_err());
    }
}
