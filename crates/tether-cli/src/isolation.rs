//! `--isolate` and `--call-timeout`: out-of-process instances and call
//! time-outs for every instance of a system (docs/reliability.md).

use tether_master::spec::Isolation;
use tether_master::SystemSpec;

/// Isolates every instance (`isolate`) and gives every instance without its
/// own `call_timeout` the time-out `seconds`.
pub fn apply(isolate: bool, seconds: Option<f64>, spec: &mut SystemSpec) -> anyhow::Result<()> {
    if let Some(t) = seconds.filter(|t| !t.is_finite() || *t <= 0.0) {
        anyhow::bail!("--call-timeout {t}: expected a finite time in seconds > 0");
    }
    for instance in &mut spec.instances {
        if isolate {
            instance.isolation = Isolation::Process;
        }
        if instance.call_timeout.is_none() {
            instance.call_timeout = seconds;
        }
    }
    Ok(())
}
