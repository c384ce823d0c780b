"""What calling Tether through Python costs: a 10⁵-step run of the paper's
oscillator with `tether.run` against the same run through the Rust library
(`crates/tether-master/examples/run_in_memory.rs`, built with the wheel's
profile), alternated, each timed inside its own process.

    cargo build --release -p tether-master --example run_in_memory
    python crates/tether-py/bench/overhead.py [--runs 10] [--stop 100] [--parallel off]

Both time the setup (FMUs loaded, initialised) and the run with its results
in memory; `tether.run` also hands the results to Python (one `bytes` copy,
viewed by NumPy). Prints the medians, the minima and their ratios, of the
wall time and of the CPU time of the calling thread (Linux; with
``parallel off`` the whole run is on that thread, which makes the CPU time
robust against other load on the machine).
"""

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import tether

ROOT = Path(__file__).resolve().parents[3]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=10, help="alternated pairs of runs")
    p.add_argument("--stop", type=float, default=100.0, help="stop time (H = 1e-3)")
    p.add_argument("--parallel", default="off", help="auto, on or off (both sides)")
    p.add_argument("--system", default=str(ROOT / "examples" / "oscillator.toml"))
    p.add_argument("--rust", default=str(ROOT / "target" / "release" / "examples" / "run_in_memory"))
    a = p.parse_args()
    if not os.path.exists(a.rust):
        sys.exit(f"{a.rust} is missing: cargo build --release -p tether-master --example run_in_memory")
    times = {"rust wall": [], "python wall": [], "rust cpu": [], "python cpu": []}
    rows = None
    for i in range(a.runs):
        out = subprocess.run([a.rust, a.system, str(a.stop), a.parallel],
                             capture_output=True, text=True, check=True)
        wall, cpu, n = out.stdout.split()
        times["rust wall"].append(float(wall))
        times["rust cpu"].append(float(cpu))
        cpu0 = thread_cpu()
        start = time.perf_counter()
        result = tether.run(a.system, stop=a.stop, parallel=a.parallel)
        times["python wall"].append(time.perf_counter() - start)
        times["python cpu"].append(thread_cpu() - cpu0)
        assert len(result) == int(n), (len(result), n)
        rows = len(result)
        print(f"run {i + 1}: " + ", ".join(f"{k} {v[-1]:.3f} s" for k, v in times.items()), flush=True)
    print(f"{rows - 1} macro steps, {a.runs} alternated runs each, parallel {a.parallel}; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for what in ("wall", "cpu"):
        r, p_ = times[f"rust {what}"], times[f"python {what}"]
        print(f"{what:>4}: rust library median {statistics.median(r):.3f} s (min {min(r):.3f}), "
              f"tether.run median {statistics.median(p_):.3f} s (min {min(p_):.3f}); "
              f"ratio python/rust: median {statistics.median(p_) / statistics.median(r):.3f}, "
              f"min {min(p_) / min(r):.3f}")


def thread_cpu() -> float:
    """CPU seconds of the calling thread (Linux), else NaN."""
    try:
        with open("/proc/thread-self/schedstat") as f:
            return int(f.read().split()[0]) * 1e-9
    except OSError:
        return float("nan")


if __name__ == "__main__":
    main()
