"""The predictor/corrector macro step of Tether (Method 1, Baumgarte) on the
paper's oscillator pair, driven from Python through fmpy: the same FMI calls
per macro step and instance as Tether and as the C floor (crates/tether-bench/
c/floor.c), and the same scalar arithmetic, so the final values agree bit for
bit with both.

    python fmpy_loop.py --fmu oscillator.fmu --steps 1000 --step 1e-3 --order 0
        --exact 1 --beta 2e-3 --gamma 1e-6 --epsilon 1e-5 --lambda0 333.33

prints `per_step_s=<wall time of the loop per macro step> lambda=<λ_N> x1=<x1>`.
Used by `cargo bench -p tether-bench` (docs/performance.md).
"""

import argparse
import shutil
import time
from ctypes import byref

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2FMUstate


def extrapolation(hist, degree, h):
    if degree == 0:
        return (hist[0], 0.0, 0.0)
    if degree == 1:
        return (hist[0], (hist[0] - hist[1]) / h, 0.0)
    return (
        hist[0],
        (3.0 * hist[0] - 4.0 * hist[1] + hist[2]) / (2.0 * h),
        (hist[0] - 2.0 * hist[1] + hist[2]) / (h * h),
    )


def interpolation(u_new, hist, degree, h):
    if degree == 0:
        return (u_new, 0.0, 0.0)
    if degree == 1:
        return (hist[0], (u_new - hist[0]) / h, 0.0)
    return (hist[0], (u_new - hist[1]) / (2.0 * h), (u_new - 2.0 * hist[0] + hist[1]) / (h * h))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--fmu", required=True)
    p.add_argument("--steps", type=int, required=True)
    p.add_argument("--step", type=float, required=True)
    p.add_argument("--order", type=int, required=True)
    p.add_argument("--exact", type=int, required=True)
    p.add_argument("--beta", type=float, required=True)
    p.add_argument("--gamma", type=float, required=True)
    p.add_argument("--epsilon", type=float, required=True)
    p.add_argument("--lambda0", type=float, required=True)
    args = p.parse_args()

    md = read_model_description(args.fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipdir = extract(args.fmu)
    try:
        run(args, md, vr, unzipdir)
    finally:
        # extract() unpacks into a fresh temporary directory and leaves it.
        shutil.rmtree(unzipdir, ignore_errors=True)


def run(args, md, vr, unzipdir):
    h, k, start = args.step, args.order, 0.0
    stop = start + args.steps * h
    masses = (1.0, 2.0)
    sign = (1.0, -1.0)
    fmus = []
    for s, name in enumerate(("mass1", "mass2")):
        fmu = FMU2Slave(
            guid=md.guid,
            unzipDirectory=unzipdir,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName=name,
        )
        fmu.instantiate()
        fmu.setReal(
            [vr["m"], vr["c"], vr["d"], vr["x0"], vr["v0"]],
            [masses[s], 1000.0, 10.0, 0.0, 100.0],
        )
        fmu.setBoolean([vr["exact"]], [args.exact != 0])
        fmu.setupExperiment(startTime=start, stopTime=stop)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.setReal([vr["F"]], [0.0 + sign[s] * args.lambda0])
        fmus.append(fmu)

    F = [vr["F"]]
    outs = [vr["x"], vr["v"], vr["a"]]
    nd = min(k, 2)
    d_vrs, d_orders = [vr["F"]] * nd, [1, 2][:nd]
    states = [fmi2FMUstate(), fmi2FMUstate()]

    def apply(fmu, s, poly):
        fmu.setReal(F, [0.0 + sign[s] * poly[0]])
        if k > 0:
            d = [0.0 + sign[s] * poly[1], 0.0 + sign[s] * poly[2]]
            fmu.setRealInputDerivatives(d_vrs, d_orders, d[:nd])

    hist = [args.lambda0] * 3
    y = [None, None]
    recorded = [None, None]
    clock = time.perf_counter()
    for n in range(args.steps):
        t = start + n * h
        degree_pred, degree_corr = min(k, n), min(k, n + 1)
        pred = extrapolation(hist, degree_pred, h)
        u_pred = pred[0] + h * (pred[1] + 0.5 * h * pred[2])
        for s, fmu in enumerate(fmus):
            # fmi2GetFMUstate into the existing state (fmpy's getFMUstate() would
            # allocate a new one every step).
            fmu.fmi2GetFMUstate(fmu.component, byref(states[s]))
            apply(fmu, s, pred)
            fmu.doStep(t, h)
            y[s] = fmu.getReal(outs)
        g = [0.0 + y[1][l] + -1.0 * y[0][l] for l in range(3)]

        delta = args.epsilon * max(abs(hist[0]), 1.0)
        pert = interpolation(u_pred + delta, hist, degree_corr, h)
        for s, fmu in enumerate(fmus):
            fmu.setFMUstate(states[s])
            apply(fmu, s, pert)
            fmu.doStep(t, h)
            y[s] = fmu.getReal(outs)
        jac = [((0.0 + y[1][l] + -1.0 * y[0][l]) - g[l]) / delta for l in range(3)]

        a, b = jac[0], g[0]
        if args.beta > 0.0:
            a += args.beta * jac[1]
            b += args.beta * g[1]
        if args.gamma > 0.0:
            a += args.gamma * jac[2]
            b += args.gamma * g[2]
        scale = abs(a)
        a *= 1.0 / scale
        b /= scale
        corrected = u_pred - (1.0 / a) * b

        corr = interpolation(corrected, hist, degree_corr, h)
        for s, fmu in enumerate(fmus):
            fmu.setFMUstate(states[s])
            apply(fmu, s, corr)
            fmu.doStep(t, h)
        hist = [corrected, hist[0], hist[1]]
        for s, fmu in enumerate(fmus):
            y[s] = fmu.getReal(outs)
            recorded[s] = fmu.getReal(outs)
    elapsed = time.perf_counter() - clock
    for s, fmu in enumerate(fmus):
        fmu.fmi2FreeFMUstate(fmu.component, byref(states[s]))
        fmu.terminate()
        fmu.freeInstance()
    print(f"per_step_s={elapsed / args.steps!r} lambda={hist[0]!r} x1={recorded[0][0]!r}")


if __name__ == "__main__":
    main()
