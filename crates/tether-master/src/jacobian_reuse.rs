//! Jacobian reuse (`[coupling] jacobian = "reuse"`, beyond the paper): the
//! perturbed runs are made only when the interface Jacobian is due; in
//! between it is kept and corrected by Broyden rank-one updates from each
//! step's own secant, the predicted and the corrected point
//! (docs/algorithm.md, "Jacobian reuse").

use serde::{Deserialize, Serialize};

use crate::solve::Jacobians;

/// `[coupling] jacobian`: when the perturbed runs are made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JacobianMode {
    /// Every macro step (the paper).
    #[default]
    EveryStep,
    /// Only when due: the last correction changed g otherwise than the
    /// Jacobian predicted, the Jacobian is older than `jacobian_max_age`
    /// steps, the step size changed by more than a factor 1.25 since it was
    /// made, or the polynomials' degree is still growing (start-up).
    Reuse,
}

impl std::str::FromStr for JacobianMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "every_step" => Ok(JacobianMode::EveryStep),
            "reuse" => Ok(JacobianMode::Reuse),
            other => Err(format!(
                "unknown jacobian mode '{other}': expected every_step or reuse"
            )),
        }
    }
}

/// A Jacobian predicts a step well when the actual change of g differs from
/// the predicted one by at most this fraction of the predicted change.
const MISMATCH: f64 = 0.2;

/// When the Jacobian is due, and its Broyden updates.
pub(crate) struct Reuse {
    max_age: u64,
    /// Steps since the Jacobian was made from perturbed runs (None: never).
    age: Option<u64>,
    /// The step size it was made for.
    h: f64,
    /// The last correction did not go as the Jacobian predicted.
    mispredicted: bool,
    /// Δu = u^c − u^p, Δg = g^c − g^p, and J·Δu of the last step.
    du: Vec<f64>,
    dg: Vec<f64>,
    predicted: Vec<f64>,
}

impl Reuse {
    pub fn new(max_age: u64, unknowns: usize, rows: usize) -> Reuse {
        Reuse {
            max_age,
            age: None,
            h: 0.0,
            mispredicted: false,
            du: vec![0.0; unknowns],
            dg: vec![0.0; rows],
            predicted: vec![0.0; rows],
        }
    }

    /// Whether this step makes the perturbed runs: in start-up (`growing`),
    /// after a misprediction, at the age limit, or when H changed.
    pub fn due(&self, h: f64, growing: bool) -> bool {
        let Some(age) = self.age else {
            return true;
        };
        let ratio = h / self.h;
        growing || self.mispredicted || age >= self.max_age || !(0.8..=1.25).contains(&ratio)
    }

    /// The Jacobian was just made from perturbed runs for step size `h`.
    pub fn made(&mut self, h: f64) {
        self.age = Some(0);
        self.h = h;
    }

    /// After an accepted step: compare the change of g from the predicted
    /// to the corrected point (`g_p`, `g_c`, every level the method uses)
    /// with the Jacobian's prediction `J·(u_c − u_p)`; a mismatch above 20 %
    /// makes the next step recompute the Jacobian, otherwise the Broyden
    /// update `J += (Δg − J·Δu)·Δuᵀ/(Δuᵀ·Δu)` takes the secant in.
    pub fn after_step(
        &mut self,
        jac: &mut Jacobians,
        (u_p, u_c): (&[f64], &[f64]),
        (g_p, g_c): (&[f64], &[f64]),
    ) {
        if let Some(age) = &mut self.age {
            *age += 1;
        }
        for ((d, c), p) in self.du.iter_mut().zip(u_c).zip(u_p) {
            *d = c - p;
        }
        for ((d, c), p) in self.dg.iter_mut().zip(g_c).zip(g_p) {
            *d = c - p;
        }
        self.predicted.fill(0.0);
        for (m, &du) in self.du.iter().enumerate() {
            for (p, j) in self.predicted.iter_mut().zip(jac.column_mut(m).iter()) {
                *p += j * du;
            }
        }
        let norm = |v: &mut dyn Iterator<Item = f64>| v.fold(0.0, |m: f64, x| m.max(x.abs()));
        let predicted = norm(&mut self.predicted.iter().copied());
        let miss = norm(&mut self.dg.iter().zip(&self.predicted).map(|(d, p)| d - p));
        self.mispredicted = miss.is_nan() || miss > MISMATCH * predicted;
        let du2: f64 = self.du.iter().map(|d| d * d).sum();
        if self.mispredicted || du2 == 0.0 {
            return;
        }
        for (m, &du) in self.du.iter().enumerate() {
            let scale = du / du2;
            let residual = self.dg.iter().zip(&self.predicted);
            for (j, (d, p)) in jac.column_mut(m).iter_mut().zip(residual) {
                *j += (d - p) * scale;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a linear g the secant is exact: one Broyden update moves a wrong
    /// Jacobian onto the true one along Δu, and the true one predicts well.
    #[test]
    fn broyden_takes_in_the_secant_and_flags_mispredictions() {
        let mut jac = Jacobians::new(2, 1);
        let truth = [[2.0, 1.0], [0.5, 3.0]];
        jac.column_mut(0)
            .copy_from_slice(&[truth[0][0], truth[1][0]]);
        jac.column_mut(1)
            .copy_from_slice(&[truth[0][1], truth[1][1]]);
        let mut reuse = Reuse::new(10, 2, 2);
        reuse.made(1e-3);
        let (u_p, u_c) = ([1.0, 2.0], [1.5, 1.0]);
        let g_p = [0.3, -0.2];
        let g = |u: [f64; 2]| {
            [
                g_p[0] + truth[0][0] * (u[0] - u_p[0]) + truth[0][1] * (u[1] - u_p[1]),
                g_p[1] + truth[1][0] * (u[0] - u_p[0]) + truth[1][1] * (u[1] - u_p[1]),
            ]
        };
        reuse.after_step(&mut jac, (&u_p, &u_c), (&g_p, &g(u_c)));
        assert!(!reuse.mispredicted && !reuse.due(1e-3, false));
        assert!(reuse.due(2e-3, false), "H doubled");
        // A Jacobian off by 5 % predicts well enough: the update makes it
        // exact along Δu.
        for m in 0..2 {
            for j in jac.column_mut(m) {
                *j *= 1.05;
            }
        }
        reuse.after_step(&mut jac, (&u_p, &u_c), (&g_p, &g(u_c)));
        assert!(!reuse.mispredicted);
        let (du, dg) = ([0.5, -1.0], [g(u_c)[0] - g_p[0], g(u_c)[1] - g_p[1]]);
        for (r, dg) in dg.iter().enumerate() {
            let jdu = jac.get(0, r, 0) * du[0] + jac.get(0, r, 1) * du[1];
            assert!((jdu - dg).abs() < 1e-12, "{jdu} {dg}");
        }
        // Off by a factor 2: a misprediction, the next step recomputes.
        for m in 0..2 {
            for j in jac.column_mut(m) {
                *j *= 2.0;
            }
        }
        reuse.after_step(&mut jac, (&u_p, &u_c), (&g_p, &g(u_c)));
        assert!(reuse.mispredicted && reuse.due(1e-3, false));
        assert!(reuse.due(1e-3, true), "start-up always recomputes");
    }
}
