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

use crate::coupling::touched::Touched;
use crate::linalg::lu::{inverse, lu_in_place, norm1};
use crate::linalg::sparse_lu::{Singular, SparseLu};
use crate::state_bytes::{Pass, Passed};
use crate::MasterError;

/// The interface Jacobians ∂g/∂u of every level a method evaluates
/// (position first), on the pattern of the rows each unknown touches
/// ([`Touched`]): column `m` holds its touched rows of every level in turn,
/// so the finite difference in unknown `m` fills one contiguous run of
/// `levels × rows` values. Entries off the pattern are exact zeros.
#[derive(Debug, Default, Clone)]
pub(crate) struct Jacobians {
    n: usize,
    levels: usize,
    /// Column c's rows are `rows[ptr[c]..ptr[c + 1]]`, sorted.
    ptr: Vec<usize>,
    rows: Vec<usize>,
    data: Vec<f64>,
}

impl Jacobians {
    /// Zero Jacobians of `levels` levels on the pattern of `touched`.
    pub fn new(touched: &Touched, levels: usize) -> Jacobians {
        Jacobians {
            n: touched.row_ptr.len() - 1,
            levels,
            ptr: touched.row_ptr.clone(),
            rows: touched.rows.clone(),
            data: vec![0.0; touched.nnz() * levels],
        }
    }

    /// Zero Jacobians with every entry on the pattern (tests).
    #[cfg(test)]
    pub fn dense(n: usize, levels: usize) -> Jacobians {
        Jacobians {
            n,
            levels,
            ptr: (0..=n).map(|c| c * n).collect(),
            rows: (0..n * n).map(|i| i % n).collect(),
            data: vec![0.0; n * n * levels],
        }
    }

    /// Zero Jacobians on the pattern `columns` (column m's rows, sorted; tests).
    #[cfg(test)]
    pub fn pattern(columns: &[&[usize]], levels: usize) -> Jacobians {
        let mut ptr = vec![0];
        let mut rows = Vec::new();
        for column in columns {
            rows.extend_from_slice(column);
            ptr.push(rows.len());
        }
        Jacobians {
            n: columns.len(),
            levels,
            data: vec![0.0; rows.len() * levels],
            ptr,
            rows,
        }
    }

    /// The rows of column `m`, and its values of every level, level after level.
    #[inline]
    pub fn column_mut(&mut self, m: usize) -> (&[usize], &mut [f64]) {
        let (start, end) = (self.ptr[m], self.ptr[m + 1]);
        let values = &mut self.data[start * self.levels..end * self.levels];
        (&self.rows[start..end], values)
    }

    /// Column `m` of every level as the finite difference `(rows − g)/delta`
    /// on its pattern, from `rows` and `g` (every row of every level, level
    /// after level).
    pub fn difference(&mut self, m: usize, rows: &[f64], g: &[f64], delta: f64) {
        let n = self.n;
        let (pattern, column) = self.column_mut(m);
        let levels = rows.chunks_exact(n).zip(g.chunks_exact(n));
        for (values, (perturbed, g)) in column.chunks_exact_mut(pattern.len().max(1)).zip(levels) {
            for (j, &r) in values.iter_mut().zip(pattern) {
                *j = (perturbed[r] - g[r]) / delta;
            }
        }
    }

    /// Load every column into `solver`'s matrix, entry `k` of column `c`
    /// (row `r`) as `value(column values, rows in the column, k, r)`, and
    /// hand out its right-hand side.
    fn load<'s>(
        &self,
        solver: &'s mut Solver,
        value: impl Fn(&[f64], usize, usize, usize) -> f64,
    ) -> &'s mut [f64] {
        let n = self.n;
        let columns = (0..n).map(|c| {
            let (start, end) = (self.ptr[c], self.ptr[c + 1]);
            let values = &self.data[start * self.levels..end * self.levels];
            (c, &self.rows[start..end], values)
        });
        if solver.sparse.is_none() {
            let (a, b) = solver.system(n);
            a.fill(0.0);
            for (c, rows, column) in columns {
                for (k, &r) in rows.iter().enumerate() {
                    a[r + c * n] = value(column, rows.len(), k, r);
                }
            }
            return b;
        }
        let sparse = solver.sparse.as_mut().expect("checked above");
        for (c, rows, column) in columns {
            let start = sparse.column_start(c);
            for (k, &r) in rows.iter().enumerate() {
                sparse.values[start + k] = value(column, rows.len(), k, r);
            }
        }
        &mut sparse.x
    }

    /// Load level `l` of the Jacobians and of `g` (every row of every
    /// level, level after level) into `solver`.
    pub fn load_level(&self, solver: &mut Solver, g: &[f64], l: usize) {
        let n = self.n;
        let b = self.load(solver, |column, len, k, _| column[l * len + k]);
        b.copy_from_slice(&g[l * n..(l + 1) * n]);
    }

    /// `G^B = G + β Ġ + γ G̈` and `g^B = g + β ġ + γ g̈` into `solver`, from
    /// `g` (the conditions of every level, level after level); a level is
    /// added with its weight when it is evaluated (`Some(index)`). Rows
    /// marked in `plain` (coupling variables and ports) keep their position
    /// level.
    pub fn baumgarte(
        &self,
        solver: &mut Solver,
        g: &[f64],
        velocity: Option<(usize, f64)>,
        acceleration: Option<(usize, f64)>,
        plain: &[bool],
    ) {
        let stabilised = |level: &[f64], len: usize, k: usize, r: usize| {
            let mut sum = level[k];
            if plain[r] {
                return sum;
            }
            if let Some((v, beta)) = velocity {
                sum += beta * level[v * len + k];
            }
            if let Some((acc, gamma)) = acceleration {
                sum += gamma * level[acc * len + k];
            }
            sum
        };
        let n = self.n;
        let b = self.load(solver, stabilised);
        for (r, x) in b.iter_mut().enumerate() {
            *x = stabilised(g, n, r, r);
        }
    }
}

