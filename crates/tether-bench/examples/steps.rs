//! Runs N macro steps (default 20 000) of the bench's oscillator pair (exact
//! FMUs, k = 1) or of a system file and prints the time per step: a target
//! for profilers and for comparing two builds (tools/bench/ab.py), not a
//! benchmark. With `--floor` the oscillator pair's steps are made by the C
//! floor instead of Tether.
//!
//! ```sh
//! cargo build --profile bench -p tether-bench --example steps
//! target/release/examples/steps 20000 --system examples/double_pendulum.toml
//! valgrind --tool=callgrind target/release/examples/steps 10000 [--floor]
//! valgrind --tool=callgrind target/release/examples/steps 30000 [--floor]
//! ```
//!
//! The difference of the two callgrind counts, per function, divided by
//! 20 000 is the instruction count of one macro step without the setup
//! (docs/performance.md, "Profiling").
//!
//! `--system FILE` runs that system file instead of the oscillator pair (its
//! workspace FMUs are packaged first, so run it from the workspace);
//! `--order 0` extrapolates the oscillator pair's inputs with k = 0 instead of
//! k = 1; `--first-steps K` prints the wall time of each of the first K macro
//! steps (one-off costs such as the "auto" parallel decision at step 3 show
//! there).

use tether_bench::{floor, Case};
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
    let on_floor = args.iter().any(|a| a == "--floor");
    let spec = match option("--system") {
        Some(_) if on_floor => fail("--floor runs the oscillator pair only, not --system"),
        Some(path) => {
            let mut spec =
                SystemSpec::from_file(std::path::Path::new(path)).unwrap_or_else(|e| fail(e));
            package_workspace_fmus(&spec);
            spec.experiment.stop = spec.experiment.start + steps as f64 * spec.experiment.step;
            spec
        }
        None => case.spec(),
    };
    // Errors from here on return through `run`, so that the simulation and
    // the FMUs' unpacked copies are dropped (their temporary directories
    // removed) before the process exits.
    if let Err(e) = run(&case, &spec, steps, first, on_floor) {
        fail(e);
    }
}

/// Packages the workspace FMUs that `spec` names by their file name
/// (`target/fmus/link.fmu` is the crate `link`), as the examples refer to them.
fn package_workspace_fmus(spec: &SystemSpec) {
    let names = tether_fmu_build::workspace_fmu_names().unwrap_or_else(|e| fail(e));
    for instance in &spec.instances {
        let stem = instance.fmu.file_stem().map(|s| s.to_string_lossy());
        if let Some(name) = stem.filter(|s| names.iter().any(|n| n == s)) {
            if let Err(e) = tether_fmu_build::workspace_fmu(&name) {
                fail(format!("cannot package the {name} FMU: {e}"));
            }
        }
    }
}

/// Tether's macro steps, or with `on_floor` the C floor's.
fn run(
    case: &Case,
    spec: &SystemSpec,
    steps: u64,
    first: usize,
    on_floor: bool,
) -> Result<(), String> {
    let mut sim = Simulation::new(spec).map_err(|e| e.to_string())?;
    if on_floor {
        let fmu = Fmu::open(&case.spec().instances[0].fmu).map_err(|e| e.to_string())?;
        let lambda0 = sim.unknowns()[0];
        let result = floor(case, &fmu, lambda0)?;
        println!(
            "{steps} macro steps of the C floor, {:.3} µs per step",
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
