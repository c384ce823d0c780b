//! Reading a results CSV back, as [`CsvRecorder`](super::CsvRecorder) writes
//! it: the header (`time` first), one row per recorded point, and the
//! `# incomplete: …` trailer of a run that stopped early. `tether compare`
//! and the studies read results through it.

use std::path::Path;

/// A results CSV read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Results {
    /// The column names after `time`.
    pub columns: Vec<String>,
    /// The time of each row, increasing.
    pub times: Vec<f64>,
    /// `rows[i][j]`: column `columns[j]` at `times[i]`.
    pub rows: Vec<Vec<f64>>,
    /// The reason of a `# incomplete: …` line, if the run stopped early.
    pub incomplete: Option<String>,
}

impl Results {
    /// Reads the results file `path`; an error says what is wrong and where
    /// in the file (the caller names the file).
    pub fn read(path: &Path) -> Result<Results, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read it: {e}"))?;
        Results::parse(&text)
    }

    /// Reads results from the text of a CSV file: `time` first, each column
    /// named once, numbers in every field, times increasing, at least one
    /// row; `# …` lines are comments.
    pub fn parse(text: &str) -> Result<Results, String> {
        let incomplete = text
            .lines()
            .find_map(|l| l.strip_prefix("# incomplete:"))
            .map(|r| r.trim().to_string());
        let mut reader = ::csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .flexible(true)
            .trim(::csv::Trim::All)
            .from_reader(text.as_bytes());
        let header: Vec<String> = reader
            .headers()
            .map_err(|e| format!("cannot read the header: {e}"))?
            .iter()
            .map(str::to_string)
            .collect();
        if header.first().map(String::as_str) != Some("time") {
            return Err("the first column must be 'time'".into());
        }
        let columns = header[1..].to_vec();
        for (j, name) in columns.iter().enumerate() {
            if columns[..j].contains(name) {
                return Err(format!("column '{name}' appears twice"));
            }
        }
        let (mut times, mut rows) = (Vec::new(), Vec::new());
        for record in reader.records() {
            let record = record.map_err(|e| e.to_string())?;
            let line = record.position().map_or(0, |p| p.line());
            if record.len() != header.len() {
                return Err(format!(
                    "line {line} has {} fields, the header {}",
                    record.len(),
                    header.len()
                ));
            }
            let mut values = Vec::with_capacity(header.len());
            for (field, name) in record.iter().zip(&header) {
                let value: f64 = field.parse().map_err(|_| {
                    format!("line {line}, column '{name}': '{field}' is not a number")
                })?;
                values.push(value);
            }
            let t = values.remove(0);
            if times.last().is_some_and(|&last| t <= last) {
                return Err(format!("line {line}: time {t} does not increase"));
            }
            times.push(t);
            rows.push(values);
        }
        if rows.is_empty() {
            return Err("no rows".into());
        }
        Ok(Results {
            columns,
            times,
            rows,
            incomplete,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Results;

    #[test]
    fn what_the_recorder_writes_reads_back() {
        let text = "time,a.x,a.v\n0,1,2\n0.5,3,4\n# incomplete: stopped\n";
        let r = Results::parse(text).unwrap();
        assert_eq!(r.columns, ["a.x", "a.v"]);
        assert_eq!(r.times, [0.0, 0.5]);
        assert_eq!(r.rows, [vec![1.0, 2.0], vec![3.0, 4.0]]);
        assert_eq!(r.incomplete.as_deref(), Some("stopped"));
    }

    #[test]
    fn a_malformed_file_is_one_message_naming_the_place() {
        let cases = [
            ("x,a\n0,1\n", "the first column must be 'time'"),
            ("time,a,a\n0,1,2\n", "column 'a' appears twice"),
            (
                "time,a\n0,1\n1,abc\n",
                "line 3, column 'a': 'abc' is not a number",
            ),
            ("time,a\n0,1\n1\n", "line 3 has 1 fields, the header 2"),
            ("time,a\n1,1\n0,2\n", "line 3: time 0 does not increase"),
            ("time,a\n", "no rows"),
        ];
        for (text, message) in cases {
            assert_eq!(Results::parse(text).unwrap_err(), message, "{text:?}");
        }
    }
}
