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
//!
//! `--first-steps K` prints the wall time of each of the first K macro steps
//! (one-off costs such as the "auto" parallel decision at step 3 show there);
//! `--system FILE` runs that system file instead of the oscillator pair;
//! `--order 0` extrapolates the inputs with k = 0 instead of k = 1;
//! `--floor-extra MODE` runs the C floor with synthetic work added to every
//! macro step (`nothing`, `lines`, `one-line`, `straight`, `looped`; see
//! `tether_bench::Extra` and tools/bench/extra_ab.py).

use tether_bench::{floor, floor_extra, Case, Extra};
use tether_fmi::Fmu;
use tether_master::{Simulation, SystemSpec};

fn fail(message: impl std::fmt::Display) -> ! {
    eprintln!("steps: {message}");
    std::process::exit(1);
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let option = |name: &str| {
        args.iter().position(|a| a == name).map(|i| {
            args.get(i + 1)
                .unwrap_or_else(|| fail(format!("{name} needs a value")))
        })
    };
    let steps: u64 = match args.first().filter(|a| !a.starts_with("--")) {
        None => 20_000,
        Some(n) => n.parse().unwrap_or_else(|e| {
            eprintln!("steps: the first argument must be a number of macro steps ({e})");
            std::process::exit(2);
        }),
    };
    let first: usize = option("--first-steps").map_or(0, |k| {
        k.parse()
            .unwrap_or_else(|e| fail(format!("--first-steps: {e}")))
    });
    let order: usize = option("--order").map_or(1, |k| {
        k.parse()
            .ok()
            .filter(|k| *k <= 1)
            .unwrap_or_else(|| fail(format!("--order: 0 or 1, not {k}")))
    });
    let mut case = Case::example(true, order);
    case.steps = steps;
    // The case's FMU is packaged from the workspace the program is run in.
    if let Err(e) = tether_fmu_build::workspace_fmu("oscillator") {
        fail(format!(
            "cannot package the oscillator FMU (run from the Tether workspace): {e}"
        ));
    }
    let spec = match option("--system") {
        Some(path) => {
            let mut spec =
                SystemSpec::from_file(std::path::Path::new(path)).unwrap_or_else(|e| fail(e));
            spec.experiment.stop = spec.experiment.start + steps as f64 * spec.experiment.step;
            spec
        }
        None => case.spec(),
    };
    let extra = option("--floor-extra").map(|m| m.parse::<Extra>().unwrap_or_else(|e| fail(e)));
    let on_floor = extra.is_some() || args.iter().any(|a| a == "--floor");
    // Errors from here on return through `run`, so that the simulation and
    // the FMUs' unpacked copies are dropped (their temporary directories
    // removed) before the process exits.
    if let Err(e) = run(&case, &spec, steps, first, on_floor, extra) {
        fail(e);
    }
}

/// Tether's macro steps, or with `on_floor` the C floor's (with `extra` work
/// if given).
fn run(
    case: &Case,
    spec: &SystemSpec,
    steps: u64,
    first: usize,
    on_floor: bool,
    extra: Option<Extra>,
) -> Result<(), String> {
    let mut sim = Simulation::new(spec).map_err(|e| e.to_string())?;
    if on_floor {
        let fmu = Fmu::open(&case.spec().instances[0].fmu).map_err(|e| e.to_string())?;
        let lambda0 = sim.unknowns()[0];
        let result = match extra {
            Some(extra) => floor_extra(case, &fmu, lambda0, extra),
            None => floor(case, &fmu, lambda0),
        }?;
        println!(
            "{steps} macro steps of the C floor{}, {:.3} µs per step",
            extra.map_or(String::new(), |e| format!(" with extra work {e:?}")),
            result.seconds / steps.max(1) as f64 * 1e6
        );
        return Ok(());
    }
    let clock = std::time::Instant::now();
    let mut times = Vec::with_capacity(first);
    for n in 0..steps {
        let step_clock = (n < first as u64).then(std::time::Instant::now);
        sim.step().map_err(|e| e.to_string())?;
        if let Some(c) = step_clock {
            times.push(format!("{:.1}", c.elapsed().as_secs_f64() * 1e6));
        }
    }
    let per_step = clock.elapsed().as_secs_f64() / steps.max(1) as f64;
    println!("{steps} macro steps, {:.3} µs per step", per_step * 1e6);
    if first > 0 {
        println!("first {} steps [µs]: {}", times.len(), times.join(" "));
    }
    Ok(())
}
