"""Solving the linearised coupling conditions (eq. 68, 73-75).

Rows are scaled to unit max-norm (position, velocity and acceleration rows
differ by powers of H), the 1-norm condition number of the scaled matrix is
taken from its inverse, and a condition above the limit stops the run.
"""

import numpy as np

from errors import RunError


def solve(matrix, rhs, time, level, limit):
    a = np.array(matrix, dtype=float)
    b = np.array(rhs, dtype=float)
    n = a.shape[0]

    def singular(condition):
        return RunError(
            f"singular interface Jacobian ({level} level) at t = {time}: "
            f"condition estimate {condition:.3e} exceeds {limit:.1e}"
        )

    for i in range(n):
        s = float(np.max(np.abs(a[i, :])))
        if not (np.isfinite(s) and s > 0.0):
            raise singular(float("inf"))
        a[i, :] *= 1.0 / s
        b[i] /= s
    try:
        inverse = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        raise singular(float("inf")) from None
    condition = float(np.max(np.sum(np.abs(a), axis=0)) * np.max(np.sum(np.abs(inverse), axis=0)))
    if not (np.isfinite(condition) and condition <= limit):
        raise singular(condition)
    return inverse @ b
