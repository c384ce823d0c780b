"""Closed forms the fmpy-driven checks of the exported FMUs compare against."""
import math


def ramp_closed_form(t, m, c, d, v0, a0, b0):
    """x(t) of m x'' + d x' + c x = a0 + b0 t, x(0) = 0, x'(0) = v0."""
    p1 = b0 / c
    p0 = (a0 - d * p1) / c
    y0, dy0 = -p0, v0 - p1
    sigma = d / (2 * m)
    omega = math.sqrt(c / m - sigma * sigma)
    y = math.exp(-sigma * t) * (y0 * math.cos(omega * t) + (dy0 + sigma * y0) / omega
                                * math.sin(omega * t))
    return p0 + p1 * t + y
