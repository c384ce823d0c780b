"""The host process of an isolated FMU instance (``isolation = "process"``,
docs/reliability.md): the master starts ``python -m tether._fmi_host`` with
pipes as standard input and output and makes every FMI call of one instance
through them. Not meant to be started by hand.

``python -m tether._fmi_host --listen ADDR:PORT --token-file FILE
[--max-fmu-mib N] [--max-frame-mib N] [--parent PID]`` serves instances to masters over TCP as
``tether host`` does (docs/remote.md): what ``tether.run(system,
client=…)`` starts on a Dask worker."""

import argparse
import os
import sys

from tether import _tether


def _listen(argv):
    parser = argparse.ArgumentParser(prog="python -m tether._fmi_host")
    parser.add_argument("--listen", required=True, metavar="ADDR:PORT")
    parser.add_argument("--token-file", required=True, metavar="FILE")
    parser.add_argument("--max-fmu-mib", type=int, default=1024, metavar="MIB")
    parser.add_argument("--max-frame-mib", type=int, default=256, metavar="MIB")
    parser.add_argument("--parent", type=int, default=None, metavar="PID",
                        help="end when the process PID (the parent) ends")
    args = parser.parse_args(argv)
    _tether.listen_host(args.listen, args.token_file, args.max_fmu_mib << 20,
                        args.max_frame_mib << 20, args.parent)


if __name__ == "__main__":
    try:
        if len(sys.argv) > 1:
            _listen(sys.argv[1:])
        else:
            _tether.serve_fmi_host()
    except RuntimeError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.stderr.flush()
        os._exit(2)
    # The instance is freed and its FMU released: end without the exit-time
    # teardown of FMU libraries still loaded (docs/reliability.md, "After the run").
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)
