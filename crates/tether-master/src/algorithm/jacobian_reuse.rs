//! Jacobian reuse (`[coupling] jacobian = "reuse"`, beyond the paper): the
//! perturbed runs are made only when the interface Jacobian is due; in
//! between it is kept and corrected by Broyden rank-one updates from each
//! step's own secant, the predicted and the corrected point. A correction
//! the reused Jacobian mispredicted is made again with a fresh one
//! (docs/algorithm.md, "Jacobian reuse").

use crate::linalg::solve::Jacobians;
use crate::state_bytes::{Pass, Passed};

/// A Jacobian predicts a correction well when on every row the actual change
/// of g differs from the predicted one by at most this fraction of the larger
/// of the predicted change and the row's residual before the correction.
const MISMATCH: f64 = 0.2;

/// When the Jacobian is due, and its Broyden updates.
#[derive(Debug, Clone)]
pub(crate) struct Reuse {
    max_age: u64,
    /// Steps since the Jacobian was made from perturbed runs (None: never).
    age: Option<u64>,
    /// The step size it was made for.
    h: f64,
    /// The last correction did not go as the Jacobian predicted.
    mispredicted: bool,
    /// Δu = u^c − u^p, Δg = g^c − g^p, and J·Δu of the last step (every
    /// level, level after level).
    du: Vec<f64>,
    dg: Vec<f64>,
    predicted: Vec<f64>,
    /// Per row: Σ Δu_m² over the unknowns m on the row's pattern.
    row_du2: Vec<f64>,
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
            row_du2: vec![0.0; unknowns],
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

    /// After a correction: compare the change of g from the predicted to
    /// the corrected point (`g_p`, `g_c`, every level the method uses) with
    /// the Jacobian's prediction `J·(u_c − u_p)`, row by row. Whether the
    /// Jacobian mispredicted it: on some row and level the actual change
    /// differs from the predicted one by more than 20 % of the larger of
    /// the predicted change and the residual |g_p| the correction started
    /// from. Row by row, because the rows of one level differ in units and
    /// scale (a joint's position condition in metres beside a force port's
    /// balance in newtons): over all rows, a constraint row's miss would
    /// hide below a port row's predicted change.
    pub fn mispredicted(
        &mut self,
        jac: &mut Jacobians,
        (u_p, u_c): (&[f64], &[f64]),
        (g_p, g_c): (&[f64], &[f64]),
    ) -> bool {
        let nu = self.du.len();
        for ((d, c), p) in self.du.iter_mut().zip(u_c).zip(u_p) {
            *d = c - p;
        }
        for ((d, c), p) in self.dg.iter_mut().zip(g_c).zip(g_p) {
            *d = c - p;
        }
        self.predicted.fill(0.0);
        self.row_du2.fill(0.0);
        for (m, &du) in self.du.iter().enumerate() {
            let (rows, values) = jac.column_mut(m);
            let levels = values.chunks_exact(rows.len().max(1));
            for (column, predicted) in levels.zip(self.predicted.chunks_exact_mut(nu)) {
                for (j, &r) in column.iter().zip(rows) {
                    predicted[r] += j * du;
                }
            }
            for &r in rows {
                self.row_du2[r] += du * du;
            }
        }
        let rows = self.dg.iter().zip(&self.predicted).zip(g_p);
        self.mispredicted = rows.into_iter().any(|((dg, predicted), gp)| {
            let miss = (dg - predicted).abs();
            miss.is_nan() || miss > MISMATCH * predicted.abs().max(gp.abs())
        });
        self.mispredicted
    }

