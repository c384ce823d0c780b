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


def test_run_until_stops_on_the_grid_and_the_rest_equals_a_whole_run(oscillator_toml):
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


def test_a_force_set_between_steps_follows_the_closed_form(oscillator_toml, oscillator_fmu):
    # A third oscillator that no constraint drives: its force F is free.
    system = tether.System.from_file(oscillator_toml)
    system.add_instance("mass3", oscillator_fmu, {"m": 1.5, "c": 800.0, "d": 4.0, "v0": 1.0, "exact": True})
    plain = tether.run(system, stop=0.4)
    sim = tether.Simulation(system, stop=0.4)
    sim.run_until(0.2)
    x1, v1, t1 = sim.outputs["mass3.x"], sim.outputs["mass3.v"], sim.time
    sim.set_parameter("mass3.F", 40.0)
    result = sim.run()
    # The coupled pair does not see it; mass3 follows the closed form of a
    # damped oscillator under a constant force from t1 on.
    assert same_bits(result["mass1.x"], plain["mass1.x"])
    before = result.time <= t1 + 1e-12
    assert same_bits(result["mass3.x"][before], plain["mass3.x"][before])
    m, c, d, f = 1.5, 800.0, 4.0, 40.0
    delta = d / (2 * m)
    wd = np.sqrt(c / m - delta**2)
    tau = result.time[~before] - t1
    a0 = x1 - f / c
    b0 = (v1 + delta * a0) / wd
    exact = f / c + np.exp(-delta * tau) * (a0 * np.cos(wd * tau) + b0 * np.sin(wd * tau))
    assert np.max(np.abs(result["mass3.x"][~before] - exact)) < 1e-12


def test_set_parameter_refuses_fixed_driven_output_and_unknown_names(oscillator_toml):
    sim = tether.Simulation(oscillator_toml)
    with pytest.raises(tether.SettingsError, match="fixed.*start value"):
        sim.set_parameter("mass1.m", 2.0)
    with pytest.raises(tether.SettingsError, match="coupling drives"):
        sim.set_parameter("mass1.F", 1.0)
    with pytest.raises(tether.SettingsError, match="Real output"):
        sim.set_parameter("mass1.x", 1.0)
    with pytest.raises(tether.SettingsError, match="mass9"):
        sim.set_parameter("mass9.F", 1.0)
    with pytest.raises(tether.SettingsError, match="Fx"):
        sim.set_parameter("mass1.Fx", 1.0)
    sim.close()
    with pytest.raises(tether.TetherError, match="closed"):
        sim.set_parameter("mass1.F", 1.0)
