"""A stability map on a Dask cluster against the same map run here.

    python crates/tether-py/bench/dask_map.py [--points 20] [--repeat 3] [--workers 2]
    python crates/tether-py/bench/dask_map.py --scheduler tcp://host:8786   # a real cluster

Starts a `LocalCluster` of worker processes (one thread each), unless given a
scheduler address, then alternates the local run (the cells in parallel over
this machine's cores) with the same map on the cluster: with the default
chunks (at least 64 tasks) and with one task per cell. Checks that every run
gives the same map, bit for bit, and prints the wall times, the ratios and
the cluster's overhead per run: (cluster time − local time) / cells. Also the
CPU time of all processes taking part (this one, with a LocalCluster's
scheduler, and the workers): on a machine loaded by other work the wall
times are noise, the CPU times much less.
"""

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

import tether

ROOT = Path(__file__).resolve().parents[3]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=int, default=20, help="cells per axis")
    p.add_argument("--repeat", type=int, default=3, help="alternated rounds")
    p.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")
    p.add_argument("--scheduler", help="address of a running scheduler instead of a LocalCluster")
    a = p.parse_args()
    from dask.distributed import Client, LocalCluster

    system = ROOT / "examples" / "oscillator.toml"
    n = a.points
    kw = dict(
        x=f"mass1.c,mass2.c=1e2..1e6:{n}:log",
        y=f"mass1.d,mass2.d=1e-1..1e3:{n}:log",
        growth=1.0,
        monitor=["mass1.v"],
        beta=0.2,
        gamma=1e-2,
        step=1e-3,
        stop=1.0,
        parallel="off",
    )
    cells = n * n
    started = time.perf_counter()
    if a.scheduler:
        cluster, client = None, Client(a.scheduler)
    else:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    setup = time.perf_counter() - started
    client.run(lambda: __import__("tether"))  # import on the workers once
    times = {"local": [], "cluster": [], "cluster, 1 cell per task": []}
    cpu = {label: [] for label in times}

    def cpu_now() -> float:
        workers = client.run(time.process_time)
        return time.process_time() + sum(workers.values())

    reference = None
    for r in range(a.repeat):
        for label in times:
            cpu0 = cpu_now()
            start = time.perf_counter()
            if label == "local":
                result = tether.sweep_stability(system, **kw)
            elif label == "cluster":
                result = tether.sweep_stability(system, executor=client, **kw)
            else:
                result = tether.sweep_stability(system, executor=client, chunksize=1, **kw)
            times[label].append(time.perf_counter() - start)
            cpu[label].append(cpu_now() - cpu0)
            [m] = result.maps
            bits = (m.classes.tolist(), m.reached.view(np.uint64).tolist(), m.reasons.tolist())
            reference = reference or bits
            assert bits == reference, f"{label} differs"
            print(f"round {r + 1}: {label} {times[label][-1]:.2f} s wall, {cpu[label][-1]:.2f} s CPU",
                  flush=True)
    workers = len(client.scheduler_info()["workers"])
    client.close()
    if cluster is not None:
        cluster.close()
    counts = m.counts()
    print(f"{n}×{n} = {cells} cells ({counts['stable']} stable, {counts['unstable']} unstable, "
          f"{counts['failed']} failed), 1000 steps each; {workers} workers; identical maps: yes")
    print(f"cluster start {setup:.2f} s; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for what, table in (("wall", times), ("CPU", cpu)):
        local = statistics.median(table["local"])
        for label, t in table.items():
            med = statistics.median(t)
            line = f"{what:>4} {label}: median {med:.2f} s (min {min(t):.2f})"
            if label != "local":
                line += (f", ratio to local {med / local:.3f}, "
                         f"overhead per run {(med - local) / cells * 1e3:.2f} ms")
            print(line)


if __name__ == "__main__":
    main()
