"""Isolated instances placed on Dask workers (`tether.run(system,
client=…)`, docs/remote.md) on a real LocalCluster of worker processes, one
of them with the resource `licence`: results bit for bit as in process, the
instance that needs the licence served by a host under that worker, the
resource held while the run goes on, no host left after the run, also when
it fails or is interrupted."""
import os

import numpy as np
import pytest

import tether
from conftest import need_tool, same_bits
from test_remote import LINK, MASS


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of two worker processes, one thread each; the worker
    named "licensed" has the resource licence = 1. Yields (client, address of
    the licensed worker, {worker address: pid})."""
    distributed = need_tool("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        (plain,) = cluster.worker_spec.values()
        options = {**plain["options"], "resources": {"licence": 1}}
        cluster.worker_spec["licensed"] = {"cls": plain["cls"], "options": options}
        cluster.scale(2)
        with distributed.Client(cluster) as client:
            client.wait_for_workers(2, timeout=120)
            workers = client.scheduler_info()["workers"]
            (licensed,) = [a for a, w in workers.items() if w["resources"].get("licence")]
            yield client, licensed, client.run(os.getpid)


def children(pid):
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                parent = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError):
            continue  # ended meanwhile
        if parent == pid:
            out.append(int(entry))
    return out


def cmdline(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().split(b"\0")
    except OSError:
        return []


def hosts(pids):
    """{worker address: [(listener pid, [its host processes])]}: the Tether
    hosts each worker runs now."""
    out = {}
    for address, pid in pids.items():
        listeners = [c for c in children(pid)
                     if b"tether._fmi_host" in cmdline(c) and b"--listen" in cmdline(c)]
        out[address] = [(c, children(c)) for c in listeners]
    return out


def licences(client, address):
    return client.run(lambda dask_worker: dask_worker.state.available_resources["licence"],
                      workers=[address])[address]


def pair(oscillator_fmu, stop=1.0, **mass2):
    return (
        tether.System("two-mass oscillator")
        .experiment(stop=stop, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .add_instance("mass1", oscillator_fmu, {"m": 1.0, **MASS})
        .add_instance("mass2", oscillator_fmu, {"m": 2.0, **MASS}, **mass2)
        .add_constraint("link", **LINK, initial="consistent")
    )


def assert_no_host_left(client, licensed, pids):
    assert all(found == [] for found in hosts(pids).values()), hosts(pids)
    # The task returned: its resource is free again.
    assert licences(client, licensed) == 1


def test_an_instance_needing_a_licence_runs_on_the_licensed_worker(cluster, oscillator_fmu):
    client, licensed, pids = cluster
    seen = []

    def look(step, total):
        if not seen:
            seen.append((hosts(pids), licences(client, licensed)))

    # 5000 steps: the run lasts longer than the 50 ms to the first progress call.
    placed = tether.run(pair(oscillator_fmu, stop=5.0, resources={"licence": 1}), client=client,
                        progress=look)
    local = tether.run(pair(oscillator_fmu, stop=5.0))
    assert placed.complete and placed.columns == local.columns
    assert same_bits(placed.to_numpy().view(np.float64), local.to_numpy().view(np.float64))
    # While the run went on: one host, under the licensed worker, serving
    # the master (a host process per connection), the licence held.
    assert seen, "the run ended before the first progress call"
    during, held = seen[0]
    assert held == 0
    # (The master may open more than one connection: copies for parallel
    # perturbed runs are host processes of their own.)
    assert [len(served) >= 1 for _, served in during[licensed]] == [True], during
    assert all(found == [] for address, found in during.items() if address != licensed), during
    assert list(placed.placement) == ["mass2"]
    assert placed.placement["mass2"]["worker"] == licensed
    ip = licensed.split("://")[1].rsplit(":", 1)[0]
    assert placed.placement["mass2"]["host"].startswith(f"tcp://{ip}:")
    assert_no_host_left(client, licensed, pids)


def test_double_pendulum_on_workers_is_bit_for_bit(cluster, root):
    client, licensed, pids = cluster
    system = root / "examples" / "double_pendulum.toml"
    local = tether.run(system, stop=1.0)
    placed = tether.run(system, stop=1.0, isolate=True, client=client)
    assert sorted(placed.placement) == ["link1", "link2"]
    assert placed.columns == local.columns
    assert same_bits(placed.to_numpy().view(np.float64), local.to_numpy().view(np.float64))
    assert set(h["worker"] for h in placed.placement.values()) <= set(pids)
    assert_no_host_left(client, licensed, pids)


def test_a_failing_run_ends_the_hosts(cluster, oscillator_fmu, tmp_path, root):
    client, licensed, pids = cluster
    # Not an FMU: the master cannot load it, after the hosts started.
    broken = tmp_path / "broken.fmu"
    broken.write_bytes(b"not a zip archive")
    system = pair(oscillator_fmu, isolation="process")
    system.instances[0]["fmu"] = str(broken)
    system.instances[0]["isolation"] = "process"
    with pytest.raises(tether.FmuError) as failed:
        tether.run(system, client=client)
    assert "broken.fmu" in str(failed.value) and "\n" not in str(failed.value)
    assert_no_host_left(client, licensed, pids)
    # An FMU that crashes on its worker at t = 0.5: the rows before it are kept.
    faults = root / "target" / "fmus" / "faults.fmu"
    system = pair(oscillator_fmu, resources={"licence": 1})
    system.instances[1]["fmu"] = str(faults)
    system.instances[1]["parameters"]["mode"] = 1
    with pytest.raises(tether.TetherError) as failed:
        tether.run(system, client=client)
    assert "instance 'mass2'" in str(failed.value) and "t=0.5" in str(failed.value), failed.value
    assert failed.value.result is not None and not failed.value.result.complete
    assert failed.value.result.time[-1] == pytest.approx(0.5, abs=1.5e-3)
    assert_no_host_left(client, licensed, pids)


def test_an_interrupted_run_ends_the_hosts(cluster, oscillator_fmu):
    client, licensed, pids = cluster

    def stop(step, total):
        raise KeyboardInterrupt

    with pytest.raises(tether.Interrupted) as stopped:
        tether.run(pair(oscillator_fmu, stop=5.0, resources={"licence": 1}), client=client,
                   progress=stop)
    assert not stopped.value.result.complete
    assert_no_host_left(client, licensed, pids)


def test_resources_no_worker_has_are_one_line(cluster, oscillator_fmu):
    client, licensed, pids = cluster
    with pytest.raises(tether.TetherError) as missing:
        tether.run(pair(oscillator_fmu, resources={"gpu": 1}), client=client)
    assert str(missing.value) == (
        "instance 'mass2': no worker of the Dask cluster has the resources { gpu = 1 } "
        "(start one with dask worker --resources …)")
    assert_no_host_left(client, licensed, pids)


def test_resources_travel_through_the_system_file(tmp_path, oscillator_fmu):
    system = pair(oscillator_fmu, resources={"licence": 1})
    system.save(tmp_path / "placed.toml")
    assert "[instance.resources]\nlicence = 1\n" in (tmp_path / "placed.toml").read_text()
    loaded = tether.System.from_file(tmp_path / "placed.toml")
    assert loaded.instances[1]["resources"] == {"licence": 1.0}
    # Without a client the instance runs here, bit for bit as without the key.
    a = tether.run(loaded, stop=0.1)
    b = tether.run(pair(oscillator_fmu), stop=0.1)
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))
    bad = pair(oscillator_fmu, resources={"licence": "yes"})
    with pytest.raises(tether.SystemFileError) as wrong:
        tether.run(bad)
    assert "expected a number of units of a Dask worker resource" in str(wrong.value)


VANISHING = """
import sys
sys.path.insert(0, sys.argv[2])
import distributed, tether
from test_dask_placement import pair
client = distributed.Client(sys.argv[1])
tether.run(pair(sys.argv[3], stop=500.0, resources={"licence": 1}), client=client)
"""


def test_a_vanished_client_ends_its_hosts(cluster, oscillator_fmu):
    """A client killed during its run: the scheduler releases its tasks, whose
    hosts end."""
    import subprocess
    import sys
    import time

    client, licensed, pids = cluster
    tests = os.path.dirname(os.path.abspath(__file__))
    other = subprocess.Popen([sys.executable, "-c", VANISHING, client.scheduler.address, tests,
                              str(oscillator_fmu)], stderr=subprocess.DEVNULL)
    try:
        for _ in range(600):  # the host serving, within a minute
            time.sleep(0.1)
            if any(served for _, served in hosts(pids)[licensed]):
                break
        else:
            raise AssertionError(f"no host served the other client: {hosts(pids)}")
    finally:
        other.kill()
        other.wait()
    for _ in range(100):  # gone within ten seconds
        time.sleep(0.1)
        if all(found == [] for found in hosts(pids).values()) and licences(client, licensed) == 1:
            break
    assert_no_host_left(client, licensed, pids)


def test_model_exchange_instances_on_workers_are_bit_for_bit(cluster, oscillator_fmu):
    """Model-exchange instances placed on Dask workers: the integrator runs
    in the worker's host, the results are the in-process run's bits."""
    client, licensed, pids = cluster
    me = {"fmi_type": "model_exchange", "integrator": {"method": "rk45", "rtol": 1e-10}}

    def system():
        return (
            tether.System("two-mass oscillator")
            .experiment(stop=0.5, step=1e-3)
            .method("baumgarte", beta=2e-3, gamma=1e-6)
            .add_instance("mass1", oscillator_fmu, {"m": 1.0, **MASS}, **me)
            .add_instance("mass2", oscillator_fmu, {"m": 2.0, **MASS}, resources={"licence": 1}, **me)
            .add_constraint("link", **LINK, initial="consistent")
        )

    local = tether.run(system())
    placed = tether.run(system(), client=client)
    assert placed.complete and placed.columns == local.columns
    assert placed.placement["mass2"]["worker"] == licensed
    assert same_bits(placed.to_numpy().view(np.float64), local.to_numpy().view(np.float64))
    assert_no_host_left(client, licensed, pids)
