//! Solving the linearised coupling conditions (eq. 68, 73–75) with an LU
//! factorisation and a condition check.

use nalgebra::{DMatrix, DVector};

use crate::MasterError;

/// Solve `A x = b`. Rows are scaled to unit max-norm first (position, velocity
/// and acceleration rows have very different magnitudes), then the 1-norm
/// condition number of the scaled matrix is estimated from its inverse — the
/// systems are small (one row per coupling unknown). A condition above `limit`
/// or an exactly singular matrix is an error naming the time and the level.
pub(crate) fn solve(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    time: f64,
    level: &'static str,
    limit: f64,
) -> Result<DVector<f64>, MasterError> {
    let singular = |condition: f64| MasterError::SingularJacobian {
        time,
        level,
        condition,
        limit,
    };
    let n = a.nrows();
    let mut scaled = a.clone();
    let mut rhs = b.clone();
    for i in 0..n {
        let s = scaled.row(i).amax();
        if !(s.is_finite() && s > 0.0) {
            return Err(singular(f64::INFINITY));
        }
        scaled.row_mut(i).scale_mut(1.0 / s);
        rhs[i] /= s;
    }
    let lu = scaled.clone().lu();
    let inverse = lu.try_inverse().ok_or_else(|| singular(f64::INFINITY))?;
    let condition = norm1(&scaled) * norm1(&inverse);
    if !(condition.is_finite() && condition <= limit) {
        return Err(singular(condition));
    }
    Ok(&inverse * rhs)
}

fn norm1(m: &DMatrix<f64>) -> f64 {
    m.column_iter()
        .map(|c| c.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max)
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
    }
}