/// Largest number of unknowns always solved densely. The sparse LU is the
/// faster from about 16 unknowns on chain and tree patterns, where the dense
/// inverse's O(n³) starts to dominate (the `scale` benchmark, docs/performance.md);
/// 20 keeps every system of the fmpy cross-check (at most 17 unknowns) on the
/// dense path's arithmetic, bit for bit.
pub(crate) const DENSE_MAX: usize = 20;

/// A reusable solver for `A x = b` with `n × n` systems.
#[derive(Debug, Default)]
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
    /// The sparse path, for systems above [`DENSE_MAX`] unknowns.
    sparse: Option<SparseLu>,
}

impl Solver {
    /// A solver for Jacobians on the pattern of `touched`: sparse above
    /// [`DENSE_MAX`] unknowns when at most a quarter of the entries are on
    /// the pattern, dense otherwise.
    pub fn new(touched: &Touched) -> Solver {
        let n = touched.row_ptr.len() - 1;
        let mut solver = Solver::default();
        if n > DENSE_MAX && 4 * touched.nnz() <= n * n {
            let (ptr, rows) = (touched.row_ptr.clone(), touched.rows.clone());
            solver.sparse = Some(SparseLu::new(n, ptr, rows));
        }
        solver
    }

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
    /// taken from its inverse (dense path) or estimated from its LU factors
    /// (sparse path, [`crate::linalg::sparse_lu`]). A condition above `limit` or an
    /// exactly singular matrix is an error naming the time and the level.
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
            step: None,
        };
        if let Some(sparse) = &mut self.sparse {
            let condition = sparse.solve().map_err(|Singular(c)| singular(c))?;
            if !(condition.is_finite() && condition <= limit) {
                return Err(singular(condition));
            }
            return Ok(&sparse.x);
        }
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

/// Jacobians of a chain (tridiagonal) and of a binary tree (each node
/// coupled to its parent and children), with random entries on the
/// pattern: one column per node.
pub(crate) fn pattern_matrix(
    n: usize,
    tree: bool,
    seed: u64,
) -> (Vec<usize>, Vec<usize>, nalgebra::DMatrix<f64>) {
    let mut state = seed;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut ptr = vec![0];
    let mut rows = Vec::new();
    let mut a = nalgebra::DMatrix::zeros(n, n);
    for c in 0..n {
        let mut column: Vec<usize> = if tree {
            let mut v = vec![c, 2 * c + 1, 2 * c + 2];
            if c > 0 {
                v.push((c - 1) / 2);
            }
            v
        } else {
            vec![c.saturating_sub(1), c, c + 1]
        };
        column.retain(|&r| r < n);
        column.sort_unstable();
        column.dedup();
        for &r in &column {
            // Diagonally weighted, with row scales of 1e-6 … 1.
            let diagonal = if r == c { 4.0 } else { 0.0 };
            a[(r, c)] = (next() + diagonal) * 10f64.powi(-((r % 4) as i32) * 2);
        }
        rows.extend(column);
        ptr.push(rows.len());
    }
    (ptr, rows, a)
}

