//! Solving the linearised coupling conditions (eq. 68, 73–75) with an LU
//! factorisation and a condition check, on buffers reused across macro steps.
//!
//! The systems are small (one row per coupling unknown) and solved every macro
//! step, so the factorisation is a plain dense LU with partial pivoting on
//! preallocated column-major buffers: after the first solve of a given size no
//! step allocates. The operations are those of nalgebra's `LU::new`,
//! `try_inverse` and matrix–vector product in the same order, so the results are
//! bit for bit what `DMatrix::lu` gave before (checked by a test below).

#[cfg(test)]
use nalgebra::{DMatrix, DVector};

use crate::MasterError;

/// The interface Jacobians ∂g/∂u of every level a method evaluates
/// (position first), column after column: column `m` holds its rows of every
/// level in turn, so the finite difference in unknown `m` fills one
/// contiguous run of `levels × n` values.
#[derive(Debug, Default, Clone)]
pub(crate) struct Jacobians {
    n: usize,
    levels: usize,
    data: Vec<f64>,
}

impl Jacobians {
    /// Zero Jacobians of `levels` levels for `n` unknowns.
    pub fn new(n: usize, levels: usize) -> Jacobians {
        Jacobians {
            n,
            levels,
            data: vec![0.0; n * n * levels],
        }
    }

    /// Column `m` of every level, level after level.
    #[inline]
    pub fn column_mut(&mut self, m: usize) -> &mut [f64] {
        let len = self.levels * self.n;
        &mut self.data[m * len..(m + 1) * len]
    }

    /// Entry `(r, c)` of level `l`.
    #[inline]
    pub fn get(&self, l: usize, r: usize, c: usize) -> f64 {
        self.data[(c * self.levels + l) * self.n + r]
    }

    /// Level `l` into `a` (column-major `n × n`).
    pub fn level_into(&self, l: usize, a: &mut [f64]) {
        let n = self.n;
        for (c, column) in a.chunks_exact_mut(n).enumerate() {
            for (r, x) in column.iter_mut().enumerate() {
                *x = self.get(l, r, c);
            }
        }
    }

    /// `G^B = G + β Ġ + γ G̈` into `a` (column-major `n × n`) and
    /// `g^B = g + β ġ + γ g̈` into `b`, from `g` (the conditions of every
    /// level, level after level); a level is added with its weight when it
    /// is evaluated (`Some(index)`). Rows in `plain` (coupling variables and
    /// ports) keep their position level.
    pub fn baumgarte(
        &self,
        g: &[f64],
        velocity: Option<(usize, f64)>,
        acceleration: Option<(usize, f64)>,
        plain: &[usize],
        a: &mut [f64],
        b: &mut [f64],
    ) {
        let n = self.n;
        let stabilised = |level: &[f64], r: usize| {
            let mut sum = level[r];
            if let Some((v, beta)) = velocity {
                sum += beta * level[v * n + r];
            }
            if let Some((acc, gamma)) = acceleration {
                sum += gamma * level[acc * n + r];
            }
            sum
        };
        let len = self.levels * n;
        for c in 0..n {
            let column = &self.data[c * len..(c + 1) * len];
            for r in 0..n {
                a[r + c * n] = stabilised(column, r);
            }
        }
        for (r, x) in b.iter_mut().enumerate() {
            *x = stabilised(g, r);
        }
        for &r in plain {
            for c in 0..n {
                a[r + c * n] = self.get(0, r, c);
            }
            b[r] = g[r];
        }
    }
}

/// A reusable solver for `A x = b` with `n × n` systems.
#[derive(Debug, Default, Clone)]
pub(crate) struct Solver {
    n: usize,
    /// The system matrix, column-major; scaled and factorised in place.
    a: Vec<f64>,
    /// The right-hand side, scaled in place.
    b: Vec<f64>,
    /// Row-scaled copy of `a` (its 1-norm enters the condition estimate).
    scaled: Vec<f64>,
    /// Row swapped with row `i` at elimination step `i`.
    pivots: Vec<usize>,
    /// A⁻¹ of the scaled system, column-major.
    inverse: Vec<f64>,
    /// The solution.
    x: Vec<f64>,
}

