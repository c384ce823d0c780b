#!/usr/bin/env python3
"""What extra data or extra code costs the C floor, in the host's two states
(docs/performance.md, "Extra data and extra code, tried on the C floor").

Each round runs the `steps` example four times, N macro steps each (exact
FMUs): Tether, the plain C floor, and the C floor with two kinds of synthetic
extra work that differ in one thing only (`--floor-extra`, c/extra.c):

    data   96 loads a step from 96 different 64-byte lines   vs  from one line
    code   1280 loads as ~10 KiB of straight-line code        vs  in a loop

The pair's order alternates between rounds. Rounds are split into the host's
quiet and busy states by the plain floor's time a step (--busy-above). For
each state: median times, the median of the paired differences (second minus
first of the pair) with its quartiles, and in how many rounds the first of
the pair was the faster.

    cargo build --release -p tether-bench --example steps
    tools/bench/extra_ab.py data [--rounds 100] [--steps 50000] [--order 1]
    tools/bench/extra_ab.py code
"""

import argparse
import os
import statistics
import subprocess
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
STEPS = os.path.join(ROOT, "target", "release", "examples", "steps")
PAIRS = {"data": ("lines", "one-line"), "code": ("straight", "looped")}


def time_per_step(args):
    out = subprocess.run(
        [STEPS, *args], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout
    # "... , 1.234 µs per step"
    return float(out.split()[-4])


def quartiles(values):
    q = statistics.quantiles(values, n=4)
    return q[0], statistics.median(values), q[2]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("pair", choices=PAIRS)
    parser.add_argument("--rounds", type=int, default=100)
    parser.add_argument("--steps", type=int, default=50000)
    parser.add_argument("--order", type=int, default=1, choices=(0, 1))
    parser.add_argument("--busy-above", type=float, default=0.75,
                        help="µs a step of the plain floor above which a round counts as busy")
    opts = parser.parse_args()
    if not os.path.exists(STEPS):
        sys.exit(f"extra_ab: {STEPS} is missing: cargo build --release -p tether-bench --example steps")
    first, second = PAIRS[opts.pair]
    common = [str(opts.steps), "--order", str(opts.order)]
    rows = []
    for r in range(opts.rounds):
        tether = time_per_step(common)
        floor = time_per_step(common + ["--floor"])
        order = (first, second) if r % 2 == 0 else (second, first)
        t = {m: time_per_step(common + ["--floor-extra", m]) for m in order}
        rows.append((tether, floor, t[first], t[second]))
    print(f"{opts.rounds} rounds of {opts.steps} macro steps (k = {opts.order}); "
          f"times in µs a step, differences in ns")
    for state, sel in (
        ("quiet", [r for r in rows if r[1] <= opts.busy_above]),
        ("busy", [r for r in rows if r[1] > opts.busy_above]),
    ):
        if len(sel) < 4:
            print(f"{state}: {len(sel)} rounds, too few to report")
            continue
        med = [statistics.median(r[i] for r in sel) for i in range(4)]
        ratio = statistics.median(r[0] / r[1] for r in sel)
        diff = [(r[2] - r[3]) * 1000 for r in sel]
        q1, q2, q3 = quartiles(diff)
        faster = sum(d < 0 for d in diff)
        print(f"{state}: {len(sel)} rounds; Tether {med[0]:.3f} (ratio {ratio:.2f}), floor {med[1]:.3f}, "
              f"{first} {med[2]:.3f}, {second} {med[3]:.3f}")
        print(f"    {first} − {second}: median {q2:+.0f} ns (quartiles {q1:+.0f}, {q3:+.0f}); "
              f"{first} faster in {faster} of {len(sel)} rounds")


if __name__ == "__main__":
    main()
