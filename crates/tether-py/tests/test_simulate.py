"""tether.simulate and tether.info against fmpy on the workspace oscillator FMU."""

import numpy as np
import pytest

import tether

fmpy = pytest.importorskip("fmpy")


@pytest.mark.parametrize("parameters", [{}, {"m": 2.0, "c": 500.0, "x0": 0.1}], ids=["defaults", "set"])
def test_simulate_matches_fmpy(oscillator_fmu, parameters):
    ours = tether.simulate(oscillator_fmu, stop=1.0, step=1e-3, parameters=parameters)
    theirs = fmpy.simulate_fmu(
        str(oscillator_fmu),
        fmi_type="CoSimulation",
        start_time=0.0,
        stop_time=1.0,
        step_size=1e-3,
        output_interval=1e-3,
        start_values=parameters,
    )
    table = ours.to_numpy()
    assert table.dtype.names == theirs.dtype.names
    assert len(table) == len(theirs)
    assert ours.complete and ours.stats["macro_steps"] == 1000
    for name in theirs.dtype.names:
        a, b = table[name], theirs[name]
        deviation = np.max(np.abs(a - b) / np.maximum(np.abs(a), 1.0))
        assert deviation <= 1e-12, (name, deviation)


def test_simulate_errors(tmp_path, oscillator_fmu):
    with pytest.raises(tether.FmuError):
        tether.simulate(tmp_path / "gone.fmu")
    with pytest.raises(tether.SettingsError, match="invalid time span"):
        tether.simulate(oscillator_fmu, start=1.0, stop=0.5)


def test_info_matches_fmpy(oscillator_fmu):
    ours = tether.info(oscillator_fmu)
    md = fmpy.read_model_description(str(oscillator_fmu))
    assert ours["modelName"] == md.modelName
    assert ours["guid"] == md.guid
    assert ours["fmiVersion"] == md.fmiVersion
    assert ours["coSimulation"]["modelIdentifier"] == md.coSimulation.modelIdentifier
    assert ours["coSimulation"]["canGetAndSetFMUstate"] == md.coSimulation.canGetAndSetFMUstate
    names = [v["name"] for v in ours["modelVariables"]]
    assert names == [v.name for v in md.modelVariables]
    for v, w in zip(ours["modelVariables"], md.modelVariables):
        assert v["valueReference"] == w.valueReference
        assert v["causality"] == w.causality
        assert v["type"] == w.type