impl Solver {
    /// Size the system to `n × n` (allocating only when `n` grows) and hand out
    /// the matrix (column-major, like nalgebra's storage) and right-hand side to
    /// fill. Their previous contents are unspecified.
    pub fn system(&mut self, n: usize) -> (&mut [f64], &mut [f64]) {
        if n != self.n {
            self.size(n);
        }
        (&mut self.a, &mut self.b)
    }

    fn size(&mut self, n: usize) {
        self.n = n;
        self.a.resize(n * n, 0.0);
        self.b.resize(n, 0.0);
        self.scaled.resize(n * n, 0.0);
        self.pivots.resize(n, 0);
        self.inverse.resize(n * n, 0.0);
        self.x.resize(n, 0.0);
    }

    /// Load level `l` of `jac` and of `g` (every level, level after level).
    pub fn load_level(&mut self, jac: &Jacobians, g: &[f64], l: usize) {
        let n = jac.n;
        let (sa, sb) = self.system(n);
        jac.level_into(l, sa);
        sb.copy_from_slice(&g[l * n..(l + 1) * n]);
    }

    /// Load `A` and `b` (copies, no allocation once sized).
    #[cfg(test)]
    pub fn load(&mut self, a: &DMatrix<f64>, b: &DVector<f64>) {
        let n = b.len();
        debug_assert_eq!(a.shape(), (n, n));
        let (sa, sb) = self.system(n);
        sa.copy_from_slice(a.as_slice());
        sb.copy_from_slice(b.as_slice());
    }

    /// Solve the loaded system. Rows are scaled to unit max-norm first
    /// (position, velocity and acceleration rows have very different
    /// magnitudes), then the 1-norm condition number of the scaled matrix is
    /// estimated from its inverse. A condition above `limit` or an exactly
    /// singular matrix is an error naming the time and the level.
    pub fn solve(
        &mut self,
        time: f64,
        level: &'static str,
        limit: f64,
    ) -> Result<&[f64], MasterError> {
        let singular = |condition: f64| MasterError::SingularJacobian {
            time,
            level,
            condition,
            limit,
        };
        let n = self.n;
        let a = &mut self.a;
        for i in 0..n {
            let s = (0..n).map(|j| a[i + j * n].abs()).fold(0.0, f64::max);
            if !(s.is_finite() && s > 0.0) {
                return Err(singular(f64::INFINITY));
            }
            let inv = 1.0 / s;
            for j in 0..n {
                a[i + j * n] *= inv;
            }
            self.b[i] /= s;
        }
        self.scaled.copy_from_slice(a);
        if !lu_in_place(a, &mut self.pivots, n) {
            return Err(singular(f64::INFINITY));
        }
        if !inverse(a, &self.pivots, &mut self.inverse, n) {
            return Err(singular(f64::INFINITY));
        }
        let condition = norm1(&self.scaled, n) * norm1(&self.inverse, n);
        if !(condition.is_finite() && condition <= limit) {
            return Err(singular(condition));
        }
        // x = A⁻¹ b, accumulated column by column.
        for i in 0..n {
            self.x[i] = self.inverse[i] * self.b[0];
        }
        for j in 1..n {
            let bj = self.b[j];
            for i in 0..n {
                self.x[i] += self.inverse[i + j * n] * bj;
            }
        }
        Ok(&self.x)
    }
}

