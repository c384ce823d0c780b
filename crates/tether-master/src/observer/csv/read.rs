//! Reading a results CSV back, as [`CsvRecorder`](super::CsvRecorder) writes
//! it: the header (`time` first), one row per recorded point, and the
//! `# incomplete: …` trailer of a run that stopped early. `tether compare`
//! and the studies read results through it. A column with a quoted field
//! is a String column (the recorder quotes every String value).

use std::path::Path;

/// A results CSV read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Results {
    /// The column names after `time`.
    pub columns: Vec<String>,
    /// The time of each row, increasing.
    pub times: Vec<f64>,
    /// `rows[i][j]`: column `columns[j]` at `times[i]` (NaN in a String
    /// column).
    pub rows: Vec<Vec<f64>>,
    /// The String columns: each column's index in `columns` and its text
    /// in every row, in column order.
    pub texts: Vec<(usize, Vec<String>)>,
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

    /// The texts of String column `name`, if it is one.
    pub fn texts_of(&self, name: &str) -> Option<&[String]> {
        let j = self.columns.iter().position(|c| c == name)?;
        self.texts
            .iter()
            .find(|(k, _)| *k == j)
            .map(|(_, t)| t.as_slice())
    }

    /// Reads results from the text of a CSV file: `time` first, each column
    /// named once, numbers in every field except in String columns (those
    /// with a quoted field), times increasing, at least one row; `# …`
    /// lines are comments.
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
        // The String columns: those with a field in quotes (after `time`).
        let mut is_text = vec![false; header.len()];
        for quoted in quoted_fields(text) {
            for (flag, q) in is_text.iter_mut().zip(quoted).skip(1) {
                *flag |= q;
            }
        }
        let mut texts: Vec<(usize, Vec<String>)> = (1..header.len())
            .filter(|&j| is_text[j])
            .map(|j| (j - 1, Vec::new()))
            .collect();
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
            let mut column_texts = texts.iter_mut();
            for ((field, name), &text) in record.iter().zip(&header).zip(&is_text) {
                if text {
                    if let Some((_, t)) = column_texts.next() {
                        t.push(field.to_string());
                    }
                    values.push(f64::NAN);
                    continue;
                }
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
            texts,
            incomplete,
        })
    }
}

/// Per record of a CSV text after its header (comment and blank lines
/// skipped, as the reader skips them): whether each field is in quotes.
fn quoted_fields(text: &str) -> Vec<Vec<bool>> {
    let mut records = Vec::new();
    let mut chars = text.chars().peekable();
    let mut header = true;
    loop {
        // At the start of a record.
        match chars.peek() {
            None => break,
            Some('#') => {
                for c in chars.by_ref() {
                    if c == '\n' {
                        break;
                    }
                }
                continue;
            }
            Some('\n' | '\r') => {
                chars.next();
                continue;
            }
            Some(_) => {}
        }
        let mut fields = Vec::new();
        loop {
            while chars.next_if(|c| *c == ' ' || *c == '\t').is_some() {}
            let quoted = chars.next_if_eq(&'"').is_some();
            if quoted {
                while let Some(c) = chars.next() {
                    if c == '"' && chars.next_if_eq(&'"').is_none() {
                        break;
                    }
                }
            }
            fields.push(quoted);
            let mut end = true;
            for c in chars.by_ref() {
                match c {
                    ',' => {
                        end = false;
                        break;
                    }
                    '\n' => break,
                    _ => {}
                }
            }
            if end {
                break;
            }
        }
        if !std::mem::take(&mut header) {
            records.push(fields);
        }
    }
    records
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

    /// A column with quoted fields is a String column: its texts as they
    /// were written (commas, doubled quotes, line breaks inside), NaN in
    /// `rows`; the other columns stay numbers.
    #[test]
    fn quoted_fields_make_a_string_column() {
        let text = "time,\"a.s[1,2]\",a.x\n0,\"x, \"\"y\"\"\",1\n# note\n0.5,\"two\nlines\",2\n";
        let r = Results::parse(text).unwrap();
        assert_eq!(r.columns, ["a.s[1,2]", "a.x"]);
        assert_eq!(r.texts.len(), 1);
        assert_eq!(r.texts_of("a.s[1,2]").unwrap(), ["x, \"y\"", "two\nlines"]);
        assert!(r.rows[0][0].is_nan());
        assert_eq!((r.rows[0][1], r.rows[1][1]), (1.0, 2.0));
        assert_eq!(r.texts_of("a.x"), None);
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
