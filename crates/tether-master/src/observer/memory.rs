//! [`MemoryRecorder`]: every sample kept in memory.

use crate::observer::{Observer, Sample};

/// Keeps every sample in memory (for library users and tests).
#[derive(Debug, Default, Clone)]
pub struct MemoryRecorder {
    /// Column names after `time`.
    pub columns: Vec<String>,
    /// T_n of each sample.
    pub times: Vec<f64>,
    /// One row per sample.
    pub rows: Vec<Vec<f64>>,
    /// Per sample: its String values by column index (the row holds 0
    /// there); empty rows without String outputs.
    pub strings: Vec<Vec<(usize, String)>>,
    /// The failure that ended the run, if any.
    pub failure: Option<String>,
}

impl MemoryRecorder {
    /// Index of a column by name.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// All values of one column.
    pub fn series(&self, name: &str) -> Option<Vec<f64>> {
        let i = self.column(name)?;
        Some(self.rows.iter().map(|r| r[i]).collect())
    }

    /// All values of one String column (`None` for a column of numbers).
    pub fn texts(&self, name: &str) -> Option<Vec<String>> {
        let i = self.column(name)?;
        self.strings
            .iter()
            .map(|row| row.iter().find(|(k, _)| *k == i).map(|(_, s)| s.clone()))
            .collect()
    }
}

impl Observer for MemoryRecorder {
    fn start(&mut self, columns: &[String]) -> std::io::Result<()> {
        self.columns = columns.to_vec();
        Ok(())
    }

    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()> {
        self.times.push(sample.time);
        self.rows.push(sample.values.to_vec());
        self.strings.push(sample.strings.to_vec());
        Ok(())
    }

    fn finish(&mut self, failure: Option<&str>) -> std::io::Result<()> {
        self.failure = failure.map(str::to_string);
        Ok(())
    }
}
