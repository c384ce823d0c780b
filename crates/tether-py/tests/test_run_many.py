"""run_many: the same runs on a process pool as one after the other, bit for bit."""

from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import tether
from conftest import same_bits

# A small stability map: index 3 with k = 1 diverges, the others do not.
VARIANTS = [
    {"stop": 0.1, "beta": beta, "gamma": gamma, "order": order}
    for beta, gamma in [(0.0, 0.0), (2e-3, 1e-6)]
    for order in (0, 1)
]


def bits(result):
    return result.to_numpy().view(np.float64)


def test_process_pool_equals_local_runs(oscillator_toml):
    local = tether.run_many(oscillator_toml, VARIANTS, errors="return")
    with ProcessPoolExecutor(max_workers=2) as pool:
        remote = tether.run_many(oscillator_toml, VARIANTS, executor=pool, errors="return")
    assert len(local) == len(remote) == len(VARIANTS)
    kinds = []
    for a, b, v in zip(local, remote, VARIANTS):
        assert type(a) is type(b)
        if isinstance(a, tether.TetherError):
            assert str(a) == str(b)
            assert same_bits(bits(a.result), bits(b.result))
            kinds.append("failed")
        else:
            assert same_bits(bits(a), bits(b))
            assert same_bits(bits(a), bits(tether.run(oscillator_toml, **v)))
            kinds.append("ok")
    assert kinds == ["ok", "failed", "ok", "ok"], kinds
    assert isinstance(local[1], tether.DivergenceError) and not local[1].result.complete


def test_errors_raise_by_default(oscillator_toml):
    with pytest.raises(tether.DivergenceError):
        tether.run_many(oscillator_toml, VARIANTS)


def test_system_objects_go_to_workers(oscillator_toml):
    system = tether.System.from_file(oscillator_toml)
    with ProcessPoolExecutor(max_workers=2) as pool:
        [a, b] = tether.run_many(system, [{"stop": 0.05}, {"stop": 0.05, "parameters": {"mass1.m": 2.0}}], executor=pool)
    assert same_bits(bits(a), bits(tether.run(oscillator_toml, stop=0.05)))
    assert not np.array_equal(a["mass1.x"], b["mass1.x"])