/// LU with partial pivoting (first largest magnitude) in place: unit lower
/// factor below the diagonal, upper factor on and above. `false` if a pivot
/// column is all zero.
fn lu_in_place(a: &mut [f64], pivots: &mut [usize], n: usize) -> bool {
    for i in 0..n {
        let mut piv = i;
        let mut max = a[i + i * n].abs();
        for r in i + 1..n {
            let v = a[r + i * n].abs();
            if v > max {
                max = v;
                piv = r;
            }
        }
        pivots[i] = piv;
        let diag = a[piv + i * n];
        if diag == 0.0 {
            return false;
        }
        if piv != i {
            for j in 0..n {
                a.swap(i + j * n, piv + j * n);
            }
        }
        let inv_diag = 1.0 / diag;
        for r in i + 1..n {
            a[r + i * n] *= inv_diag;
        }
        for k in i + 1..n {
            let p = a[i + k * n];
            for r in i + 1..n {
                a[r + k * n] += -p * a[r + i * n];
            }
        }
    }
    true
}

/// The inverse from the factors: permuted identity, forward then backward
/// substitution, column by column. `false` on a zero diagonal.
fn inverse(lu: &[f64], pivots: &[usize], out: &mut [f64], n: usize) -> bool {
    out.fill(0.0);
    for i in 0..n {
        out[i + i * n] = 1.0;
    }
    for (i, &piv) in pivots.iter().enumerate().take(n) {
        if piv != i {
            for j in 0..n {
                out.swap(i + j * n, piv + j * n);
            }
        }
    }
    for c in 0..n {
        let col = &mut out[c * n..(c + 1) * n];
        for i in 0..n.saturating_sub(1) {
            let coeff = col[i];
            for r in i + 1..n {
                col[r] += -coeff * lu[r + i * n];
            }
        }
        for i in (0..n).rev() {
            let diag = lu[i + i * n];
            if diag == 0.0 {
                return false;
            }
            let coeff = col[i] / diag;
            col[i] = coeff;
            for r in 0..i {
                col[r] += -coeff * lu[r + i * n];
            }
        }
    }
    true
}

