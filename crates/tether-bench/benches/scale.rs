//! How the macro step's cost grows with the number of coupled instances
//! (docs/performance.md, "Large systems"): an oscillator chain up to
//! N = 1024, a pendulum chain and a binary tree of links up to N = 256.
//! Per size: setup time and resident memory per instance, the number of
//! perturbation groups, µs per macro step and per step and instance, and
//! each phase's share; then N = 8 and the largest N alternated in one run,
//! the ratio of their per-instance costs (the goal: at most 2).
//!
//! `cargo bench -p tether-bench -- scale`; `TETHER_BENCH_REPS` alternated
//! repetitions (default 10, medians reported).

use std::time::{Duration, Instant};

use tether_bench::median;
use tether_bench::scale::Family;
use tether_master::{PhaseTimes, Simulation};

fn reps() -> usize {
    std::env::var("TETHER_BENCH_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10)
}

/// Resident set size in bytes (Linux), else `None`.
fn resident() -> Option<f64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: f64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096.0)
}

/// Macro steps per timed block: about 20 ms of work, at least 20 steps.
fn block(n: usize) -> u64 {
    (20_000 / n as u64).max(20)
}

/// A simulation of `family` with `n` instances, room for `reps` blocks
/// after 20 warm-up steps; its setup time and resident growth.
fn build(family: Family, n: usize, reps: usize) -> (Simulation, Duration, Option<f64>) {
    let spec = family.spec(n, 20 + block(n) * (reps as u64 + 1));
    let before = resident();
    let clock = Instant::now();
    let mut sim =
        Simulation::new(&spec).unwrap_or_else(|e| panic!("{} N = {n}: {e}", family.name()));
    let setup = clock.elapsed();
    let grown = resident().zip(before).map(|(a, b)| a - b);
    sim.time_phases(true);
    for _ in 0..20 {
        sim.step().expect("macro step");
    }
    (sim, setup, grown)
}

/// Seconds per macro step over one block, and the phases it added.
fn time_block(sim: &mut Simulation, n: usize) -> (f64, PhaseTimes) {
    let before = sim.stats().times;
    let steps = block(n);
    let clock = Instant::now();
    for _ in 0..steps {
        sim.step().expect("macro step");
    }
    let per_step = clock.elapsed().as_secs_f64() / steps as f64;
    let after = sim.stats().times;
    let phases = PhaseTimes {
        predictor: after.predictor - before.predictor,
        jacobian: after.jacobian - before.jacobian,
        solve: after.solve - before.solve,
        corrector: after.corrector - before.corrector,
        ..after
    };
    (per_step, phases)
}

fn shares(p: &PhaseTimes) -> String {
    let parts = [p.predictor, p.jacobian, p.solve, p.corrector].map(|d| d.as_secs_f64());
    let total: f64 = parts.iter().sum::<f64>().max(1e-300);
    let [a, b, c, d] = parts.map(|x| 100.0 * x / total);
    format!("{a:.0}/{b:.0}/{c:.0}/{d:.0}")
}

fn table(family: Family, sizes: &[usize], reps: usize) {
    println!(
        "\n{} (Method 1, index 2, H = 1e-3; medians of {reps} blocks)",
        family.name()
    );
    println!("| system | N | groups | setup / instance | µs per step | µs per step and instance | phases P/J/S/C % |");
    for &n in sizes {
        let (mut sim, setup, grown) = build(family, n, reps);
        let mut times = Vec::new();
        let mut phases = PhaseTimes::default();
        for _ in 0..reps {
            let (t, p) = time_block(&mut sim, n);
            times.push(t);
            phases.predictor += p.predictor;
            phases.jacobian += p.jacobian;
            phases.solve += p.solve;
            phases.corrector += p.corrector;
        }
        let step = median(times);
        let memory = grown.map_or("n/a".to_string(), |g| {
            format!("{:.1}", g / 1024.0 / n as f64)
        });
        println!(
            "| {} | {n} | {} | {:.0} µs, {memory} KiB | {:.1} | {:.3} | {} |",
            family.name(),
            sim.perturbation_groups(),
            setup.as_secs_f64() * 1e6 / n as f64,
            step * 1e6,
            step * 1e6 / n as f64,
            shares(&phases)
        );
    }
}

/// N = 8 and `largest` alternated block by block: the ratio of their
/// median per-instance costs.
fn alternated(family: Family, largest: usize, reps: usize) {
    let (mut small, _, _) = build(family, 8, reps);
    let (mut large, _, _) = build(family, largest, reps);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        a.push(time_block(&mut small, 8).0 / 8.0);
        b.push(time_block(&mut large, largest).0 / largest as f64);
    }
    let (a, b) = (median(a), median(b));
    println!(
        "{}: per step and instance, N = 8 {:.3} µs, N = {largest} {:.3} µs (alternated): ratio {:.2} (goal ≤ 2)",
        family.name(),
        a * 1e6,
        b * 1e6,
        b / a
    );
}

/// The dense and the sparse solve of chain and tree matrices of size n:
/// where the sparse path takes over (`DENSE_MAX` in solve.rs).
fn crossover(reps: usize) {
    println!(
        "\nsolve of one n × n interface matrix (row scaling, LU, condition), µs: dense | sparse"
    );
    println!("{:>5} {:>17} {:>17}", "n", "chain", "tree");
    for n in [8, 16, 24, 32, 48, 64, 128, 256] {
        let (cd, cs) = tether_master::bench_hooks::solve_times(n, false, reps);
        let (td, ts) = tether_master::bench_hooks::solve_times(n, true, reps);
        println!(
            "{n:>5} {:>8.2} | {:>6.2} {:>8.2} | {:>6.2}",
            cd * 1e6,
            cs * 1e6,
            td * 1e6,
            ts * 1e6
        );
    }
}

fn main() {
    let wanted: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    if !(wanted.is_empty() || wanted.iter().any(|w| w == "scale")) {
        return;
    }
    let reps = reps();
    println!(
        "scale: {} logical CPUs; load {}",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
    crossover(reps);
    let chains = [2, 8, 32, 128, 256];
    table(Family::OscillatorChain, &[2, 8, 32, 128, 512, 1024], reps);
    table(Family::PendulumChain, &chains, reps);
    table(Family::Tree, &chains, reps);
    println!();
    alternated(Family::OscillatorChain, 1024, reps);
    alternated(Family::PendulumChain, 256, reps);
    alternated(Family::Tree, 256, reps);
}