/// Seconds per solve of one matrix of [`pattern_matrix`] on the dense and on
/// the sparse path (medians of alternated blocks): where `DENSE_MAX` comes
/// from (`cargo bench -p tether-bench -- scale`).
pub fn solve_times(n: usize, tree: bool, reps: usize) -> (f64, f64) {
    let (ptr, rows, a) = pattern_matrix(n, tree, 0x9e37_79b9 + n as u64);
    let mut dense = Solver::default();
    let mut sparse = Solver {
        sparse: Some(SparseLu::new(n, ptr.clone(), rows.clone())),
        ..Solver::default()
    };
    let solves = (20_000 / (n * n).max(1)).clamp(20, 2_000);
    let time = |solver: &mut Solver| {
        let clock = std::time::Instant::now();
        for _ in 0..solves {
            if let Some(sp) = &mut solver.sparse {
                for c in 0..n {
                    for k in ptr[c]..ptr[c + 1] {
                        sp.values[k] = a[(rows[k], c)];
                    }
                }
                sp.x.fill(1.0);
            } else {
                let (m, b) = solver.system(n);
                m.copy_from_slice(a.as_slice());
                b.fill(1.0);
            }
            std::hint::black_box(solver.solve(0.0, "position", f64::INFINITY).is_ok());
        }
        clock.elapsed().as_secs_f64() / solves as f64
    };
    let (mut d, mut s) = (Vec::new(), Vec::new());
    for _ in 0..reps.max(1) {
        d.push(time(&mut dense));
        s.push(time(&mut sparse));
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(d), median(s))
}

impl Jacobians {
    /// Its numbers through `p`, for the saved state's bytes (the pattern
    /// must be this system's).
    pub(crate) fn pass(&mut self, p: &mut Pass) -> Passed {
        p.same(self.n, "the unknowns")?;
        p.same(self.levels, "the Jacobian's levels")?;
        for (what, indices) in [
            ("the Jacobian's columns", &self.ptr),
            ("its rows", &self.rows),
        ] {
            p.same(indices.len(), what)?;
            indices.iter().try_for_each(|&i| p.same(i, what))?;
        }
        p.f64s(&mut self.data, "the Jacobian's entries")
    }
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

    /// Random systems of sizes 1..5 (nalgebra multiplies with its own loop up to
    /// 5 × 5) with rows of very different magnitudes, from a small deterministic
    /// generator (xorshift).
    fn random_systems(count: usize) -> Vec<(DMatrix<f64>, DVector<f64>)> {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        (0..count)
            .map(|trial| {
                let n = 1 + trial % 5;
                let scale: Vec<f64> = (0..n).map(|i| 10f64.powi(3 * i as i32 - 6)).collect();
                let a = DMatrix::from_fn(n, n, |i, _| next() * scale[i]);
                let b = DVector::from_fn(n, |i, _| next() * scale[i]);
                (a, b)
            })
            .collect()
    }

    /// The solve is accurate to its condition: the residual of every row
    /// (relative to the row's largest entry) and the distance to nalgebra's LU
    /// solution are within 64·n·ε·condition·‖x‖∞, with one solver reused for
    /// every size.
    #[test]
    fn dense_solve_is_accurate_to_its_condition_and_reuses_its_buffers() {
        let mut solver = Solver::default();
        for (trial, (a, b)) in random_systems(500).into_iter().enumerate() {
            let n = b.len();
            let (expected, condition) =
                nalgebra_solve(&a, &b).expect("random matrices are regular");
            solver.load(&a, &b);
            let x = match solver.solve(0.0, "position", f64::INFINITY) {
                Ok(x) => DVector::from_column_slice(x),
                Err(e) => panic!("trial {trial}: {e}, nalgebra condition {condition}"),
            };
            let tol = 64.0 * n as f64 * f64::EPSILON * condition * x.amax();
            let residual = &b - &a * &x;
            for i in 0..n {
                let r = residual[i].abs() / a.row(i).amax();
                assert!(r <= tol, "trial {trial}, row {i}: residual {r:e} > {tol:e}");
            }
            let distance = (&x - &expected).amax();
            assert!(distance <= tol, "trial {trial}: {distance:e} from nalgebra");
        }
    }

    /// Partial pivoting: a zero (or tiny) leading entry is pivoted past, and the
    /// solution is exact where the pivoted system is triangular.
    #[test]
    fn dense_solve_pivots_past_zero_and_tiny_leading_entries() {
        for tiny in [0.0, 1e-300, 1e-20] {
            let a = DMatrix::from_row_slice(2, 2, &[tiny, 1.0, 1.0, 1.0]);
            let x_true = DVector::from_vec(vec![3.0, -2.0]);
            let b = DVector::from_vec(vec![tiny * 3.0 - 2.0, 1.0]);
            let x = solve(&a, &b, 0.0, "position", 1e12).unwrap();
            assert!((&x - &x_true).amax() <= 1e-15, "{tiny}: {x}");
        }
    }

