//! The dense LU kernels of the interface solve: LU with partial pivoting in
//! place, the inverse from the factors, and the 1-norm of the condition
//! estimate; the operations of nalgebra's `LU::new` and `try_inverse` in the
//! same order.

/// LU with partial pivoting (first largest magnitude) in place: unit lower
/// factor below the diagonal, upper factor on and above. `false` if a pivot
/// column is all zero.
pub(super) fn lu_in_place(a: &mut [f64], pivots: &mut [usize], n: usize) -> bool {
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
pub(super) fn inverse(lu: &[f64], pivots: &[usize], out: &mut [f64], n: usize) -> bool {
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
pub(super) fn norm1(m: &[f64], n: usize) -> f64 {
    (0..n)
        .map(|j| m[j * n..(j + 1) * n].iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}
