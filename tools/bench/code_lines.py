#!/usr/bin/env python3
"""Code one macro step runs through, for Tether and for the C floor
(docs/performance.md, "Code touched per step").

Runs the `steps` example under callgrind with per-instruction counts, once for
SHORT and once for LONG macro steps (default 1000 and 3000). An instruction
whose count grows by at least LONG - SHORT between the two runs is executed at
least once per macro step; the distinct 64-byte lines those instructions sit
in are the code a macro step needs in the instruction cache. They are counted
per loaded object: the program (the master, or the C loop), the FMU's shared
library and libc. Needs valgrind; takes about a minute.

    tools/bench/code_lines.py [--short N] [--long N]
"""

import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
STEPS = os.path.join(ROOT, "target", "release", "examples", "steps")
ENTRY = re.compile(r"^(0x[0-9a-f]+|[+-]\d+|\*)\s+(.*)$")
NAMED = re.compile(r"\((\d+)\)(?: (.*))?")


def counts(path):
    """Per instruction address: its own count (calls excluded) and its object."""
    count = collections.Counter()
    owner = {}
    names = {}
    obj = None
    address = 0
    after_call = False
    for line in open(path, encoding="utf-8", errors="replace"):
        line = line.rstrip("\n")
        if line.startswith(("ob=", "cob=")):
            m = NAMED.match(line.split("=", 1)[1])
            if m.group(2):
                names[m.group(1)] = m.group(2)
            if line.startswith("ob="):
                obj = names.get(m.group(1), "?")
            continue
        if line.startswith("calls="):
            after_call = True
            continue
        m = ENTRY.match(line)
        if not m:
            continue
        token = m.group(1)
        if token.startswith("0x"):
            address = int(token, 16)
        elif token != "*":
            address += int(token)
        if after_call:  # the cost of a call line is the callee's, not this line's
            after_call = False
            continue
        fields = m.group(2).split()
        count[address] += int(fields[-1]) if fields else 0
        owner[address] = os.path.basename(obj or "?")
    return count, owner


def profile(steps, floor, out):
    """Start one callgrind run of `steps` macro steps (the C floor's if `floor`)."""
    command = ["valgrind", "--tool=callgrind", "--dump-instr=yes",
               f"--callgrind-out-file={out}", STEPS, str(steps)]
    if floor:
        command.append("--floor")
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--short", type=int, default=1000)
    parser.add_argument("--long", type=int, default=3000)
    args = parser.parse_args()
    if args.long <= args.short:
        sys.exit("code_lines.py: --long must be larger than --short")
    if shutil.which("valgrind") is None:
        sys.exit("code_lines.py: needs valgrind")
    build = subprocess.run(["cargo", "build", "--release", "-q", "-p", "tether-bench",
                            "--example", "steps"], cwd=ROOT)
    if build.returncode != 0:
        sys.exit("code_lines.py: building the steps example failed (cargo's message above)")
    with tempfile.TemporaryDirectory() as tmp:
        for who, floor in (("Tether", False), ("C floor", True)):
            files = [os.path.join(tmp, f"{who}.{n}") for n in (args.short, args.long)]
            # The two runs go side by side.
            runs = [profile(n, floor, path) for n, path in zip((args.short, args.long), files)]
            if [run.wait() for run in runs] != [0, 0]:
                sys.exit(f"code_lines.py: callgrind failed for {who}")
            short, _ = counts(files[0])
            long, owner = counts(files[1])
            per_step = args.long - args.short
            lines = collections.defaultdict(set)
            for address, n in long.items():
                if n - short.get(address, 0) >= per_step:
                    lines[address // 64].add(owner[address])
            by_object = collections.Counter()
            for objects in lines.values():
                for o in objects:
                    by_object[o] += 1 / len(objects)
            parts = ", ".join(f"{o} {round(n)}" for o, n in by_object.most_common())
            print(f"{who}: {len(lines)} code lines ({len(lines) * 64 / 1024:.1f} KiB) "
                  f"per macro step: {parts}")


if __name__ == "__main__":
    main()