/// Largest column sum of magnitudes.
fn norm1(m: &[f64], n: usize) -> f64 {
    (0..n)
        .map(|j| m[j * n..(j + 1) * n].iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Solve `A x = b` once (allocates a solver; for setup code and tests).
#[cfg(test)]
pub(crate) fn solve(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    time: f64,
    level: &'static str,
    limit: f64,
) -> Result<DVector<f64>, MasterError> {
    let mut solver = Solver::default();
    solver.load(a, b);
    Ok(DVector::from_column_slice(
        solver.solve(time, level, limit)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_badly_scaled_but_regular_systems() {
        // One position row (~H²) and one plain row (~1).
        let a = DMatrix::from_row_slice(2, 2, &[1e-7, 2e-7, 3.0, -1.0]);
        let x_true = DVector::from_vec(vec![2.0, -1.0]);
        let b = &a * &x_true;
        let x = solve(&a, &b, 0.0, "position", 1e12).unwrap();
        assert!((x - x_true).amax() < 1e-12);
    }

    #[test]
    fn singular_matrices_are_reported_with_time_and_condition() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0 + 1e-15]);
        let b = DVector::from_vec(vec![1.0, 1.0]);
        let err = solve(&a, &b, 0.25, "baumgarte", 1e12)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("t = 0.25") && err.contains("condition"),
            "{err}"
        );
        let zero = DMatrix::zeros(1, 1);
        let err = solve(&zero, &DVector::from_vec(vec![1.0]), 1.0, "position", 1e12).unwrap_err();
        assert!(err.to_string().contains("inf"), "{err}");
        let rank_one = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]);
        let err = solve(&rank_one, &b, 2.0, "velocity", 1e12).unwrap_err();
        assert!(err.to_string().contains("t = 2"), "{err}");
    }

    /// The previous implementation, on nalgebra's LU: the reference for the
    /// bit-for-bit comparison.
    fn nalgebra_solve(a: &DMatrix<f64>, b: &DVector<f64>) -> Option<(DVector<f64>, f64)> {
        let n = a.nrows();
        let mut scaled = a.clone();
        let mut rhs = b.clone();
        for i in 0..n {
            let s = scaled.row(i).amax();
            scaled.row_mut(i).scale_mut(1.0 / s);
            rhs[i] /= s;
        }
        let inverse = scaled.clone().lu().try_inverse()?;
        let n1 = |m: &DMatrix<f64>| {
            m.column_iter()
                .map(|c| c.iter().map(|x| x.abs()).sum::<f64>())
                .fold(0.0, f64::max)
        };
        Some((&inverse * rhs, n1(&scaled) * n1(&inverse)))
    }

    #[test]
    fn matches_nalgebra_lu_bit_for_bit_and_reuses_its_buffers() {
        // A small deterministic generator (xorshift) for matrices of sizes 1..5
        // (nalgebra multiplies with its own loop up to 5 × 5).
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let mut solver = Solver::default();
        for trial in 0..500 {
            let n = 1 + trial % 5;
            let scale: Vec<f64> = (0..n).map(|i| 10f64.powi(3 * i as i32 - 6)).collect();
            let a = DMatrix::from_fn(n, n, |i, _| next() * scale[i]);
            let b = DVector::from_fn(n, |i, _| next() * scale[i]);
            let (expected, condition) =
                nalgebra_solve(&a, &b).expect("random matrices are regular");
            solver.load(&a, &b);
            match solver.solve(0.0, "position", f64::INFINITY) {
                Ok(x) => {
                    for i in 0..n {
                        assert_eq!(x[i].to_bits(), expected[i].to_bits(), "trial {trial}");
                    }
                }
                Err(e) => panic!("trial {trial}: {e}, nalgebra condition {condition}"),
            }
        }
    }

    #[test]
    fn jacobian_levels_combine_like_separate_matrices() {
        // Three levels of an n × n Jacobian, filled column by column as the
        // finite differences do, against one matrix per level. `plain` rows
        // are coupling variables: not stabilised.
        for (n, plain) in [(3, vec![1]), (3, vec![]), (1, vec![]), (1, vec![0])] {
            let levels = 3;
            let value = |l: usize, r: usize, c: usize| ((l * 7 + r * 3 + c) as f64).sin() * 1e3;
            let mut jac = Jacobians::new(n, levels);
            for c in 0..n {
                for (i, x) in jac.column_mut(c).iter_mut().enumerate() {
                    *x = value(i / n, i % n, c);
                }
            }
            let mats: Vec<DMatrix<f64>> = (0..levels)
                .map(|l| DMatrix::from_fn(n, n, |r, c| value(l, r, c)))
                .collect();
            let g: Vec<f64> = (0..levels * n).map(|i| (i as f64 + 0.5).cos()).collect();
            let (beta, gamma) = (0.3, 0.07);
            let (mut a, mut b) = (vec![0.0; n * n], vec![0.0; n]);
            jac.baumgarte(
                &g,
                Some((1, beta)),
                Some((2, gamma)),
                &plain,
                &mut a,
                &mut b,
            );
            for c in 0..n {
                for r in 0..n {
                    let mut expected = mats[0][(r, c)];
                    if !plain.contains(&r) {
                        expected += beta * mats[1][(r, c)];
                        expected += gamma * mats[2][(r, c)];
                    }
                    assert_eq!(
                        a[r + c * n].to_bits(),
                        expected.to_bits(),
                        "n = {n}, ({r}, {c})"
                    );
                }
            }
            for r in 0..n {
                let mut expected = g[r];
                if !plain.contains(&r) {
                    expected += beta * g[n + r];
                    expected += gamma * g[2 * n + r];
                }
                assert_eq!(b[r].to_bits(), expected.to_bits(), "n = {n}, row {r}");
            }
            let mut solver = Solver::default();
            solver.load_level(&jac, &g, 2);
            let (sa, sb) = solver.system(n);
            assert_eq!(sa, mats[2].as_slice());
            assert_eq!(sb, &g[2 * n..]);
        }
    }
}
