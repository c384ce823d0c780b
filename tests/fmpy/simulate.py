"""Simulate an FMU with fmpy at a fixed step and write every step to CSV.

    python simulate.py FMU OUT.csv --stop T --step H [--start T0] [--set name=value ...]
        [--fmi-type CoSimulation|ModelExchange] [--solver CVode|Euler]
        [--relative-tolerance RTOL]

The CSV has a `time` column followed by every output, values printed with full
(round-trip) precision; an array output (FMI 3.0) is one column per element, named
`y[1]`, `A[2,3]` (1-based, row-major) as Tether names them. Values of --set: true/false for Booleans, numbers otherwise;
an array's values separated by spaces, row-major (`--set "A=1 0 0 1"`).

With --fmi-type ModelExchange fmpy integrates the FMU itself (--solver, default
CVode, at --relative-tolerance) and records the output grid and, at each event, a
row before and a row after it (the same time twice).
"""

import argparse
import csv
import sys

import numpy

from fmpy import read_model_description, simulate_fmu


def parse_value(text):
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text)
    except ValueError:
        return float(text)


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("fmu")
    parser.add_argument("out")
    parser.add_argument("--stop", type=float, required=True, help="stop time")
    parser.add_argument("--step", type=float, required=True, help="communication step size")
    parser.add_argument("--start", type=float, default=0.0, help="start time")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="start value")
    parser.add_argument("--fmi-type", default="CoSimulation", choices=["CoSimulation", "ModelExchange"])
    parser.add_argument("--solver", default="CVode", choices=["CVode", "Euler"])
    parser.add_argument("--relative-tolerance", type=float, default=None)
    args = parser.parse_args(argv)

    types = {v.name: v.type for v in read_model_description(args.fmu).modelVariables}
    start_values = {}
    for assignment in args.set:
        name, sep, value = assignment.partition("=")
        if not sep or name not in types:
            parser.error(f"--set {assignment!r}: expected NAME=VALUE with a variable of the FMU")
        real = types[name] in ("Real", "Float64")
        if " " in value.strip():
            values = [parse_value(v) for v in value.split()]
            start_values[name] = [float(v) for v in values] if real else values
            continue
        value = parse_value(value)
        start_values[name] = float(value) if real else value

    options = {}
    if args.fmi_type == "ModelExchange":
        options = {"solver": args.solver, "relative_tolerance": args.relative_tolerance}
    result = simulate_fmu(
        args.fmu,
        fmi_type=args.fmi_type,
        start_time=args.start,
        stop_time=args.stop,
        step_size=args.step,
        output_interval=args.step,
        start_values=start_values,
        **options,
    )
    names = result.dtype.names
    columns = []  # (header, field name, index into the field or None)
    for name in names:
        shape = result.dtype[name].shape
        if shape:
            for index in numpy.ndindex(*shape):
                columns.append((name + "[" + ",".join(str(i + 1) for i in index) + "]", name, index))
        else:
            columns.append((name, name, None))
    with open(args.out, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow([header for header, _, _ in columns])
        for row in result:
            writer.writerow([
                repr(float(row[name] if index is None else row[name][index]))
                for _, name, index in columns
            ])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
