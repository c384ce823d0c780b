//! The faults themselves, struck from inside `fmi2DoStep`.

use std::cell::Cell;
use std::time::Duration;

use tether_fmu_kit::model::Restore;

/// What goes wrong from `at` on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    None,
    Segfault,
    Abort,
    Exit0,
    Exit3,
    EndlessLoop,
    LogFlood,
    SlowCalls,
    HelperThenSegfault,
    ForkedChildExits,
    ForkedChildLingersThenSegfault,
    Helper,
    RestoreIgnored,
    RestoreNoisy,
    OutputsDrift,
    AbortAtExit,
    Barrier,
}

impl Mode {
    /// The value of the `mode` parameter.
    pub fn from_index(i: i32) -> Option<Mode> {
        Some(match i {
            0 => Mode::None,
            1 => Mode::Segfault,
            2 => Mode::Abort,
            3 => Mode::Exit0,
            4 => Mode::Exit3,
            5 => Mode::EndlessLoop,
            6 => Mode::LogFlood,
            7 => Mode::SlowCalls,
            8 => Mode::HelperThenSegfault,
            9 => Mode::ForkedChildExits,
            10 => Mode::ForkedChildLingersThenSegfault,
            11 => Mode::Helper,
            12 => Mode::RestoreIgnored,
            13 => Mode::RestoreNoisy,
            14 => Mode::OutputsDrift,
            15 => Mode::AbortAtExit,
            16 => Mode::Barrier,
            _ => return None,
        })
    }
}

#[derive(Clone, Debug)]
pub struct Fault {
    pub mode: Mode,
    pub at: f64,
    pub delay: f64,
    pub pause: f64,
    pub flood: u32,
    /// Mode 16: the instances that meet in the step from `at`.
    pub peers: u32,
    /// Mode 13: the largest offset the step after a restore adds to every
    /// state.
    pub noise: f64,
    /// Mode 13: the state of the pseudo-random offsets (xorshift64), so that
    /// two steps from one restored state end in different states.
    pub seed: Cell<u64>,
    /// Mode 13: the offset the next `fmi2DoStep` adds to the states before it
    /// integrates (0 when no restore came before it): state that
    /// `fmi2SetFMUstate` leaves behind, invisible in the outputs until then.
    pub pending: Cell<f64>,
    /// Mode 14: how many times the outputs were evaluated from `at` on.
    pub reads: Cell<u64>,
}

impl Fault {
    /// Runs at the start of every `fmi2DoStep` from communication point `t`.
    pub fn strike(&self, t: f64, h: f64) {
        if self.delay > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(self.delay));
        }
        // The first step whose communication point is `at` (up to rounding) or later.
        if self.mode == Mode::None || t < self.at - 0.5 * h {
            return;
        }
        match self.mode {
            Mode::None => {}
            Mode::Segfault => crate::crash(),
            Mode::Abort => std::process::abort(),
            Mode::Exit0 => std::process::exit(0),
            Mode::Exit3 => std::process::exit(3),
            Mode::EndlessLoop => loop {
                std::hint::black_box(t);
                std::hint::spin_loop();
            },
            Mode::LogFlood => {
                for n in 0..self.flood {
                    crate::log_warning(n, t);
                }
            }
            Mode::SlowCalls => std::thread::sleep(Duration::from_secs_f64(self.pause)),
            Mode::HelperThenSegfault => {
                crate::start_helper();
                crate::crash()
            }
            // Only in the step from `at` itself: one child, not one per step.
            Mode::ForkedChildExits if t < self.at + 0.5 * h => crate::fork_and_exit_in_child(),
            Mode::ForkedChildExits => {}
            Mode::ForkedChildLingersThenSegfault => {
                crate::fork_lingering_child();
                crate::crash()
            }
            Mode::Helper if t < self.at + 0.5 * h => crate::start_helper(),
            Mode::AbortAtExit => crate::abort_at_exit(),
            Mode::Barrier if t < self.at + 0.5 * h => crate::barrier(self.peers),
            Mode::Barrier => {}
            Mode::Helper | Mode::RestoreIgnored | Mode::RestoreNoisy | Mode::OutputsDrift => {}
        }
    }

    /// What `fmi2SetFMUstate` does when the instance is at `t`: mode 12
    /// restores the time but not the states once `t` reaches `at` (after the master's setup check); mode
    /// 13 restores the states exactly (the outputs read back are those of the
    /// saved state) but leaves an offset behind for the next step
    /// ([`Fault::disturb`]): the step repeated after a restore is not the same.
    pub fn restore(&self, t: f64) -> Restore {
        if t < self.at {
            return Restore::Exact;
        }
        match self.mode {
            Mode::RestoreIgnored => Restore::KeepStates,
            Mode::RestoreNoisy => {
                let mut x = self.seed.get();
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                self.seed.set(x);
                // Uniform in [-noise, noise].
                let unit = (x >> 11) as f64 / (1u64 << 53) as f64;
                self.pending.set(self.noise * (2.0 * unit - 1.0));
                Restore::Exact
            }
            _ => Restore::Exact,
        }
    }

    /// Runs on the outputs at every evaluation (every `fmi2GetReal` of an
    /// output) at time `t`: mode 14 adds `noise` times the count of earlier
    /// evaluations from `at` on to the first output, so that two reads with no
    /// step between them differ.
    pub fn drift(&self, t: f64, y: &mut [f64]) {
        if self.mode == Mode::OutputsDrift && t >= self.at {
            let n = self.reads.get();
            self.reads.set(n + 1);
            y[0] += self.noise * n as f64;
        }
    }

    /// Runs at the start of every `fmi2DoStep`, on the states it starts from:
    /// mode 13 adds the offset its last restore left behind.
    pub fn disturb(&self, x: &mut [f64]) {
        let e = self.pending.replace(0.0);
        if e != 0.0 {
            x.iter_mut().for_each(|x| *x += e);
        }
    }
}
