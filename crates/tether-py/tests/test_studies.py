"""Studies from Python: the same files as the `tether` command, and the same
results, bit for bit, on a process pool and on a Dask cluster with real
worker processes as here."""

from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import tether
from conftest import cli, error_line, need_tool, same_bits

# A small map of the paper's oscillator, Method 1 on index 1 with large
# Baumgarte parameters at H = 5e-3: stable at small c, unstable at large c.
MAP = dict(
    x="mass1.c,mass2.c=1e2..1e6:6:log",
    y="mass1.d,mass2.d=0.1,10",
    growth=1.0,
    monitor=["mass1.v"],
    method="baumgarte",
    beta=0.2,
    gamma=1e-2,
    step=5e-3,
    stop=0.5,
)
MAP_FLAGS = [
    "--x", MAP["x"], "--y", MAP["y"], "--growth", "1", "--monitor", "mass1.v",
    "--method", "baumgarte", "--beta", "0.2", "--gamma", "1e-2", "--step", "5e-3", "--stop", "0.5",
]


def same_maps(a, b):
    assert a.summary == b.summary
    assert len(a.maps) == len(b.maps)
    for m, n in zip(a.maps, b.maps):
        assert m.label == n.label
        assert same_bits(m.x, n.x) and same_bits(m.y, n.y)
        assert (m.classes == n.classes).all()
        assert same_bits(m.reached, n.reached)
        assert (m.reasons == n.reasons).all()


def test_stability_map_writes_the_files_of_tether_sweep(oscillator_toml, tether_bin, tmp_path):
    result = tether.sweep_stability(oscillator_toml, out_dir=tmp_path / "py", **MAP)
    proc = cli(tether_bin, "sweep", "stability", str(oscillator_toml), *MAP_FLAGS,
               "--out-dir", str(tmp_path / "cli"), "--quiet")
    assert proc.returncode == 0, proc.stderr
    for ext in ("csv", "txt", "svg"):
        assert (tmp_path / "py" / f"stability.{ext}").read_bytes() == \
            (tmp_path / "cli" / f"stability.{ext}").read_bytes(), ext
    [m] = result.maps
    assert m.classes.shape == (2, 6)
    counts = m.counts()
    assert counts["stable"] > 0 and counts["unstable"] > 0, m.classes
    # Stable at the smallest c, unstable at the largest, for both dampings.
    assert m.stable[:, 0].all() and not m.stable[:, -1].any()
    assert (m.reasons[m.stable] == "").all() and (m.reasons[~m.stable] != "").all()
    assert result.summary.startswith(result.title)
    assert sorted(result.files) == sorted(str(tmp_path / "py" / f"stability.{e}") for e in ("csv", "txt", "svg"))


def test_convergence_equals_tether_sweep(oscillator_toml, tether_bin, tmp_path):
    kw = dict(steps=[4e-3, 2e-3, 1e-3], columns=["mass1.x", "mass1.v"], reference="two-mass-oscillator",
              beta=2e-3, gamma=0.0, parameters={"mass1.exact": True, "mass2.exact": True})
    result = tether.sweep_convergence(oscillator_toml, out_dir=tmp_path / "py", **kw)
    proc = cli(tether_bin, "sweep", "convergence", str(oscillator_toml), "--beta", "2e-3", "--gamma", "0",
               "--set", "mass1.exact=true", "--set", "mass2.exact=true", "--steps", "4e-3,2e-3,1e-3",
               "--reference", "two-mass-oscillator", "--columns", "mass1.x,mass1.v",
               "--out-dir", str(tmp_path / "cli"), "--quiet")
    assert proc.returncode == 0, proc.stderr
    for ext in ("csv", "txt"):
        assert (tmp_path / "py" / f"convergence.{ext}").read_bytes() == \
            (tmp_path / "cli" / f"convergence.{ext}").read_bytes(), ext
    [c] = result.curves
    assert list(c.steps) == [4e-3, 2e-3, 1e-3] and c.errors.shape == (3, 2)
    assert c.outcomes == ["completed"] * 3
    # Index 2 (beta only) converges with order 2 against the closed form.
    assert 1.8 < c.order < 2.3, c.order
    assert same_bits(c.error, c.errors.max(axis=1))


def test_process_pool_equals_local(oscillator_toml):
    local = tether.sweep_stability(oscillator_toml, **MAP)
    with ProcessPoolExecutor(max_workers=2) as pool:
        remote = tether.sweep_stability(oscillator_toml, executor=pool, chunksize=5, **MAP)
    same_maps(local, remote)


