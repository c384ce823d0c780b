"""fmpy reference for `tether run`: the same system file, the same coupling
equations, with fmpy as the FMI host (model-exchange instances integrated by
fmpy's CVode).

    python tools/fmpy_reference SYSTEM.toml [--method baumgarte|weighted|explicit]
        [--index 1|2|3] [--beta B] [--gamma G] [--a A] [--b B] [--mu MU] [--order K] [--epsilon E]
        [--stop T] [--step H] [--out FILE.csv] [--quiet]

Writes the CSV layout of `tether run` (time, every Real output as
<instance>.<variable>, the unknowns: <constraint>.lambda, <joint>.lambda[k],
<variable>.value, force ports <instance>.<marker>.F[k] / .T[k], then the
residuals <constraint>.g, <joint>.g[k]). Compare the two with
`tether compare` (docs/validation.md). Errors are one line on stderr, exit status 1;
a run that stops early keeps its rows and ends the file with `# incomplete: ...`.
"""

import argparse
import csv
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import system as systemfile  # noqa: E402
from errors import RunError  # noqa: E402


def arguments(argv):
    p = argparse.ArgumentParser(prog="fmpy_reference", description=__doc__.split("\n\n")[0])
    p.add_argument("system", help="the system file (TOML), see docs/system-file.md")
    p.add_argument("--stop", type=float, help="stop time (overrides [experiment] stop)")
    p.add_argument("--step", type=float, help="macro-step size H (overrides [experiment] step)")
    p.add_argument("--method", choices=["baumgarte", "weighted", "explicit"])
    p.add_argument("--index", type=int, choices=[1, 2, 3], help="index level of method baumgarte or weighted")
    p.add_argument("--beta", type=float)
    p.add_argument("--gamma", type=float)
    p.add_argument("--a", type=float)
    p.add_argument("--b", type=float)
    p.add_argument("--mu", type=float)
    p.add_argument("--order", type=int, help="degree k of the coupling polynomials: 0, 1 or 2")
    p.add_argument("--epsilon", type=float, help="finite-difference increment")
    p.add_argument("--iterations", type=int, help="corrections per macro step (1 = the paper)")
    p.add_argument("--iteration-tol", type=float, help="an iterated correction stops below this update")
    p.add_argument("--jacobian", choices=["every_step", "reuse"], help="when the interface Jacobian is made")
    p.add_argument("--step-rtol", type=float, help="adaptive macro steps: relative tolerance")
    p.add_argument("--step-atol", type=float, help="adaptive macro steps: absolute tolerance")
    p.add_argument("--out", "-o", help="output CSV (default: the system file's name with .csv)")
    p.add_argument("--quiet", "-q", action="store_true", help="no run summary")
    return p.parse_args(argv)


def apply_overrides(system, args):
    """The command-line flags of `tether run`, with its rules."""
    for name in ("stop", "step", "epsilon"):
        if getattr(args, name) is not None:
            setattr(system, name, getattr(args, name))
    for name in ("iterations", "iteration_tol", "jacobian"):
        if getattr(args, name) is not None:
            setattr(system, name, getattr(args, name))
    for name, key in (("step_rtol", "rtol"), ("step_atol", "atol")):
        if getattr(args, name) is not None:
            if system.step_control is None:
                system.step_control = {"rtol": 1e-4, "atol": 1e-6, "h_min": None, "h_max": None,
                                       "h_initial": None}
            system.step_control[key] = getattr(args, name)
    if args.order is not None:
        if args.order < 0:
            raise RunError(f"invalid order = {args.order}: expected a polynomial degree k of 0, 1 or 2")
        system.order = args.order
    m = system.method
    kind = args.method or m.kind
    if kind != m.kind:
        m = systemfile.Method(kind, mu=m.mu if m.kind == "explicit" else 0.0)
        had_mu = False
    else:
        had_mu = m.kind == "explicit"
    if args.index is not None and kind in ("baumgarte", "weighted"):
        # The method's own weights where the index uses them, else its defaults.
        own = (m.beta, m.gamma) if kind == "baumgarte" else (m.a, m.b)
        flags = (args.beta, args.gamma) if kind == "baumgarte" else (args.a, args.b)
        kept = (own[0] > 0 and args.index <= 2, own[1] > 0 and args.index <= 1)
        given = tuple(f if f is not None else (o if k else None) for f, o, k in zip(flags, own, kept))
        w = systemfile.at_index(kind, args.index, given, flags=True)
        m = systemfile.Method(kind, beta=w[0], gamma=w[1]) if kind == "baumgarte" \
            else systemfile.Method(kind, a=w[0], b=w[1])
    elif args.index is not None:
        raise RunError("--index applies to method baumgarte or weighted, but the method is explicit")
    elif kind == "baumgarte":
        m = systemfile.Method(kind, beta=_pick(args.beta, m.beta), gamma=_pick(args.gamma, m.gamma))
    elif kind == "weighted":
        m = systemfile.Method(kind, a=_pick(args.a, m.a), b=_pick(args.b, m.b))
    else:
        if args.mu is None and not had_mu:
            raise RunError("method explicit needs --mu (or mu in [method])")
        m = systemfile.Method(kind, mu=_pick(args.mu, m.mu))
    system.method = m
    for flag, given, method in [("--beta", args.beta, "baumgarte"), ("--gamma", args.gamma, "baumgarte"),
                                ("--a", args.a, "weighted"), ("--b", args.b, "weighted"),
                                ("--mu", args.mu, "explicit")]:
        if given is not None and m.kind != method:
            raise RunError(f"{flag} applies to method {method}, but the method is {m.kind}")


