//! Intermediate update (FMI 3.0 §4.2.2): how an FMI 3.0 instance takes a polynomial
//! input over a step. The FMU calls `fmi3IntermediateUpdateCallback` at its internal
//! times; when it asks for inputs (`intermediateVariableSetRequested`), the callback
//! sets every input that has a polynomial to the polynomial's value at that time with
//! `fmi3SetFloat64`, which intermediate update mode allows for inputs declared
//! `intermediateUpdate="true"`.
//!
//! The instance environment handed to `fmi3InstantiateCoSimulation` is an [`Env3`]:
//! the instance's [`LogEnv`] first (so that the log callback finds it at the same
//! address), then the polynomials. It is boxed and lives until after
//! `fmi3FreeInstance`.

use std::ffi::c_void;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError};

use crate::logger::LogEnv;
use crate::raw::fmi3::*;

/// `fmi3SetFloat64`, as the callback calls it.
type SetFloat64 = unsafe extern "C" fn(
    fmi3Instance,
    *const fmi3ValueReference,
    usize,
    *const fmi3Float64,
    usize,
) -> fmi3Status;

/// The instance environment of an FMI 3.0 instance.
#[repr(C)]
pub(crate) struct Env3 {
    /// First: the log callback reads the environment as a [`LogEnv`].
    pub(crate) log: LogEnv,
    /// The inputs' polynomials, read by the intermediate update callback during
    /// `fmi3DoStep` and written between calls.
    polynomials: Mutex<Polynomials>,
    /// Whether `polynomials.failure` holds a failure: read after every step
    /// without taking the lock.
    failed: AtomicBool,
}

/// The inputs that take a polynomial, each its Taylor coefficients around the time
/// it was given.
#[derive(Debug, Default)]
struct Polynomials {
    /// The FMU's instance and its `fmi3SetFloat64` (set once instantiated).
    target: Option<(fmi3Instance, SetFloat64)>,
    /// The inputs with a polynomial: their value references, as one callback sets
    /// them.
    vrs: Vec<fmi3ValueReference>,
    /// Per input of `vrs`: the time `t0` of its value, and its value and
    /// derivatives there (`coefficients[0]` the value, `[j]` the j-th derivative).
    polynomials: Vec<(f64, Vec<f64>)>,
    /// The values set in a callback (reused).
    values: Vec<f64>,
    /// The first failed `fmi3SetFloat64` of the callback: its status and time.
    failure: Option<(fmi3Status, f64)>,
}

impl Polynomials {
    /// Input `i` of `vrs` is held: it has no polynomial any more.
    fn remove(&mut self, i: usize) {
        self.vrs.swap_remove(i);
        self.polynomials.swap_remove(i);
    }
}

impl Env3 {
    /// A boxed environment for the instance called `instance`.
    pub(crate) fn new(instance: &str) -> Box<Env3> {
        Box::new(Env3 {
            log: LogEnv::plain(instance),
            polynomials: Mutex::new(Polynomials::default()),
            failed: AtomicBool::new(false),
        })
    }

