"""What the fmpy-driven checks of the exported FMUs (exported_fmu.py for FMI 2.0,
exported_fmu3.py for FMI 3.0) share: the failure exit, fmpy's validation and
`simulate_fmu` run, and the closed form the ramp input is compared against."""
import math
import sys

from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu


def fail(message):
    print(message)
    sys.exit(1)


def validate_and_simulate(fmu, out):
    """Validates `fmu`, runs fmpy's `simulate_fmu` on its own grid and writes
    every output to the CSV `out`; returns the model description, the step H
    and the output names."""
    problems = validate_fmu(fmu)
    if problems:
        fail("validate: " + "; ".join(problems))
    print("validate: no problems")
    md = read_model_description(fmu)
    step = float(md.defaultExperiment.stepSize)
    names = [v.name for v in md.modelVariables if v.causality == "output"]
    result = simulate_fmu(fmu, output_interval=step, output=names)
    with open(out, "w") as f:
        f.write(",".join(["time"] + names) + "\n")
        for row in result:
            f.write(",".join(repr(float(x)) for x in row) + "\n")
    print(f"simulate_fmu: {len(result)} rows")
    return md, step, names


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


# The ramp force F(t) = RAMP_A + RAMP_B t on the exported rigid pair (m = 1 + 2, c = 1000 + 1000,
# d = 10 + 10, v0 = 100).
RAMP_A, RAMP_B = 100.0, 2000.0


def ramp_error(samples):
    """The largest distance of the (t, x) samples from the pair's closed form under the ramp."""
    return max(abs(x - ramp_closed_form(t, 3.0, 2000.0, 20.0, 100.0, RAMP_A, RAMP_B))
               for t, x in samples)
