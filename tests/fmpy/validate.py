"""Validate FMUs with fmpy: python validate.py A.fmu [B.fmu ...]

Prints the problems fmpy finds in each FMU and exits non-zero if there are any.
"""

import sys

from fmpy.validation import validate_fmu


def main(paths):
    if not paths:
        print("usage: validate.py FMU [FMU ...]", file=sys.stderr)
        return 2
    failed = False
    for path in paths:
        problems = validate_fmu(path)
        if problems:
            failed = True
            print(f"{path}: {len(problems)} problem(s)")
            for problem in problems:
                print(f"  {problem}")
        else:
            print(f"{path}: no problems found")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
