"""Solving the linearised coupling conditions (eq. 68, 73-75).

Rows are scaled to unit max-norm (position, velocity and acceleration rows
differ by powers of H), the scaled matrix is factorised by LU with partial
pivoting, its inverse formed, the 1-norm condition number taken from it, and a
condition above the limit stops the run.

The arithmetic is spelled out in plain Python floats in a fixed order
(docs/validation.md, "Bit-for-bit solves"): pivot = first row of largest
magnitude, unit lower factor, the inverse column by column by forward then
backward substitution, x = A^-1 b accumulated column by column. Python floats
are IEEE doubles rounded to nearest with no fused multiply-add, so a system
solved this way gives the same bits on every host that follows the same order.
"""

import math

from errors import RunError


def solve(matrix, rhs, time, level, limit):
    n = len(rhs)
    # a[r][c], plain floats.
    a = [[float(matrix[r][c]) for c in range(n)] for r in range(n)]
    b = [float(x) for x in rhs]

    def singular(condition):
        return RunError(
            f"singular interface Jacobian ({level} level) at t = {time}: "
            f"condition estimate {condition:.3e} exceeds {limit:.1e}"
        )

    for i in range(n):
        s = 0.0
        for c in range(n):
            s = max(s, abs(a[i][c]))
        if not (math.isfinite(s) and s > 0.0):
            raise singular(float("inf"))
        inv = 1.0 / s
        for c in range(n):
            a[i][c] *= inv
        b[i] /= s
    scaled = [row[:] for row in a]

    # LU in place with partial pivoting.
    pivots = [0] * n
    for i in range(n):
        piv, biggest = i, abs(a[i][i])
        for r in range(i + 1, n):
            if abs(a[r][i]) > biggest:
                biggest, piv = abs(a[r][i]), r
        pivots[i] = piv
        diag = a[piv][i]
        if diag == 0.0:
            raise singular(float("inf"))
        if piv != i:
            a[i], a[piv] = a[piv], a[i]
        inv_diag = 1.0 / diag
        for r in range(i + 1, n):
            a[r][i] *= inv_diag
        for k in range(i + 1, n):
            p = a[i][k]
            for r in range(i + 1, n):
                a[r][k] += -p * a[r][i]

    # The inverse: permuted identity, then per column forward/backward substitution.
    inverse = [[1.0 if r == c else 0.0 for c in range(n)] for r in range(n)]
    for i, piv in enumerate(pivots):
        if piv != i:
            inverse[i], inverse[piv] = inverse[piv], inverse[i]
    for c in range(n):
        for i in range(n - 1):
            coeff = inverse[i][c]
            for r in range(i + 1, n):
                inverse[r][c] += -coeff * a[r][i]
        for i in range(n - 1, -1, -1):
            diag = a[i][i]
            if diag == 0.0:
                raise singular(float("inf"))
            coeff = inverse[i][c] / diag
            inverse[i][c] = coeff
            for r in range(i):
                inverse[r][c] += -coeff * a[r][i]

    def norm1(m):
        best = 0.0
        for c in range(n):
            total = 0.0
            for r in range(n):
                total += abs(m[r][c])
            best = max(best, total)
        return best

    condition = norm1(scaled) * norm1(inverse)
    if not (math.isfinite(condition) and condition <= limit):
        raise singular(condition)
    x = [inverse[r][0] * b[0] for r in range(n)]
    for c in range(1, n):
        for r in range(n):
            x[r] += inverse[r][c] * b[c]
    return x
