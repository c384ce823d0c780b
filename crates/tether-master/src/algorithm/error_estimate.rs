//! The local error estimate of adaptive macro steps (Milne's device for the
//! predictor/corrector pair, docs/algorithm.md "Adaptive macro steps").
//!
//! The predictor and the corrector run of a step start from the same saved
//! states and differ only in their input polynomials: the extrapolation
//! through u_N, …, u_{N−k} and the interpolation through u_{N+1}, u_N, …,
//! u_{N−k+1}. Both input errors are proportional to the same derivative
//! u^{(k+1)}, with the node polynomials Π_p(τ) = τ(τ+H)…(τ+kH) and
//! Π_c(τ) = (τ−H)τ…(τ+(k−1)H). A state that integrates the input once (a
//! velocity under a force) takes the error ∫₀^H of each, so the corrector's
//! local error is −C_k times the predictor's with C_k = |∫Π_c|/|∫Π_p| = 1,
//! 1/5, 1/9 for k = 0, 1, 2, and the difference of the two runs' states is
//! (1 + C_k) times the predictor's error: the corrected state's local error
//! is C_k/(1 + C_k)·|y^p − y^c| = 1/2, 1/6, 1/10 of that difference.
//!
//! The states are the coupled outputs the position- and velocity-level
//! conditions read (positions, orientations, velocities of the coupling
//! points; the values of coupling variables). Outputs only the
//! acceleration level reads respond to the input without integrating it, so
//! the corrector has almost no error in them at T_{N+1} and they are left
//! out; so are the multipliers, whose error is one order lower than the
//! states' and reaches the states only through the FMUs' integration.
//!
//! The relation takes u_{N+1} for a sample of λ(T_{N+1}). Measured on the
//! double pendulum, the corrected multipliers are instead the values that
//! close the condition (k = 0: λ at the step's midpoint; k = 1:
//! λ(T_{N+1}) − λ̈H²/12), with which the joint's impulse over the step is
//! one order more accurate than assumed: there the estimate is 81 to 2054
//! times the corrected run's local error, mostly the predicted run's error
//! (docs/algorithm.md).

use crate::coupling::rows::{RowLevel, View};
use crate::step_control::StepControl;
use crate::system::System;

/// C_k/(1 + C_k) for k = 0, 1, 2 (module documentation).
const MILNE: [f64; 3] = [1.0 / 2.0, 1.0 / 6.0, 1.0 / 10.0];

/// Which coupled outputs are states, and the tolerances.
pub(crate) struct ErrorEstimate {
    /// Per instance, the coupled-output slots the estimate covers.
    states: Vec<Vec<usize>>,
    /// Per instance and slot of `states`: the largest |y| at the accepted
    /// points so far, the scale of the relative tolerance.
    peaks: Vec<Vec<f64>>,
    rtol: f64,
    atol: f64,
}

impl ErrorEstimate {
    /// The scales of the relative tolerance so far (the master's state).
    pub fn peaks(&self) -> Vec<Vec<f64>> {
        self.peaks.clone()
    }

    /// Back to scales of [`peaks`](Self::peaks).
    pub fn set_peaks(&mut self, peaks: &[Vec<f64>]) {
        for (mine, saved) in self.peaks.iter_mut().zip(peaks) {
            mine.copy_from_slice(saved);
        }
    }

    /// Find the outputs that the position and velocity levels of the rows
    /// read: those whose change (relative 1e-6) changes some row at these
    /// levels, at the current outputs and unknowns of `system`.
    pub fn new(system: &System, levels: &[RowLevel], control: &StepControl) -> ErrorEstimate {
        let nu = system.coupling.len();
        let u: Vec<f64> = system.history.iter().map(|h| h[0]).collect();
        let levels: Vec<RowLevel> = levels
            .iter()
            .copied()
            .filter(|l| matches!(l, RowLevel::Position | RowLevel::Velocity))
            .collect();
        let eval = |outputs: &[Vec<f64>], out: &mut Vec<f64>| {
            out.clear();
            let view = View::at(outputs, &u);
            for &level in &levels {
                let mut rows = vec![0.0; nu];
                system.coupling.eval(level, &view, &mut rows);
                out.extend(rows);
            }
        };
        let (mut base, mut bumped) = (Vec::new(), Vec::new());
        eval(&system.outputs, &mut base);
        let mut outputs = system.outputs.clone();
        let mut states = vec![Vec::new(); outputs.len()];
        for s in 0..outputs.len() {
            for slot in 0..outputs[s].len() {
                let y = outputs[s][slot];
                outputs[s][slot] = y + 1e-6 * y.abs().max(1.0);
                eval(&outputs, &mut bumped);
                outputs[s][slot] = y;
                if base.iter().zip(&bumped).any(|(a, b)| a != b) {
                    states[s].push(slot);
                }
            }
        }
        let peaks = states
            .iter()
            .zip(&system.outputs)
            .map(|(slots, y)| slots.iter().map(|&slot| y[slot].abs()).collect())
            .collect();
        ErrorEstimate {
            peaks,
            states,
            rtol: control.rtol,
            atol: control.atol,
        }
    }

    /// The step's error norm: the largest estimated local error of a state,
    /// `C_k/(1 + C_k)·|y^p − y^c|`, over `atol + rtol·Y` where Y is the
    /// largest |y| of the state so far (this step's included); ≤ 1 meets the
    /// tolerances. `degree` is the corrector's k. Scaling with the largest
    /// |y| so far, not the current one, keeps an oscillating state from
    /// forcing tiny steps at each of its zero crossings; it is also the scale
    /// of the measured goal (docs/algorithm.md).
    pub fn norm(&self, predicted: &[Vec<f64>], corrected: &[Vec<f64>], degree: usize) -> f64 {
        let milne = MILNE[degree.min(2)];
        let mut worst: f64 = 0.0;
        let instances = self.states.iter().zip(&self.peaks);
        for (((slots, peaks), p), c) in instances.zip(predicted).zip(corrected) {
            for (&slot, &peak) in slots.iter().zip(peaks) {
                let (yp, yc) = (p[slot], c[slot]);
                let scale = self.atol + self.rtol * peak.max(yp.abs()).max(yc.abs());
                worst = worst.max(milne * (yp - yc).abs() / scale);
            }
        }
        worst
    }

    /// Note the accepted point's states in the peaks.
    pub fn accept(&mut self, accepted: &[Vec<f64>]) {
        let instances = self.states.iter().zip(&mut self.peaks);
        for ((slots, peaks), y) in instances.zip(accepted) {
            for (&slot, peak) in slots.iter().zip(peaks) {
                *peak = peak.max(y[slot].abs());
            }
        }
    }
}