def _pick(flag, current):
    return current if flag is None else flag


def run(args):
    system = systemfile.read(args.system)
    apply_overrides(system, args)
    systemfile.check(system)
    out = args.out or os.path.splitext(os.path.basename(args.system))[0] + ".csv"

    from master import Master  # fmpy is only needed from here on

    clock = time.perf_counter()
    master = Master(system)
    if not args.quiet:
        for note in [h.note for h in master.hosts if h.note] + master.signals.loop_notes():
            print(f"note: {note}", file=sys.stderr)
    failure = None
    try:
        try:
            f = open(out, "w", newline="")
        except OSError as e:
            raise RunError(f"cannot create {out}: {e.strerror}") from None
        with f:
            writer = csv.writer(f, lineterminator="\n")
            try:
                master.start()
                master.set_limits()
                writer.writerow(["time"] + master.columns)
                writer.writerow([repr(master.time())] + [repr(v) for v in master.row])
                while not master.finished():
                    master.step()
                    writer.writerow([repr(master.time())] + [repr(v) for v in master.row])
            except Exception as e:
                failure = e
                if f.tell() == 0:
                    writer.writerow(["time"] + master.columns)
                f.write(f"# incomplete: {one_line(e)}\n")
        if not args.quiet:
            name = system.name or "system"
            print(f"{name} (fmpy reference): {system.method.describe()} with k = {system.order}, "
                  f"H = {system.step}, t = {system.start} … {master.time()}", file=sys.stderr)
            if master.control is not None:
                c = master.control
                print(f"  adaptive steps: {c.accepted} accepted, {c.rejected} rejected", file=sys.stderr)
            if master.signals.iterations is not None:
                c = master.signals.counts
                print(f"  signals ({master.signals.solver}): {c['iterations']} iterations, at most "
                      f"{c['max_iterations']} per step, {c['repeated_runs']} repeated runs, "
                      f"{c['not_converged']} steps not converged", file=sys.stderr)
            for h in master.hosts:
                c = h.counters
                steps = "model-exchange steps (CVode)" if h.model_exchange else "fmi2DoStep"
                print(f"  {h.name}: {c.do_steps} {steps}, {c.state_gets} fmi2GetFMUstate, "
                      f"{c.state_sets} fmi2SetFMUstate", file=sys.stderr)
            print(f"  wall time {time.perf_counter() - clock:.2f} s; results: {out}", file=sys.stderr)
    finally:
        master.close()
    if failure is not None:
        raise RunError(f"run stopped; results up to t = {master.time()} kept in {out} (marked incomplete): "
                       f"{one_line(failure)}")


def one_line(e):
    return " ".join(str(e).split()) or type(e).__name__


def main(argv):
    args = arguments(argv)
    try:
        run(args)
    except RunError as e:
        print(f"error: {one_line(e)}", file=sys.stderr)
        return 1
    except Exception as e:  # an FMI call that failed (fmpy raises FMICallException), ...
        print(f"error: {type(e).__name__}: {one_line(e)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
