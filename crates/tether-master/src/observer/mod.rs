//! Observers see every accepted macro point; recording results is one of them.

mod csv;
mod memory;

pub use csv::{CsvRecorder, Emergency, Results, FLUSH_INTERVAL};
pub use memory::MemoryRecorder;

use tether_fmi::Int;

/// The values at one accepted macro point, in column order.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// Macro point index n (time = start + n·H).
    pub step: u64,
    /// T_n.
    pub time: f64,
    /// All values after `time`, in the order of [`crate::Simulation::columns`].
    pub values: &'a [f64],
    /// The integer values among them that a float rounds (beyond ±2⁵³, an
    /// FMI 3.0 `Int64` or `UInt64`), exactly, by index in `values`, in
    /// increasing order; `values` holds them rounded. Usually empty.
    pub exact: &'a [(usize, Int)],
    /// The String values (String outputs), by index in `values`, in
    /// increasing order; `values` holds 0 at their columns. Empty when the
    /// system records no String output.
    pub strings: &'a [(usize, String)],
}

impl<'a> Sample<'a> {
    /// A sample of floats only (no exact integers, no texts), as an observer
    /// fed by hand or a test builds one.
    pub fn reals(step: u64, time: f64, values: &'a [f64]) -> Sample<'a> {
        Sample {
            step,
            time,
            values,
            exact: &[],
            strings: &[],
        }
    }
}

/// `x` as a float, and whether the float is exact.
pub fn integer_value(x: Int) -> (f64, bool) {
    let v = x as f64;
    (v, v as Int == x && v.abs() <= 9_007_199_254_740_992.0)
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
