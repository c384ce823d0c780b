"""Coupling polynomials on the uniform macro grid (paper eqs. 56 and 59).

FMI 2.0 co-simulation takes a polynomial input as its value at the step start
(fmi2SetReal) and its time derivatives there (fmi2SetRealInputDerivatives). A
polynomial of degree <= 2 is its own Taylor polynomial at T_N, so each
Lagrange polynomial is handed over exactly as (value, first, second derivative)
at T_N. The formulas are the finite-difference forms of the Lagrange
polynomials through equidistant points (docs/algorithm.md, "Polynomials").
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class Jet:
    """u(T_N + tau) = value + d1*tau + d2*tau^2/2."""

    value: float = 0.0
    d1: float = 0.0
    d2: float = 0.0

    def at(self, tau):
        return self.value + tau * (self.d1 + 0.5 * tau * self.d2)


def predictor(past, degree, h, steps=None):
    """Extrapolation through (T_N, past[0]), (T_{N-1}, past[1]), ... (eq. 56).
    `steps` = (T_N - T_{N-1}, T_{N-1} - T_{N-2}) on a variable grid (adaptive
    macro steps): the Lagrange polynomial through the actual points, by divided
    differences; None on the uniform grid."""
    if steps is not None:
        return _predictor_on(past, degree, steps)
    u0 = past[0]
    if degree == 0:
        return Jet(u0)
    u1 = past[1]
    if degree == 1:
        return Jet(u0, (u0 - u1) / h)
    u2 = past[2]
    # Backward differences at the newest point of a quadratic.
    return Jet(u0, (3.0 * u0 - 4.0 * u1 + u2) / (2.0 * h), (u0 - 2.0 * u1 + u2) / (h * h))


def through(new, past, degree, h, steps=None):
    """Interpolation through (T_{N+1}, new), (T_N, past[0]), ... (eq. 59 and the
    corrector). Degree 0 is the constant `new` over the step."""
    if steps is not None and degree == 2:
        h1 = steps[0]
        f01 = (past[0] - past[1]) / h1
        fn0 = (new - past[0]) / h
        f012 = (fn0 - f01) / (h + h1)
        return Jet(past[0], f01 + f012 * h1, 2.0 * f012)
    if degree == 0:
        return Jet(new)
    u0 = past[0]
    if degree == 1:
        return Jet(u0, (new - u0) / h)
    um = past[1]
    # Central differences at the middle point of a quadratic.
    return Jet(u0, (new - um) / (2.0 * h), (new - 2.0 * u0 + um) / (h * h))


def _predictor_on(past, degree, steps):
    h1, h2 = steps
    u0 = past[0]
    if degree == 0:
        return Jet(u0)
    f01 = (u0 - past[1]) / h1
    if degree == 1:
        return Jet(u0, f01)
    f12 = (past[1] - past[2]) / h2
    f012 = (f01 - f12) / (h1 + h2)
    return Jet(u0, f01 + f012 * h1, 2.0 * f012)
