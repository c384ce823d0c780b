//! Third-party tools the tests compare against (fmpy, libcosimpy). A test that
//! needs one and cannot find it fails on CI (`CI` set: `.ci/run` installs every
//! tool) and elsewhere is skipped with a line saying why.

use std::path::PathBuf;

/// `found`, or the reason `tool` is missing: panics when `CI` is set, else
/// prints the skip line and returns `None` (the test then returns).
pub fn needed<T>(tool: &str, found: Result<T, String>) -> Option<T> {
    match found {
        Ok(found) => Some(found),
        Err(why) if std::env::var_os("CI").is_some() => {
            panic!("{tool} is needed on CI (.ci/run installs it): {why}")
        }
        Err(why) => {
            eprintln!("SKIPPED: {tool} is not available ({why}); .ci/run installs it");
            None
        }
    }
}

/// The test Python with fmpy, or `None` (skipped) as [`needed`] says.
pub fn fmpy() -> Option<PathBuf> {
    needed("fmpy", crate::fmpy::python())
}

/// The test Python with libcosimpy, or `None` (skipped) as [`needed`] says.
pub fn libcosimpy() -> Option<PathBuf> {
    needed("libcosimpy", crate::fmpy::libcosim_python())
}

/// Tether's rows of `spec` after every step (the point T_0 left out, as
/// libcosim's observer records it): time, then `columns`.
pub fn tether_rows(spec: &tether_master::SystemSpec, columns: &[&str]) -> Vec<Vec<f64>> {
    let mut sim = tether_master::Simulation::new(spec).unwrap();
    let mut rec = tether_master::MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
    let idx: Vec<usize> = columns
        .iter()
        .map(|c| rec.columns.iter().position(|n| n == c).unwrap())
        .collect();
    rec.times
        .iter()
        .zip(&rec.rows)
        .skip(1)
        .map(|(t, row)| {
            std::iter::once(*t)
                .chain(idx.iter().map(|&i| row[i]))
                .collect()
        })
        .collect()
}
