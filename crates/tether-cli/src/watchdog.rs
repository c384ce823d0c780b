//! A thread that watches the FMI calls in progress while a run goes on
//! (`tether_fmi::calls_in_progress`, polled every 50 ms):
//!
//! - an in-process call past its instance's `call_timeout` cannot be stopped,
//!   so the run ends: the results file gets every accepted row and the trailer
//!   naming the instance, the call and the time, the extraction folders are
//!   removed, exit code 1 (an isolated instance's host is killed by the
//!   library instead, and the run ends with the same kind of error);
//! - any call running for [`REPORT_AFTER`] without a time-out is reported once,
//!   so a hang is never silent.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tether_master::spec::Isolation;
use tether_master::SystemSpec;

/// How long a call runs before the watchdog says so.
pub const REPORT_AFTER: Duration = Duration::from_secs(10);

const POLL: Duration = Duration::from_millis(50);

/// Stops the watchdog when dropped.
pub struct Watchdog {
    stop: Arc<AtomicBool>,
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

/// What bounds each instance's calls.
#[derive(Clone, Copy)]
enum Limit {
    /// Nothing: long calls are reported.
    None,
    /// The watchdog ends the run after this many seconds (in-process).
    Watchdog(f64),
    /// The library kills the host (isolated, with a time-out).
    Library,
}

fn limits(spec: &SystemSpec) -> HashMap<String, Limit> {
    spec.instances
        .iter()
        .map(|i| {
            let limit = match (i.call_timeout, i.isolation) {
                (None, _) => Limit::None,
                // A host on another machine enforces it as an isolated one does.
                (Some(_), _) if i.host.is_some() => Limit::Library,
                (Some(t), Isolation::None) => Limit::Watchdog(t),
                (Some(_), Isolation::Process) => Limit::Library,
            };
            (i.name.clone(), limit)
        })
        .collect()
}

/// Starts watching the calls of `spec`'s instances.
pub fn start(spec: &SystemSpec) -> Watchdog {
    let stop = Arc::new(AtomicBool::new(false));
    let limits = limits(spec);
    let stopped = Arc::clone(&stop);
    std::thread::Builder::new()
        .name("tether-watchdog".into())
        .spawn(move || watch(&limits, &stopped))
        .ok();
    Watchdog { stop }
}

fn watch(limits: &HashMap<String, Limit>, stop: &AtomicBool) {
    // When each call in progress was first seen, and whether it was reported.
    let mut seen: HashMap<(usize, u64), (Instant, bool)> = HashMap::new();
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(POLL);
        let now = Instant::now();
        let calls = tether_fmi::calls_in_progress();
        seen.retain(|key, _| calls.iter().any(|c| c.key == *key));
        for c in calls {
            let (since, reported) = seen.entry(c.key).or_insert((now, false));
            let running = now - *since;
            // Copies on worker threads are named `<instance>#<n>`.
            let instance = c.call.instance.split('#').next().unwrap_or_default();
            let call = &c.call;
            match limits.get(instance).copied().unwrap_or(Limit::None) {
                Limit::Watchdog(limit) if running.as_secs_f64() >= limit => {
                    if stop.load(Ordering::SeqCst) {
                        return;
                    }
                    crate::exit_guard::stop_now(&format!(
                        "instance '{}': {} at t={} did not return within the call time-out of {limit} s (the FMU runs in-process and cannot be stopped: the run ends)",
                        call.instance, call.function, call.time
                    ));
                }
                Limit::None if running >= REPORT_AFTER && !*reported => {
                    *reported = true;
                    crate::say!(
                        "warning: instance '{}' has been inside {} at t={} for {} s (Ctrl-C stops the run; --call-timeout ends such calls)",
                        call.instance,
                        call.function,
                        call.time,
                        running.as_secs()
                    );
                }
                _ => {}
            }
        }
    }
}
