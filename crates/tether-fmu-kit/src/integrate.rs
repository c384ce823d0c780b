//! One communication step of the continuous states: the model's exact step if it has
//! one, else Dop853 (ode_solvers) with rtol = atol = `tolerance`.
//!
//! The system is integrated in autonomous form: the elapsed time τ = t − t_c is an
//! extra state with τ' = 1, and the model sees t = t_c + τ. ode_solvers 0.6.2
//! evaluates Dop853's 12th stage at the wrong time (its c₁₂ is 0 instead of 1), which
//! makes non-autonomous right-hand sides, such as any model with an interpolated
//! input, inaccurate (∫₀¹ 2t dt comes out as 0.99968 at rtol 1e-6) and slow. The
//! stage coefficients a_ij are right, so the autonomous form is exact again.

use std::cell::RefCell;

use ode_solvers::{DVector, Dop853, OutputType, SVector, System};

use crate::input::{eval_all, InputJet};
use crate::model::Model;

struct Rhs<'a, M> {
    model: &'a M,
    t_c: f64,
    inputs: &'a [InputJet],
    u: RefCell<Vec<f64>>,
}

impl<M: Model> Rhs<'_, M> {
    /// `y = [x…, τ]`.
    fn eval(&self, y: &[f64], dy: &mut [f64]) {
        let n = y.len() - 1;
        let tau = y[n];
        let mut u = self.u.borrow_mut();
        eval_all(self.inputs, tau, &mut u);
        self.model
            .derivatives(self.t_c + tau, &y[..n], &u, &mut dy[..n]);
        dy[n] = 1.0;
    }
}

impl<M: Model> System<f64, DVector<f64>> for Rhs<'_, M> {
    fn system(&self, _t: f64, y: &DVector<f64>, dy: &mut DVector<f64>) {
        self.eval(y.as_slice(), dy.as_mut_slice());
    }
}

impl<M: Model, const N: usize> System<f64, SVector<f64, N>> for Rhs<'_, M> {
    fn system(&self, _t: f64, y: &SVector<f64, N>, dy: &mut SVector<f64, N>) {
        self.eval(y.as_slice(), dy.as_mut_slice());
    }
}

/// Advances `x` from `t_c` to `t_c + h` with the inputs as Taylor polynomials around
/// `t_c`; returns how (for the log) or why it failed.
#[inline]
pub fn step<M: Model>(
    model: &M,
    t_c: f64,
    h: f64,
    x: &mut [f64],
    inputs: &[InputJet],
    tolerance: f64,
) -> Result<&'static str, String> {
    if x.is_empty() {
        return Ok("no states");
    }
    if model.exact_step(t_c, h, x, inputs) {
        return settle(x, t_c + h).map(|()| "exact step");
    }
    dop853(model, t_c, h, x, inputs, tolerance, false)
}

/// [`step`] with Dop853: a separate, never inlined function, so that a model's
/// exact step does not carry the integrator's set-up in its path.
///
/// `x` holds the model's states. Models with up to 15 states integrate
/// `[x…, τ]` as a fixed-size vector on the stack; larger ones as a heap
/// vector, which ode_solvers allocates anew for every intermediate result
/// (hundreds of allocations per step: slower, and slower still in a process
/// with more than one thread, where every allocation takes a lock). Both run
/// the same arithmetic; `heap` forces the heap vector (for the test that
/// shows it).
#[inline(never)]
fn dop853<M: Model>(
    model: &M,
    t_c: f64,
    h: f64,
    x: &mut [f64],
    inputs: &[InputJet],
    tolerance: f64,
    heap: bool,
) -> Result<&'static str, String> {
    let rhs = Rhs {
        model,
        t_c,
        inputs,
        u: RefCell::new(vec![0.0; inputs.len()]),
    };
    let end = |end: Option<&[f64]>, x: &mut [f64]| -> Result<(), String> {
        let end = end.ok_or("Dop853 returned no solution")?;
        x.copy_from_slice(&end[..x.len()]);
        Ok(())
    };
    macro_rules! integrate {
        ($y0:expr) => {{
            let mut solver = match model.max_step().filter(|&max| max > 0.0 && max < h) {
                // Dop853's defaults (safety 0.9, β 0, step factors 1/3..6, automatic
                // first step, 100 000 steps, stiffness check every 1000), but at most
                // `max` per step.
                Some(max) => Dop853::from_param(
                    rhs,
                    0.0,
                    h,
                    h,
                    $y0,
                    tolerance,
                    tolerance,
                    0.9,
                    0.0,
                    0.333,
                    6.0,
                    max,
                    0.0,
                    100_000,
                    1000,
                    OutputType::Sparse,
                ),
                None => Dop853::new(rhs, 0.0, h, h, $y0, tolerance, tolerance),
            };
            solver.set_output(OutputType::Sparse);
            solver
                .integrate()
                .map_err(|e| format!("Dop853 failed between t = {t_c} and t = {}: {e}", t_c + h))?;
            end(solver.y_out().last().map(|y| y.as_slice()), x)?;
        }};
    }
    macro_rules! fixed {
        ($($n:literal)*) => {
            // The model's own state count, a constant: only its arm is compiled.
            match const { M::DECLARATION.states.len() + 1 } {
                $($n if !heap && x.len() + 1 == $n => integrate!(SVector::<f64, $n>::from_iterator(
                    x.iter().copied().chain([0.0])
                )),)*
                _ => integrate!(DVector::from_iterator(
                    x.len() + 1,
                    x.iter().copied().chain([0.0])
                )),
            }
        };
    }
    fixed!(2 3 4 5 6 7 8 9 10 11 12 13 14 15 16);
    settle(x, t_c + h).map(|()| "Dop853")
}