    /// The step is accepted: the Jacobian ages by one step and, unless it
    /// mispredicted the step's correction ([`Self::mispredicted`], which
    /// makes the next step recompute it), takes the step's secant in by
    /// Schubert's sparse Broyden update, row by row on its pattern:
    /// `J[r,m] += (Δg − J·Δu)_r · Δu_m / Σ Δu_m'²`, the sum over the
    /// unknowns m' on row r's pattern. Off the pattern the entries stay
    /// structural zeros, and `J·Δu = Δg` holds afterwards on every row with
    /// some Δu on its pattern.
    pub fn accepted(&mut self, jac: &mut Jacobians) {
        if let Some(age) = &mut self.age {
            *age += 1;
        }
        if self.mispredicted {
            return;
        }
        let nu = self.du.len();
        for (m, &du) in self.du.iter().enumerate() {
            let (rows, values) = jac.column_mut(m);
            let levels = values.chunks_exact_mut(rows.len().max(1));
            let residuals = self
                .dg
                .chunks_exact(nu)
                .zip(self.predicted.chunks_exact(nu));
            for (column, (dg, predicted)) in levels.zip(residuals) {
                for (j, &r) in column.iter_mut().zip(rows) {
                    if self.row_du2[r] > 0.0 {
                        *j += (dg[r] - predicted[r]) * (du / self.row_du2[r]);
                    }
                }
            }
        }
    }
}

