"""The host process of an isolated FMU instance (``isolation = "process"``,
docs/reliability.md): the master starts ``python -m tether._fmi_host`` with
pipes as standard input and output and makes every FMI call of one instance
through them. Not meant to be started by hand."""

import sys

from tether import _tether

if __name__ == "__main__":
    try:
        _tether.serve_fmi_host()
    except RuntimeError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
