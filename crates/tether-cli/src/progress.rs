//! Progress of a run in simulated time: a bar on a terminal (once the run
//! has taken a second), a line every 10 s otherwise (a log file, CI), so a
//! long run is never silent. Off with `--quiet`.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// How often a non-terminal gets a progress line: 10 s, or
/// `TETHER_PROGRESS_INTERVAL` seconds.
fn line_interval() -> Duration {
    std::env::var("TETHER_PROGRESS_INTERVAL")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .map_or(Duration::from_secs(10), Duration::from_secs_f64)
}

pub struct Progress {
    start: f64,
    step: f64,
    total: u64,
    /// Decimals of a time on the macro grid.
    decimals: usize,
    enabled: bool,
    terminal: bool,
    bar: Option<indicatif::ProgressBar>,
    began: Instant,
    last_line: Instant,
    interval: Duration,
}

impl Progress {
    pub fn new(start: f64, step: f64, total: u64, enabled: bool) -> Progress {
        let now = Instant::now();
        Progress {
            start,
            step,
            total,
            decimals: (-step.log10().floor()).clamp(0.0, 12.0) as usize,
            enabled,
            terminal: std::io::stderr().is_terminal(),
            bar: None,
            began: now,
            last_line: now,
            interval: line_interval(),
        }
    }

    /// After macro step `n` of the run.
    pub fn update(&mut self, n: u64) {
        if !self.enabled || !(n.is_multiple_of(64) || n == self.total) {
            return;
        }
        let now = Instant::now();
        let t = self.start + n as f64 * self.step;
        let stop = self.start + self.total as f64 * self.step;
        let d = self.decimals;
        if self.terminal {
            if self.bar.is_none() && now - self.began >= Duration::from_secs(1) {
                let bar = indicatif::ProgressBar::new(self.total);
                bar.set_style(
                    indicatif::ProgressStyle::with_template("{bar:40} t = {msg}  {eta} left")
                        .expect("valid template"),
                );
                self.bar = Some(bar);
            }
            if let Some(bar) = &self.bar {
                bar.set_message(format!("{t:.d$} of {stop:.d$}"));
                bar.set_position(n);
            }
        } else if now - self.last_line >= self.interval && n < self.total {
            self.last_line = now;
            let elapsed = (now - self.began).as_secs_f64();
            let fraction = n as f64 / self.total.max(1) as f64;
            let left = elapsed * (1.0 - fraction) / fraction.max(f64::MIN_POSITIVE);
            crate::say!(
                "progress: t = {t:.d$} of {stop:.d$} ({:.0} %), {elapsed:.0} s elapsed, about {left:.0} s left",
                100.0 * fraction
            );
        }
    }

    /// Clears the bar.
    pub fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
