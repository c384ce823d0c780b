//! Runs N macro steps of the bench's oscillator pair (exact FMUs, k = 1) and
//! prints the time per step: a target for profilers, not a benchmark. With
//! `--floor` the same steps are made by the C floor instead of Tether.
//!
//! ```sh
//! cargo build --release -p tether-bench --example steps
//! valgrind --tool=callgrind target/release/examples/steps 10000 [--floor]
//! valgrind --tool=callgrind target/release/examples/steps 30000 [--floor]
//! ```
//!
//! The difference of the two counts, per function, divided by 20 000 is the
//! instruction count of one macro step without the setup (docs/performance.md).

use tether_bench::{floor, Case};
use tether_fmi::Fmu;
use tether_master::Simulation;

fn main() {
    let steps: u64 = match std::env::args().nth(1).map(|s| s.parse()) {
        None => 20_000,
        Some(Ok(n)) => n,
        Some(Err(e)) => {
            eprintln!("steps: the argument must be a number of macro steps ({e})");
            std::process::exit(2);
        }
    };
    let mut case = Case::example(true, 1);
    case.steps = steps;
    let mut sim = match Simulation::new(&case.spec()) {
        Ok(sim) => sim,
        Err(e) => {
            eprintln!("steps: {e}");
            std::process::exit(1);
        }
    };
    if std::env::args().nth(2).as_deref() == Some("--floor") {
        let fmu = match Fmu::open(&case.spec().instances[0].fmu) {
            Ok(fmu) => fmu,
            Err(e) => {
                eprintln!("steps: {e}");
                std::process::exit(1);
            }
        };
        match floor(&case, &fmu, sim.unknowns()[0]) {
            Ok(result) => println!(
                "{steps} macro steps of the C floor, {:.3} µs per step",
                result.seconds / steps.max(1) as f64 * 1e6
            ),
            Err(e) => {
                eprintln!("steps: {e}");
                std::process::exit(1);
            }
        }
        return;
    }
    let clock = std::time::Instant::now();
    for _ in 0..steps {
        if let Err(e) = sim.step() {
            eprintln!("steps: {e}");
            std::process::exit(1);
        }
    }
    let per_step = clock.elapsed().as_secs_f64() / steps.max(1) as f64;
    println!("{steps} macro steps, {:.3} µs per step", per_step * 1e6);
}
