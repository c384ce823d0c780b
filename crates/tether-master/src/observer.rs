//! Observers see every accepted macro point; recording results is one of them.

use std::io::Write;

/// The values at one accepted macro point, in column order.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// Macro point index n (time = start + n·H).
    pub step: u64,
    /// T_n.
    pub time: f64,
    /// All values after `time`, in the order of [`crate::Simulation::columns`].
    pub values: &'a [f64],
}

/// Receives the results of a run as they are produced.
pub trait Observer {
    /// Called once before the first sample with the column names (without `time`).
    fn start(&mut self, columns: &[String]) -> std::io::Result<()>;
    /// Called at T_0 and after every accepted macro step.
    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()>;
    /// Called once at the end; `failure` is the error that stopped the run, if any.
    fn finish(&mut self, failure: Option<&str>) -> std::io::Result<()>;
    /// Asked before every macro step: `Some(reason)` stops the run there with
    /// [`crate::MasterError::Interrupted`] (results so far are kept). Default: never.
    fn interrupt(&mut self) -> Option<String> {
        None
    }
}

/// Writes CSV: a `time` column, then one column per value. Numbers are written
/// in the shortest form that parses back to the same `f64` (through the `zmij`
/// crate, into a stack buffer: no allocation and no `fmt` machinery per
/// value), e.g. `0.001`, `333.3333333333333`, `1e-7`, `NaN`, `inf`, into a
/// 64 KiB buffered writer. A run that fails ends the file with a comment line
/// `# incomplete: <error>` after the last accepted step.
pub struct CsvRecorder<W: Write> {
    out: std::io::BufWriter<W>,
    number: zmij::Buffer,
    /// One row, assembled before a single write (reused, grows to the widest row).
    line: Vec<u8>,
}

impl<W: Write> CsvRecorder<W> {
    /// Record into `out`.
    pub fn new(out: W) -> Self {
        CsvRecorder {
            out: std::io::BufWriter::with_capacity(1 << 16, out),
            number: zmij::Buffer::new(),
            line: Vec::new(),
        }
    }
}

impl<W: Write> Observer for CsvRecorder<W> {
    fn start(&mut self, columns: &[String]) -> std::io::Result<()> {
        self.out.write_all(b"time")?;
        for c in columns {
            self.out.write_all(b",")?;
            // Structured names such as `link.tip.R[1,2]` contain commas: quote
            // them as RFC 4180 says, doubling any quote inside.
            if c.contains([',', '"', '\n', '\r']) {
                write!(self.out, "\"{}\"", c.replace('"', "\"\""))?;
            } else {
                self.out.write_all(c.as_bytes())?;
            }
        }
        self.out.write_all(b"\n")
    }

    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()> {
        let line = &mut self.line;
        line.clear();
        line.extend_from_slice(self.number.format(sample.time).as_bytes());
        for &v in sample.values {
            line.push(b',');
            line.extend_from_slice(self.number.format(v).as_bytes());
        }
        line.push(b'\n');
        self.out.write_all(line)
    }

    fn finish(&mut self, failure: Option<&str>) -> std::io::Result<()> {
        if let Some(reason) = failure {
            let line = reason.replace(['\n', '\r'], " ");
            writeln!(self.out, "# incomplete: {line}")?;
        }
        self.out.flush()
    }
}

/// Keeps every sample in memory (for library users and tests).
#[derive(Debug, Default, Clone)]
pub struct MemoryRecorder {
    /// Column names after `time`.
    pub columns: Vec<String>,
    /// T_n of each sample.
    pub times: Vec<f64>,
    /// One row per sample.
    pub rows: Vec<Vec<f64>>,
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
}

impl Observer for MemoryRecorder {
    fn start(&mut self, columns: &[String]) -> std::io::Result<()> {
        self.columns = columns.to_vec();
        Ok(())
    }

    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()> {
        self.times.push(sample.time);
        self.rows.push(sample.values.to_vec());
        Ok(())
    }

    fn finish(&mut self, failure: Option<&str>) -> std::io::Result<()> {
        self.failure = failure.map(str::to_string);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_rows_round_trip_and_failures_are_marked() {
        let mut buf = Vec::new();
        {
            let mut rec = CsvRecorder::new(&mut buf);
            rec.start(&["a.x".into(), "c.lambda".into(), "b.R[1,2]".into()])
                .unwrap();
            rec.sample(Sample {
                step: 0,
                time: 0.0,
                values: &[0.1, 1.0 / 3.0, 0.5],
            })
            .unwrap();
            rec.finish(Some("coupling diverged at t = 1")).unwrap();
        }
        let text = String::from_utf8(buf).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "time,a.x,c.lambda,\"b.R[1,2]\"");
        let third: f64 = lines[1].split(',').nth(2).unwrap().parse().unwrap();
        assert_eq!(third.to_bits(), (1.0f64 / 3.0).to_bits());
        assert_eq!(lines[2], "# incomplete: coupling diverged at t = 1");
    }

    /// Every number read back from the CSV has the bits that were written:
    /// random bit patterns (normal and subnormal), signed zeros, extremes.
    #[test]
    fn csv_numbers_round_trip_bit_for_bit() {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut values: Vec<f64> = (0..20_000)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                f64::from_bits(state)
            })
            .filter(|v| v.is_finite())
            .collect();
        values.extend([
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::MIN,
            1e-7,
            0.1 + 0.2,
            1000.0 / 3.0,
        ]);
        let mut buf = Vec::new();
        {
            let mut rec = CsvRecorder::new(&mut buf);
            let columns: Vec<String> = (0..values.len()).map(|i| format!("c{i}")).collect();
            rec.start(&columns).unwrap();
            rec.sample(Sample {
                step: 0,
                time: 0.001,
                values: &values,
            })
            .unwrap();
            rec.sample(Sample {
                step: 1,
                time: 0.002,
                values: &[f64::NAN, f64::INFINITY, f64::NEG_INFINITY],
            })
            .unwrap();
            rec.finish(None).unwrap();
        }
        let text = String::from_utf8(buf).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let row: Vec<f64> = lines[1].split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(row[0], 0.001);
        for (read, written) in row[1..].iter().zip(&values) {
            assert_eq!(read.to_bits(), written.to_bits(), "{written:e}");
        }
        assert_eq!(lines[2], "0.002,NaN,inf,-inf");
    }
}
