"""Isolated instances on Dask workers: ``tether.run(system, client=…)``
(docs/remote.md, "Placing instances with Dask").

For each isolated instance (``isolation = "process"``, ``isolate=True``, or
any instance with ``resources``) one task goes to the cluster, restricted to
the instance's ``resources``. On its worker the task writes the run's token
to a file only it may read, starts ``python -m tether._fmi_host --listen``
on the worker's own address (a free port), reports the address and waits;
the master here connects to every host directly, as to a ``tether host``,
and runs. When the run ends (completed, failed or interrupted) the tasks are
told to stop: each kills its host and returns, and its resources are free.
"""

from __future__ import annotations

import asyncio
import copy
import os
import re
import secrets
import shutil
import subprocess
import sys
import tempfile
import threading
import uuid
from typing import Any, Dict, List

# How long a task may take to end its host once told (seconds).
_END_WAIT = 30.0


def _host_task(token: str, run: str, instance: str, max_fmu_mib: int) -> Dict[str, Any]:
    """On a worker: serve `instance` of run `run` until the run ends."""
    from distributed import Event, Queue, get_worker, secede
    from distributed.comm import get_address_host
    from distributed.worker import thread_state

    worker = get_worker()
    key = thread_state.key
    # Out of the worker's thread pool (its slot is free for other tasks),
    # holding the task's resources until it returns.
    secede()
    ip = get_address_host(worker.address)
    listen = f"[{ip}]:0" if ":" in ip else f"{ip}:0"
    folder = tempfile.mkdtemp(prefix="tether-dask-")  # mode 700
    try:
        token_file = os.path.join(folder, "token")
        fd = os.open(token_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(token)
        host = subprocess.Popen(
            [sys.executable, "-m", "tether._fmi_host", "--listen", listen,
             "--token-file", token_file, "--max-fmu-mib", str(max_fmu_mib),
             "--parent", str(os.getpid())],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            text=True,
        )
        try:
            line = host.stderr.readline()
            found = re.search(r"listening on (\S+)", line)
            if not found:
                host.wait()
                rest = line.strip() or f"it ended with exit code {host.returncode}"
                raise RuntimeError(f"the host of instance '{instance}' on worker "
                                   f"{worker.address} did not start: {rest}")
            # What the host says later (a refused master, a crashed FMU) goes
            # to the worker's log.
            threading.Thread(target=_forward, args=(host.stderr, instance), daemon=True).start()
            Queue(run).put({"instance": instance, "host": f"tcp://{found.group(1)}",
                            "worker": worker.address, "pid": host.pid})
            stop = Event(run)
            while not stop.wait(timeout=0.5):
                if host.poll() is not None:
                    raise RuntimeError(f"the host of instance '{instance}' on worker "
                                       f"{worker.address} ended (exit code {host.returncode})")
                # The client is gone (its futures released): end too.
                task = worker.state.tasks.get(key)
                if task is None or task.state == "cancelled":
                    break
        finally:
            host.kill()
            host.wait()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return {"instance": instance, "worker": worker.address}


def _forward(stream: Any, instance: str) -> None:
    for line in stream:
        print(f"tether host of '{instance}': {line.rstrip()}", file=sys.stderr)


def _placed(inst: Dict[str, Any], isolate: bool) -> bool:
    """Whether the instance goes to a worker: isolated or with resources, and
    not already on a host of its own."""
    if inst.get("host") is not None:
        return False
    return bool(isolate or inst.get("isolation") == "process" or inst.get("resources"))


def _check_resources(client: Any, placed: List[Dict[str, Any]], error: Any) -> None:
    """Every instance's resources exist on some worker (else it would wait for ever)."""
    try:  # every worker (distributed ≥ 2025.1 lists 5 unless told)
        info = client.scheduler_info(n_workers=-1)
    except TypeError:
        info = client.scheduler_info()
    workers = info.get("workers", {})
    for inst in placed:
        wanted = inst.get("resources") or {}
        if not wanted:
            continue
        if not any(all(w.get("resources", {}).get(r, 0) >= n for r, n in wanted.items())
                   for w in workers.values()):
            text = ", ".join(f"{r} = {n:g}" for r, n in wanted.items())
            raise error(f"instance '{inst['name']}': no worker of the Dask cluster has the "
                        f"resources {{ {text} }} (start one with dask worker --resources …)")


def run_placed(system: Any, client: Any, kw: Dict[str, Any], run: Any) -> Any:
    """`run(system, **kw)` with the isolated instances' hosts on `client`'s workers."""
    from distributed import Event, Queue, wait

    from . import System, TetherError

    if not isinstance(system, System):
        system = System.from_file(system)
    else:
        system = copy.deepcopy(system)
    placed = [i for i in system.instances if _placed(i, bool(kw.get("isolate")))]
    _check_resources(client, placed, TetherError)
    tag = uuid.uuid4().hex
    name = f"tether-run-{tag}"
    token = secrets.token_hex(32)  # 32 random bytes
    folder = tempfile.mkdtemp(prefix="tether-run-")  # mode 700
    queue = Queue(name, client=client)
    stop = Event(name, client=client)
    tasks: Dict[str, Any] = {}
    hosts: Dict[str, Dict[str, Any]] = {}
    try:
        token_file = os.path.join(folder, "token")
        fd = os.open(token_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(token)
        for inst in placed:
            tasks[inst["name"]] = client.submit(
                _host_task, token, name, inst["name"], 1024,
                resources=dict(inst["resources"]) if inst.get("resources") else None,
                key=f"tether-host-{tag}-{inst['name']}", pure=False)
        while len(hosts) < len(placed):
            try:
                found = queue.get(timeout=0.5)
            except (TimeoutError, asyncio.TimeoutError):
                for instance, task in tasks.items():
                    if task.status in ("error", "cancelled"):
                        try:
                            task.result()
                        except Exception as e:  # the worker's error, one line
                            raise TetherError(
                                f"instance '{instance}': its host on a Dask worker did not start: {e}"
                            ) from None
                continue
            hosts[found["instance"]] = found
        for inst in placed:
            inst["host"] = hosts[inst["name"]]["host"]
            inst["token_file"] = token_file
            inst.pop("isolation", None)
        result = run(system, **kw)
        result.placement = {n: {"worker": h["worker"], "host": h["host"]} for n, h in hosts.items()}
        return result
    finally:
        # Hosts that serve end (their tasks return once they are gone); tasks
        # not started yet never start, those starting end at once.
        stop.set()
        try:
            client.cancel([t for n, t in tasks.items() if n not in hosts])
            wait([t for n, t in tasks.items() if n in hosts], timeout=_END_WAIT)
        finally:
            for task in tasks.values():
                task.release()
            stop.clear()
            queue.close()
            shutil.rmtree(folder, ignore_errors=True)