def test_dask_local_cluster_equals_local(oscillator_toml, tmp_path):
    distributed = need_tool("dask.distributed")
    # A study file with two variants: one map each.
    study = tmp_path / "map.toml"
    study.write_text(
        f"""
        system = "{oscillator_toml}"
        [set]
        step = 5e-3
        stop = 0.5
        [[variant]]
        label = "index 1"
        method = {{ kind = "baumgarte", beta = 0.2, gamma = 1e-2 }}
        [[variant]]
        label = "index 2"
        method = {{ kind = "baumgarte", beta = 0.2 }}
        [stability]
        x = {{ targets = ["mass1.c", "mass2.c"], from = 1e2, to = 1e6, points = 5, scale = "log" }}
        y = {{ targets = ["mass1.d", "mass2.d"], values = [0.1, 10.0] }}
        growth = 1.0
        monitor = ["mass1.v"]
        """
    )
    local = tether.study(study, out_dir=tmp_path / "local")
    seen = []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        pids = set(client.run(lambda: __import__("os").getpid()).values())
        remote = tether.study(study, executor=client, chunksize=3, out_dir=tmp_path / "dask",
                              progress=lambda done, total: seen.append((done, total)))
    assert len(pids) == 2 and __import__("os").getpid() not in pids
    same_maps(local, remote)
    assert [m.label for m in remote.maps] == ["index 1", "index 2"]
    assert (tmp_path / "local" / "map.csv").read_bytes() == (tmp_path / "dask" / "map.csv").read_bytes()
    assert seen[-1] == (20, 20)


def test_a_system_object_and_dict_axes_give_the_maps_of_the_file(oscillator_toml):
    system = tether.System.from_file(oscillator_toml)
    kw = dict(MAP, x={"targets": ["mass1.c", "mass2.c"], "from": 1e2, "to": 1e6, "points": 6, "scale": "log"})
    same_maps(tether.sweep_stability(system, **kw), tether.sweep_stability(oscillator_toml, **MAP))


def test_a_series_study_returns_each_variants_run_and_marks_the_diverged_one(oscillator_toml, tmp_path):
    study = tmp_path / "series.toml"
    study.write_text(
        f"""
        system = "{oscillator_toml}"
        [set]
        stop = 0.1
        [[variant]]
        label = "k = 0"
        [[variant]]
        label = "k = 1, index 3"
        method = {{ kind = "baumgarte" }}
        order = 1
        stop = 1.0
        [series]
        columns = ["mass1.x"]
        """
    )
    result = tether.study(study)
    a, b = result.runs
    assert same_bits(a["mass1.x"], tether.run(oscillator_toml, stop=0.1)["mass1.x"])
    assert a.complete and not b.complete
    assert "diverged" in b.stats["stop_reason"]


def test_study_errors_name_the_culprit(oscillator_toml, tether_bin):
    with pytest.raises(tether.SettingsError) as e:
        tether.sweep_stability(oscillator_toml, x="mass1.c=0..10:3:log", y="step=1e-3")
    assert "log" in str(e.value)
    with pytest.raises(tether.SettingsError) as e:
        tether.sweep_stability(oscillator_toml, x="mass3.c=1,2", y="step=1e-3")
    proc = cli(tether_bin, "sweep", "stability", str(oscillator_toml), "--x", "mass3.c=1,2",
               "--y", "step=1e-3", "--quiet", "--out-dir", "/nonexistent/never")
    assert proc.returncode != 0 and str(e.value) in error_line(proc)
    with pytest.raises(tether.SettingsError):
        tether.sweep_convergence(oscillator_toml, steps=[1e-3], columns=["mass1.x"])
    with pytest.raises(TypeError, match="unexpected override"):
        tether.sweep_stability(oscillator_toml, x="step=1e-3,2e-3", y="step=1e-3", bogus=1)


def test_an_exception_in_the_progress_callback_interrupts_with_the_partial_result(oscillator_toml):
    seen = []

    def progress(step, total):
        seen.append((step, total))
        if step > 0:
            raise RuntimeError("enough")

    with pytest.raises(tether.Interrupted, match="enough") as e:
        tether.run(oscillator_toml, stop=1e6, step=1e-3, progress=progress)
    assert seen and seen[-1][1] == 10**9
    assert 0 < len(e.value.result) < 10**9


def test_ctrl_c_stops_a_local_study(tmp_path, monkeypatch, oscillator_toml):
    import os
    import signal
    import threading

    monkeypatch.setenv("TMPDIR", str(tmp_path))
    # 400 cells of 2000 steps each: far longer than the 0.5 s to the signal.
    grid = dict(MAP, x="mass1.c,mass2.c=1e2..1e4:20:log", y="mass1.d,mass2.d=1..10:20",
                step=1e-3, stop=2.0, parallel="off")
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(tether.Interrupted, match=r"study interrupted after \d+ of 400 runs"):
            tether.sweep_stability(oscillator_toml, **grid)
    finally:
        timer.cancel()
    assert list(tmp_path.iterdir()) == []