impl Reuse {
    /// Its numbers through `p`, for the saved state's bytes.
    pub(crate) fn pass(&mut self, p: &mut Pass) -> Passed {
        let mut made = self.age.is_some();
        let mut age = self.age.unwrap_or(0);
        p.bool(&mut made)?;
        p.u64(&mut age)?;
        self.age = made.then_some(age);
        p.f64(&mut self.h)?;
        p.bool(&mut self.mispredicted)?;
        p.f64s(&mut self.du, "the unknowns")?;
        p.f64s(&mut self.dg, "the rows")?;
        p.f64s(&mut self.predicted, "the rows")?;
        p.f64s(&mut self.row_du2, "the unknowns")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// J·Δu, every level, from the stored entries.
    fn times(jac: &mut Jacobians, du: &[f64], levels: usize) -> Vec<f64> {
        let n = du.len();
        let mut out = vec![0.0; n * levels];
        for (m, &d) in du.iter().enumerate() {
            let (rows, values) = jac.column_mut(m);
            for (l, column) in values.chunks_exact(rows.len().max(1)).enumerate() {
                for (j, &r) in column.iter().zip(rows) {
                    out[l * n + r] += j * d;
                }
            }
        }
        out
    }

    fn scale(jac: &mut Jacobians, n: usize, factor: f64) {
        for m in 0..n {
            for j in jac.column_mut(m).1 {
                *j *= factor;
            }
        }
    }

    /// On a linear g the secant is exact: one Broyden update moves a wrong
    /// Jacobian onto the true one along Δu, and the true one predicts well.
    #[test]
    fn broyden_takes_in_the_secant_and_flags_mispredictions() {
        let mut jac = Jacobians::dense(2, 1);
        let truth = [[2.0, 1.0], [0.5, 3.0]];
        jac.column_mut(0)
            .1
            .copy_from_slice(&[truth[0][0], truth[1][0]]);
        jac.column_mut(1)
            .1
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
        reuse.mispredicted(&mut jac, (&u_p, &u_c), (&g_p, &g(u_c)));
        reuse.accepted(&mut jac);
        assert!(!reuse.mispredicted && !reuse.due(1e-3, false));
        assert!(reuse.due(2e-3, false), "H doubled");
        // A Jacobian off by 5 % predicts well enough: the update makes it
        // exact along Δu.
        scale(&mut jac, 2, 1.05);
        reuse.mispredicted(&mut jac, (&u_p, &u_c), (&g_p, &g(u_c)));
        reuse.accepted(&mut jac);
        assert!(!reuse.mispredicted);
        let (du, dg) = ([0.5, -1.0], [g(u_c)[0] - g_p[0], g(u_c)[1] - g_p[1]]);
        for (jdu, dg) in times(&mut jac, &du, 1).iter().zip(dg) {
            assert!((jdu - dg).abs() < 1e-12, "{jdu} {dg}");
        }
        // Off by a factor 2: a misprediction, the next step recomputes.
        scale(&mut jac, 2, 2.0);
        reuse.mispredicted(&mut jac, (&u_p, &u_c), (&g_p, &g(u_c)));
        reuse.accepted(&mut jac);
        assert!(reuse.mispredicted && reuse.due(1e-3, false));
        assert!(reuse.due(1e-3, true), "start-up always recomputes");
    }

    /// On a sparse pattern (two levels, unknown 2 touching only row 2):
    /// one update from a Jacobian off by 5 % makes the secant exact on every
    /// row and level, and leaves the entries off the pattern zero: an
    /// update of the dense Jacobian would have filled them.
    #[test]
    fn schubert_keeps_the_pattern_and_makes_the_secant_exact() {
        // Columns: u0 → rows 0, 1; u1 → rows 0, 1, 2; u2 → row 2.
        let pattern: [&[usize]; 3] = [&[0, 1], &[0, 1, 2], &[2]];
        let mut jac = Jacobians::pattern(&pattern, 2);
        // The true Jacobians of a linear g, per level, on the pattern.
        let truth =
            |l: usize, r: usize, m: usize| (1 + l) as f64 * (1.0 + r as f64 + 0.5 * m as f64);
        for (m, rows) in pattern.iter().enumerate() {
            let values = jac.column_mut(m).1;
            for l in 0..2 {
                for (k, &r) in rows.iter().enumerate() {
                    values[l * rows.len() + k] = 1.05 * truth(l, r, m);
                }
            }
        }
        let (u_p, u_c) = ([0.0, 1.0, -1.0], [0.2, 0.9, -0.7]);
        let du: Vec<f64> = u_c.iter().zip(&u_p).map(|(c, p)| c - p).collect();
        let g_p = [0.1, 0.2, 0.3, -0.1, -0.2, -0.3];
        let mut g_c = g_p;
        for (m, rows) in pattern.iter().enumerate() {
            for l in 0..2 {
                for &r in rows.iter() {
                    g_c[l * 3 + r] += truth(l, r, m) * du[m];
                }
            }
        }
        let mut reuse = Reuse::new(10, 3, 6);
        reuse.made(1e-3);
        reuse.mispredicted(&mut jac, (&u_p, &u_c), (&g_p, &g_c));
        reuse.accepted(&mut jac);
        assert!(!reuse.mispredicted);
        for (r, (jdu, dg)) in times(&mut jac, &du, 2)
            .iter()
            .zip(g_c.iter().zip(&g_p))
            .enumerate()
        {
            assert!((jdu - (dg.0 - dg.1)).abs() < 1e-12, "row {r}: {jdu}");
        }
        for (m, rows) in pattern.iter().enumerate() {
            assert_eq!(jac.column_mut(m).0, *rows, "the pattern is unchanged");
        }
    }

    /// Rows of different units on one level: a port row whose change the
    /// Jacobian predicts exactly does not hide a constraint row whose change
    /// it gets wrong by half, though the constraint row's miss is a millionth
    /// of the port row's change.
    #[test]
    fn a_misprediction_counts_row_by_row() {
        let mut jac = Jacobians::dense(2, 1);
        // Row 0: a constraint in metres, 1e-6 per unit of u0; row 1: a force
        // balance in newtons, 1 per unit of u1.
        jac.column_mut(0).1.copy_from_slice(&[1e-6, 0.0]);
        jac.column_mut(1).1.copy_from_slice(&[0.0, 1.0]);
        let mut reuse = Reuse::new(10, 2, 2);
        reuse.made(1e-3);
        let (u_p, u_c) = ([0.0, 0.0], [1.0, 1.0]);
        let g_p = [-1e-6, -1.0];
        // The constraint moved by half what was predicted, the port exactly.
        let g_c = [-0.5e-6, 0.0];
        assert!(reuse.mispredicted(&mut jac, (&u_p, &u_c), (&g_p, &g_c)));
        // Within 20 % on both rows: predicted well, and the secant goes in.
        let g_c = [-0.1e-6, 0.0];
        assert!(!reuse.mispredicted(&mut jac, (&u_p, &u_c), (&g_p, &g_c)));
        reuse.accepted(&mut jac);
        assert!((jac.column_mut(0).1[0] - 1.0e-6 + 0.05e-6).abs() < 1e-18);
        assert!(!reuse.due(1e-3, false));
    }
}
