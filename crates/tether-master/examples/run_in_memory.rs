//! One run of a system file through the Rust library, results kept in memory:
//! the reference of the Python package's overhead benchmark
//! (`crates/tether-py/bench/overhead.py`).
//!
//! ```sh
//! cargo run --release -p tether-master --example run_in_memory -- SYSTEM.toml [STOP [PARALLEL]]
//! ```
//!
//! Prints the in-process wall seconds of setup and run (`Simulation::new`
//! and `Simulation::run` into a `MemoryRecorder`), the CPU seconds of the
//! calling thread over the same span (Linux: `/proc/thread-self/schedstat`;
//! NaN elsewhere) and the number of rows.

use std::time::Instant;

use tether_master::{MemoryRecorder, Simulation, SystemSpec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or("usage: run_in_memory SYSTEM.toml [STOP]")?;
    let mut spec = SystemSpec::from_file(path.as_ref())?;
    if let Some(stop) = args.next() {
        spec.experiment.stop = stop.parse()?;
    }
    if let Some(parallel) = args.next() {
        spec.coupling.parallel = parallel.parse()?;
    }
    let cpu = thread_cpu();
    let clock = Instant::now();
    let mut sim = Simulation::new(&spec)?;
    let mut results = MemoryRecorder::default();
    sim.run(&mut [&mut results], &mut |_, _| {})?;
    let seconds = clock.elapsed().as_secs_f64();
    let cpu = thread_cpu() - cpu;
    println!("{seconds} {cpu} {}", results.rows.len());
    Ok(())
}

/// CPU seconds of the calling thread so far (NaN where unknown).
fn thread_cpu() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}
