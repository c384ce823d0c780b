#!/usr/bin/env python3
"""Time two builds of the `steps` example against each other, alternated.

Builds a decision such as "does this fast path pay?" on wall time measured
the same way for both builds: OLD and NEW are two `steps` binaries (copies of
target/release/examples/steps built from the two versions of the code), each
run as `steps STEPS --system SYSTEM [ARGS...]` COUNT times in the order
old, new, new, old, old, new, ... so that a drift of the machine's load hits
both alike. Prints every run's time per macro step, the two medians and the
median gain of NEW over OLD in % (positive: NEW is faster).

    cargo build --profile bench -p tether-bench --example steps
    cp target/release/examples/steps /tmp/steps-new
    tools/bench/ab.py /tmp/steps-old /tmp/steps-new examples/double_pendulum.toml
    tools/bench/ab.py OLD NEW examples/3d_revolute.toml --count 20 --steps 2000 -- --order 0

Runs from the workspace root whatever the current directory (the `steps`
example packages the FMUs of the workspace it is run in); paths given on the
command line are taken relative to the current directory. Python standard
library only. See docs/performance.md, "Comparing two builds".
"""

import argparse
import os
import re
import statistics
import subprocess
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
LINE = re.compile(r"macro steps, ([0-9.eE+-]+) µs per step")
# The rule for fast paths: keep one only if it gains at least this much, as the
# median of at least MIN_RUNS alternated runs of each build on a joint system.
BAR_PERCENT = 5.0
MIN_RUNS = 10


def time_per_step(binary, steps, system, extra):
    """One run of `binary`: its time per macro step in µs."""
    command = [binary, str(steps), "--system", system] + extra
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        sys.exit(f"ab.py: {' '.join(command)} failed ({done.returncode}): {tail}")
    match = LINE.search(done.stdout)
    if not match:
        sys.exit(f"ab.py: {binary} printed no time per step: {done.stdout.strip()!r}")
    return float(match.group(1))


def order(count):
    """old, new, new, old, old, new, ... : `count` runs of each."""
    pattern = ["old", "new", "new", "old"]
    return [pattern[i % 4] for i in range(2 * count)]


def main():
    parser = argparse.ArgumentParser(
        description="Alternated timing of two `steps` binaries on one system file."
    )
    parser.add_argument("old", help="the `steps` binary of the old build")
    parser.add_argument("new", help="the `steps` binary of the new build")
    parser.add_argument("system", help="the system file, e.g. examples/double_pendulum.toml")
    parser.add_argument(
        "count", nargs="?", type=int, default=MIN_RUNS, help=f"runs of each build (default {MIN_RUNS})"
    )
    parser.add_argument("--count", dest="count_opt", type=int, help="the same as COUNT")
    parser.add_argument(
        "--steps", type=int, default=2000, help="macro steps per run (default 2000)"
    )
    parser.add_argument(
        "extra", nargs=argparse.REMAINDER, help="after --: more options for `steps`"
    )
    args = parser.parse_args()
    count = args.count_opt if args.count_opt is not None else args.count
    if count < 1:
        sys.exit("ab.py: the count must be at least 1")
    extra = args.extra[1:] if args.extra[:1] == ["--"] else args.extra
    binaries = {}
    for name in ("old", "new"):
        path = os.path.abspath(getattr(args, name))
        if not (os.path.isfile(path) and os.access(path, os.X_OK)):
            sys.exit(f"ab.py: {getattr(args, name)} is not an executable file")
        binaries[name] = path
    system = os.path.abspath(args.system)
    if not os.path.isfile(system):
        sys.exit(f"ab.py: no system file {args.system}")

    print(f"old: {binaries['old']}\nnew: {binaries['new']}")
    print(f"system: {system}, {args.steps} macro steps a run, {count} runs of each, alternated")
    times = {"old": [], "new": []}
    for i, who in enumerate(order(count), 1):
        t = time_per_step(binaries[who], args.steps, system, extra)
        times[who].append(t)
        print(f"{i:3}  {who}  {t:10.3f} µs per step", flush=True)
    old, new = statistics.median(times["old"]), statistics.median(times["new"])
    gain = (old - new) / old * 100.0
    spread = {w: (min(v), max(v)) for w, v in times.items()}
    print(f"median old {old:.3f} µs (runs {spread['old'][0]:.3f}–{spread['old'][1]:.3f})")
    print(f"median new {new:.3f} µs (runs {spread['new'][0]:.3f}–{spread['new'][1]:.3f})")
    print(f"median gain of new over old: {gain:+.1f} %")
    if count < MIN_RUNS:
        print(f"(fewer than {MIN_RUNS} runs of each: no verdict on the {BAR_PERCENT:.0f} % bar)")
    else:
        verdict = "meets" if gain >= BAR_PERCENT else "does not meet"
        print(f"{verdict} the {BAR_PERCENT:.0f} % bar for keeping a fast path")


if __name__ == "__main__":
    main()
