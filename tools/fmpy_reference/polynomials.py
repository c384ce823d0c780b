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


def predictor(past, degree, h):
    """Extrapolation through (T_N, past[0]), (T_{N-1}, past[1]), ... (eq. 56)."""
    u0 = past[0]
    if degree == 0:
        return Jet(u0)
    u1 = past[1]
    if degree == 1:
        return Jet(u0, (u0 - u1) / h)
    u2 = past[2]
    # Backward differences at the newest point of a quadratic.
    return Jet(u0, (3.0 * u0 - 4.0 * u1 + u2) / (2.0 * h), (u0 - 2.0 * u1 + u2) / (h * h))


def through(new, past, degree, h):
    """Interpolation through (T_{N+1}, new), (T_N, past[0]), ... (eq. 59 and the
    corrector). Degree 0 is the constant `new` over the step."""
    if degree == 0:
        return Jet(new)
    u0 = past[0]
    if degree == 1:
        return Jet(u0, (new - u0) / h)
    um = past[1]
    # Central differences at the middle point of a quadratic.
    return Jet(u0, (new - um) / (2.0 * h), (new - 2.0 * u0 + um) / (h * h))
