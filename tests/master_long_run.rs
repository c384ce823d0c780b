//! Long runs: the resident memory of a coupled run with rollback stays flat over a
//! million macro steps. Ignored by default (about a minute in release); run it with
//!
//!     cargo test --release -p tether-tests --test master_long_run -- --ignored --nocapture
//!
//! The result is recorded in docs/reliability.md.

use tether_master::{Observer, Sample, Simulation, SystemSpec};
use tether_tests::fmi::{oscillator_fmu, rss_bytes};

const STEPS: u64 = 1_000_000;
const EVERY: u64 = 100_000;

/// Records nothing; reads the RSS every `EVERY` macro steps and checks every row.
#[derive(Default)]
struct RssProbe {
    rss: Vec<(u64, u64)>,
    rows: u64,
}

impl Observer for RssProbe {
    fn start(&mut self, _columns: &[String]) -> std::io::Result<()> {
        Ok(())
    }

    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()> {
        assert!(sample.values.iter().all(|v| v.is_finite()));
        self.rows += 1;
        if sample.step.is_multiple_of(EVERY) {
            self.rss.push((sample.step, rss_bytes()));
        }
        Ok(())
    }

    fn finish(&mut self, failure: Option<&str>) -> std::io::Result<()> {
        assert_eq!(failure, None);
        Ok(())
    }
}

#[test]
#[ignore = "a million macro steps; see the module docs for the command"]
fn memory_stays_flat_over_a_million_macro_steps_with_rollback() {
    let fmu = oscillator_fmu();
    let text = format!(
        r#"
        [experiment]
        stop = {stop}
        step = 1e-3

        [method]
        kind = "baumgarte"
        beta = 2e-3
        gamma = 1e-6

        [[instance]]
        name = "mass1"
        fmu = "{fmu}"
        parameters = {{ m = 1.0, exact = true }}

        [[instance]]
        name = "mass2"
        fmu = "{fmu}"
        parameters = {{ m = 2.0, exact = true }}

        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"
        "#,
        stop = STEPS as f64 * 1e-3,
        fmu = fmu.display()
    );
    let spec = SystemSpec::from_toml(&text).expect("system");
    let mut sim = Simulation::new(&spec).expect("setup");
    assert_eq!(sim.total_steps(), STEPS);
    let mut probe = RssProbe::default();
    let stats = sim.run(&mut [&mut probe], &mut |_, _| {}).expect("run");
    assert_eq!(probe.rows, STEPS + 1);
    let instance = &stats.instances[0];
    // Baumgarte repeats every macro step: the states were set back at least once a step.
    assert!(instance.state_sets >= STEPS, "{instance:?}");
    println!("macro steps: {}", stats.macro_steps);
    println!("{instance:?}");
    for (step, rss) in &probe.rss {
        println!(
            "RSS after {step:>7} steps: {:.2} MiB",
            *rss as f64 / 1048576.0
        );
    }
    // From the first checkpoint after the start (allocator warm) to the end.
    let warm = probe.rss[1].1;
    let peak = probe.rss[1..].iter().map(|r| r.1).max().unwrap();
    let growth = peak.saturating_sub(warm);
    println!(
        "growth from step {EVERY} to {STEPS}: {:.1} KiB",
        growth as f64 / 1024.0
    );
    assert!(
        growth < 1 << 20,
        "RSS grew by {growth} bytes over {} macro steps",
        STEPS - EVERY
    );
}