    /// The `instanceEnvironment` pointer.
    pub(crate) fn pointer(self: &mut Box<Self>) -> *mut c_void {
        let env: *mut Env3 = &mut **self;
        env.cast()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Polynomials> {
        self.polynomials
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// The instance the callback sets inputs on.
    pub(crate) fn set_target(&self, instance: fmi3Instance, set: SetFloat64) {
        self.lock().target = Some((instance, set));
    }

    /// Each input of `vrs` with derivatives of order ≥ 1 in `derivative_vrs` takes
    /// the polynomial u(t) = Σ_j c_j (t − t0)^j / j! from the coming step on
    /// ([`begin_step`](Self::begin_step) sets t0): c_0 its value in `values`, c_j
    /// its derivative of order j (`orders`, `derivatives`; 0 where none is given).
    /// An input without derivatives is held (no polynomial). No allocation once
    /// every input has had one.
    pub(crate) fn set_polynomials(
        &self,
        vrs: &[fmi3ValueReference],
        values: &[f64],
        derivative_vrs: &[fmi3ValueReference],
        orders: &[i32],
        derivatives: &[f64],
    ) {
        let degree = orders.iter().copied().max().unwrap_or(0).max(0) as usize;
        let mut p = self.lock();
        for (&vr, &value) in vrs.iter().zip(values) {
            let found = p.vrs.iter().position(|&v| v == vr);
            let given = derivative_vrs.iter().zip(orders).zip(derivatives);
            let mut given = given.filter(|((&v, &o), _)| v == vr && o >= 1).peekable();
            if given.peek().is_none() {
                if let Some(i) = found {
                    p.remove(i);
                }
                continue;
            }
            let i = found.unwrap_or_else(|| {
                p.vrs.push(vr);
                p.polynomials.push((f64::NAN, Vec::new()));
                p.vrs.len() - 1
            });
            let (t0, c) = &mut p.polynomials[i];
            *t0 = f64::NAN;
            c.clear();
            c.push(value);
            c.resize(degree + 1, 0.0);
            for ((_, &order), &d) in given {
                c[order as usize] = d;
            }
        }
    }

    /// The polynomials given for the coming step start at `t`.
    pub(crate) fn begin_step(&self, t: f64) {
        let mut p = self.lock();
        for (t0, _) in &mut p.polynomials {
            if t0.is_nan() {
                *t0 = t;
            }
        }
    }

    /// The inputs `vrs` are held from now on (a value was set on them).
    pub(crate) fn hold(&self, vrs: &[fmi3ValueReference]) {
        let mut p = self.lock();
        for vr in vrs {
            if let Some(i) = p.vrs.iter().position(|v| v == vr) {
                p.remove(i);
            }
        }
    }

    /// The failure of an `fmi3SetFloat64` made in the callback since the last
    /// call, if any: its status and the intermediate time.
    pub(crate) fn take_failure(&self) -> Option<(fmi3Status, f64)> {
        if !self.failed.swap(false, Ordering::Acquire) {
            return None;
        }
        self.lock().failure.take()
    }

    /// Sets every input with a polynomial to its value at `time`.
    fn update(&self, time: f64) {
        let mut guard = self.lock();
        let p = &mut *guard;
        let Some((instance, set)) = p.target else {
            return;
        };
        if p.vrs.is_empty() || p.failure.is_some() {
            return;
        }
        p.values.clear();
        let values = p.polynomials.iter().map(|(t0, c)| evaluate(c, time - t0));
        p.values.extend(values);
        // SAFETY: `instance` is the live instance that is calling back (the callback
        // runs inside its fmi3DoStep), `set` its fmi3SetFloat64; `vrs` and `values`
        // hold `vrs.len()` items each, valid across the call.
        let status = unsafe {
            set(
                instance,
                p.vrs.as_ptr(),
                p.vrs.len(),
                p.values.as_ptr(),
                p.values.len(),
            )
        };
        if status != fmi3OK && status != fmi3Warning {
            p.failure = Some((status, time));
            self.failed.store(true, Ordering::Release);
        }
    }
}

/// u(t0 + dt) from the value and derivatives at t0, in Horner's form
/// c0 + dt·(c1 + dt/2·(c2 + dt/3·(…))).
pub(crate) fn evaluate(c: &[f64], dt: f64) -> f64 {
    let Some((&value, derivatives)) = c.split_first() else {
        return 0.0;
    };
    let mut acc = 0.0;
    for (j, &d) in derivatives.iter().enumerate().rev() {
        acc = if j + 1 == derivatives.len() {
            d
        } else {
            d + dt / (j + 2) as f64 * acc
        };
    }
    value + dt * acc
}

/// `fmi3IntermediateUpdateCallback`: sets the inputs' polynomials at
/// `intermediateUpdateTime` when the FMU asks for inputs; never asks to return
/// early. A panic stops here (the FMU is C).
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe extern "C" fn intermediate_update(
    env: fmi3InstanceEnvironment,
    time: fmi3Float64,
    set_requested: fmi3Boolean,
    _get_allowed: fmi3Boolean,
    _step_finished: fmi3Boolean,
    _can_return_early: fmi3Boolean,
    early_return_requested: *mut fmi3Boolean,
    _early_return_time: *mut fmi3Float64,
) {
    if !early_return_requested.is_null() {
        // SAFETY: a non-NULL out-argument points at one writable fmi3Boolean for the
        // duration of the callback (the standard's contract).
        unsafe { *early_return_requested = fmi3False };
    }
    if env.is_null() || set_requested == fmi3False {
        return;
    }
    // SAFETY: `env` is the `Env3` handed to fmi3InstantiateCoSimulation, boxed in the
    // owning instance and freed only after fmi3FreeInstance; only shared references
    // to it exist while the FMU runs.
    let env = unsafe { &*env.cast_const().cast::<Env3>() };
    let _ = catch_unwind(AssertUnwindSafe(|| env.update(time)));
}

#[cfg(test)]
mod tests {
    use super::evaluate;

    #[test]
    fn the_polynomial_is_its_taylor_series() {
        let c = [1.0, 2.0, -1.0, 6.0];
        for dt in [0.0, 0.1, 0.5, 2.0] {
            let exact = 1.0 + 2.0 * dt - 0.5 * dt * dt + dt * dt * dt;
            assert!((evaluate(&c, dt) - exact).abs() < 1e-14, "{dt}");
        }
        // The kit's form of degree 2, bit for bit: value + dt·(d1 + 0.5·dt·d2).
        let (v, d1, d2, dt) = (0.3_f64, -1.7_f64, 4.1_f64, 0.013_f64);
        assert_eq!(
            evaluate(&[v, d1, d2], dt).to_bits(),
            (v + dt * (d1 + 0.5 * dt * d2)).to_bits()
        );
        assert_eq!(evaluate(&[v, d1], dt).to_bits(), (v + dt * d1).to_bits());
    }
}
