"""The step-wise API against a whole run."""

import numpy as np
import pytest

import tether
from conftest import same_bits


def test_steps_equal_a_whole_run(oscillator_toml):
    whole = tether.run(oscillator_toml, stop=0.3, method="weighted", a=1e-3, b=1e-7)
    sim = tether.Simulation(oscillator_toml, stop=0.3, method="weighted", a=1e-3, b=1e-7)
    assert sim.columns == whole.columns
    assert sim.time == 0.0 and sim.steps == 0 and sim.total_steps == 300
    rows = [sim.values]
    lambdas = [sim.unknowns[0]]
    while not sim.done:
        t = sim.step()
        assert t == sim.time
        rows.append(sim.values)
        lambdas.append(sim.unknowns[0])
        assert sim.outputs["link.lambda"] == sim.unknowns[0]
    table = whole.to_numpy()
    assert same_bits(np.array(rows), table.view(np.float64).reshape(len(table), -1)[:, 1:])
    assert same_bits(np.array(lambdas), whole["link.lambda"])
    assert same_bits(sim.result().to_numpy().view(np.float64), table.view(np.float64))
    assert sim.result().complete
    with pytest.raises(tether.TetherError, match="stop time"):
        sim.step()


def test_run_until_and_outputs(oscillator_toml):
    whole = tether.run(oscillator_toml)
    sim = tether.Simulation(oscillator_toml)
    assert sim.run_until(0.25) == pytest.approx(0.25)
    assert sim.steps == 250
    assert sim.outputs["mass2.x"] == whole["mass2.x"][250]
    assert set(sim.outputs) == set(whole.columns)
    assert not sim.result().complete
    assert sim.stats["stop_reason"] == "running"
    sim.run_until(0.2500000001)  # the next grid point at or after t
    assert sim.steps == 251
    result = sim.run()
    assert result.complete and sim.done
    assert same_bits(result["mass1.v"], whole["mass1.v"])
    assert sim.stats["macro_steps"] == whole.stats["macro_steps"] == 1000