/// Checks that the states at `t`, the end of a step, are finite, and sets the subnormal
/// ones (nonzero, below 2.2e-308 in magnitude) to the zero of their sign. A model that
/// settles to rest decays into subnormal numbers, on which common processors compute
/// many times slower than on normal ones: without this a long run would slow down step
/// by step. It is the kit's own arithmetic, not the process's floating-point mode, and a
/// step whose states are not subnormal is unchanged bit for bit.
#[inline]
fn settle(x: &mut [f64], t: f64) -> Result<(), String> {
    if x.iter()
        .all(|v| (f64::MIN_POSITIVE..f64::INFINITY).contains(&v.abs()))
    {
        return Ok(());
    }
    settle_small(x, t)
}

/// `v`, or the zero of its sign if it is subnormal: an input's value or derivative as
/// the kit stores it when a master sets it. A master's values decay with the FMUs' (see
/// [`settle`]).
#[inline]
pub fn settled(v: f64) -> f64 {
    if v.abs() < f64::MIN_POSITIVE {
        0.0f64.copysign(v)
    } else {
        v
    }
}

/// [`settle`] where a state is zero, subnormal or not finite.
#[cold]
#[inline(never)]
fn settle_small(x: &mut [f64], t: f64) -> Result<(), String> {
    for v in x.iter_mut() {
        if v.abs() < f64::MIN_POSITIVE {
            *v = 0.0f64.copysign(*v);
        }
    }
    not_finite(x, t)
}

#[cold]
#[inline(never)]
fn not_finite(x: &[f64], t: f64) -> Result<(), String> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("state {i} is not finite ({}) at t = {t}", x[i])),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    use super::*;
    use crate::tests::Decay;
    use crate::Parameters;

    /// Counts the allocations of the calling thread.
    struct Counting;

    thread_local! {
        static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    }

    // SAFETY: forwards every call unchanged to the system allocator.
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            ALLOCATIONS.with(|n| n.set(n.get() + 1));
            // SAFETY: the caller's contract is passed on unchanged.
            unsafe { System.alloc(layout) }
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: the caller's contract is passed on unchanged.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    #[global_allocator]
    static COUNTING: Counting = Counting;

    /// One Dop853 step of ẋ = u − k·x under a ramp input: the state and the
    /// number of allocations it took.
    fn step_decay(heap: bool) -> (f64, u64) {
        let model =
            Decay::new(&Parameters::new(&Decay::DECLARATION, &[1.0, 1.0], &[], &[])).unwrap();
        let inputs = [InputJet {
            value: 0.5,
            d1: 2.0,
            d2: -1.0,
        }];
        let mut x = [1.0];
        let before = ALLOCATIONS.with(Cell::get);
        dop853(&model, 0.3, 0.25, &mut x, &inputs, 1e-10, heap).unwrap();
        (x[0], ALLOCATIONS.with(Cell::get) - before)
    }

    /// Small models integrate on the stack: a handful of allocations a step
    /// (ode_solvers' stage and output lists) instead of one for every
    /// intermediate vector, with the same arithmetic, bit for bit.
    #[test]
    fn small_models_step_on_the_stack_with_the_same_result() {
        let (on_stack, stack_allocations) = step_decay(false);
        let (on_heap, heap_allocations) = step_decay(true);
        println!("allocations in one step: {stack_allocations} on the stack, {heap_allocations} on the heap");
        assert_eq!(on_stack.to_bits(), on_heap.to_bits());
        // The closed form of x(0.55) from x(0.3) = 1, k = 1, u = 0.5 + 2s − s²/2.
        let exact = {
            let (h, k) = (0.25_f64, 1.0_f64);
            // x(h) = e^{−kh}x0 + ∫₀ʰ e^{−k(h−s)} u(s) ds, u(s) = a + b s + c s²
            let (a, b, c) = (0.5, 2.0, -0.5);
            let e = (-k * h).exp();
            let int0 = (1.0 - e) / k;
            let int1 = h / k - (1.0 - e) / (k * k);
            let int2 = h * h / k - 2.0 * h / (k * k) + 2.0 * (1.0 - e) / (k * k * k);
            e + a * int0 + b * int1 + c * int2
        };
        assert!((on_stack - exact).abs() < 1e-9, "{on_stack} vs {exact}");
        assert!(
            stack_allocations <= 8 && heap_allocations > 50,
            "allocations: stack {stack_allocations}, heap {heap_allocations}"
        );
    }
}