    /// Tether's results are bit for bit those of the fmpy reference
    /// (docs/validation.md, "Why bit for bit matters"), which spells out the
    /// dense solve's operations in a fixed order (tools/fmpy_reference/linalg.py):
    /// the order of nalgebra's `LU::new`, `try_inverse` and matrix–vector
    /// product, that of every result before. This test pins that order.
    #[test]
    fn dense_solve_keeps_the_operation_order_the_fmpy_reference_repeats() {
        let mut solver = Solver::default();
        for (trial, (a, b)) in random_systems(500).into_iter().enumerate() {
            let n = b.len();
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
            let mut jac = Jacobians::dense(n, levels);
            for c in 0..n {
                let (_, column) = jac.column_mut(c);
                for (i, x) in column.iter_mut().enumerate() {
                    *x = value(i / n, i % n, c);
                }
            }
            let mats: Vec<DMatrix<f64>> = (0..levels)
                .map(|l| DMatrix::from_fn(n, n, |r, c| value(l, r, c)))
                .collect();
            let g: Vec<f64> = (0..levels * n).map(|i| (i as f64 + 0.5).cos()).collect();
            let (beta, gamma) = (0.3, 0.07);
            let mask: Vec<bool> = (0..n).map(|r| plain.contains(&r)).collect();
            let mut solver = Solver::default();
            jac.baumgarte(&mut solver, &g, Some((1, beta)), Some((2, gamma)), &mask);
            let (a, b) = solver.system(n);
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
            jac.load_level(&mut solver, &g, 2);
            let (sa, sb) = solver.system(n);
            assert_eq!(sa, mats[2].as_slice());
            assert_eq!(sb, &g[2 * n..]);
        }
    }

    #[test]
    fn sparse_and_dense_solves_agree_on_chains_and_trees() {
        for (n, tree) in [(40, false), (200, false), (63, true), (255, true)] {
            let (ptr, rows, a) = pattern_matrix(n, tree, 0x1234_5678 + n as u64);
            let b = DVector::from_fn(n, |i, _| (i as f64 * 0.37).sin());
            let mut sparse = Solver {
                sparse: Some(SparseLu::new(n, ptr.clone(), rows.clone())),
                ..Solver::default()
            };
            for _ in 0..2 {
                // Twice: the second solve reuses the symbolic factorisation.
                let values = &mut sparse.sparse.as_mut().unwrap().values;
                for c in 0..n {
                    for k in ptr[c]..ptr[c + 1] {
                        values[k] = a[(rows[k], c)];
                    }
                }
                sparse
                    .sparse
                    .as_mut()
                    .unwrap()
                    .x
                    .copy_from_slice(b.as_slice());
                let x_sparse =
                    DVector::from_column_slice(sparse.solve(0.0, "position", 1e12).unwrap());
                let x_dense = solve(&a, &b, 0.0, "position", 1e12).unwrap();
                let error = (&x_sparse - &x_dense).norm();
                assert!(
                    error <= 1e-12 * x_dense.norm(),
                    "n = {n}, tree {tree}: {error}"
                );
            }
        }
    }

    #[test]
    fn the_sparse_condition_check_fires_on_singular_systems() {
        let n = 50;
        let (ptr, rows, mut a) = pattern_matrix(n, false, 7);
        // Row 20 becomes twice row 21 (on the shared pattern entries): rank deficient.
        let with = |a: &DMatrix<f64>| {
            let mut solver = Solver {
                sparse: Some(SparseLu::new(n, ptr.clone(), rows.clone())),
                ..Solver::default()
            };
            let sparse = solver.sparse.as_mut().unwrap();
            for c in 0..n {
                for k in ptr[c]..ptr[c + 1] {
                    sparse.values[k] = a[(rows[k], c)];
                }
            }
            sparse.x.fill(1.0);
            solver
                .solve(1.5, "baumgarte", 1e12)
                .map(|_| ())
                .map_err(|e| e.to_string())
        };
        assert!(with(&a).is_ok());
        // Rows and columns 20, 21 decoupled from the rest, their 2 × 2 block
        // nearly singular: a condition far above the limit.
        for (r, c) in [(19, 20), (22, 21), (20, 19), (21, 22)] {
            a[(r, c)] = 0.0;
        }
        a[(21, 21)] = a[(21, 20)] * a[(20, 21)] / a[(20, 20)] * (1.0 + 1e-14);
        let err = with(&a).unwrap_err();
        assert!(
            err.contains("t = 1.5") && err.contains("condition"),
            "{err}"
        );
        // An exactly zero row.
        for c in 0..n {
            a[(30, c)] = 0.0;
        }
        let err = with(&a).unwrap_err();
        assert!(err.contains("inf"), "{err}");
    }
}
