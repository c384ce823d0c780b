"""Simulate an FMU with fmpy at a fixed step and write every step to CSV.

    python simulate.py FMU OUT.csv --stop T --step H [--start T0] [--set name=value ...]

The CSV has a `time` column followed by every output, values printed with full
(round-trip) precision. Values of --set: true/false for Booleans, numbers otherwise.
"""

import argparse
import csv
import sys

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
    args = parser.parse_args(argv)

    types = {v.name: v.type for v in read_model_description(args.fmu).modelVariables}
    start_values = {}
    for assignment in args.set:
        name, sep, value = assignment.partition("=")
        if not sep or name not in types:
            parser.error(f"--set {assignment!r}: expected NAME=VALUE with a variable of the FMU")
        value = parse_value(value)
        start_values[name] = float(value) if types[name] == "Real" else value

    result = simulate_fmu(
        args.fmu,
        fmi_type="CoSimulation",
        start_time=args.start,
        stop_time=args.stop,
        step_size=args.step,
        output_interval=args.step,
        start_values=start_values,
    )
    names = result.dtype.names
    with open(args.out, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in result:
            writer.writerow([repr(float(row[name])) for name in names])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
