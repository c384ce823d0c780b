"""tether.simulate and tether.info: against fmpy on the workspace oscillator
FMU, against `tether simulate` (the same simulation) on FMI 3.0 Reference
FMUs, and its checks (NaN outputs, an FMU's request to end)."""

import numpy as np
import pytest

import tether
from conftest import cli, error_line, need_tool, read_csv, same_bits


@pytest.fixture(scope="module")
def fmpy():
    return need_tool("fmpy")


@pytest.mark.parametrize("parameters", [{}, {"m": 2.0, "c": 500.0, "x0": 0.1}], ids=["defaults", "set"])
def test_simulate_matches_fmpy(fmpy, oscillator_fmu, parameters):
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


def test_simulate_of_a_missing_fmu_or_a_bad_time_span_raises_typed_errors(tmp_path, oscillator_fmu):
    with pytest.raises(tether.FmuError):
        tether.simulate(tmp_path / "gone.fmu")
    with pytest.raises(tether.SettingsError, match="invalid time span"):
        tether.simulate(oscillator_fmu, start=1.0, stop=0.5)


def test_info_matches_fmpy(fmpy, oscillator_fmu):
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


FMI3_MODELS = ["BouncingBall", "Dahlquist", "Feedthrough", "Resource", "Stair", "StateSpace",
               "VanDerPol"]


@pytest.mark.parametrize("model", FMI3_MODELS)
def test_info_of_an_fmi3_fmu_matches_fmpy(fmpy, fmi3_reference, model):
    """FMI 3.0: the capability flags, each variable's exact type, causality,
    shape and start values, as fmpy reads them (and names them)."""
    fmu = fmi3_reference(model)
    ours = tether.info(fmu)
    md = fmpy.read_model_description(str(fmu))
    assert ours["fmiVersion"] == md.fmiVersion == "3.0"
    assert ours["guid"] == md.guid
    cs = ours["coSimulation"]
    for flag in ("canGetAndSetFMUstate", "canSerializeFMUstate", "providesIntermediateUpdate",
                 "hasEventMode", "canHandleVariableCommunicationStepSize",
                 "canReturnEarlyAfterIntermediateUpdate", "providesEvaluateDiscreteStates"):
        assert cs[flag] == bool(getattr(md.coSimulation, flag)), flag
    # The same variables (fmpy lists an <Alias> after every variable, here it
    # follows the variable it names).
    theirs = {w.name: w for w in md.modelVariables}
    assert sorted(v["name"] for v in ours["modelVariables"]) == sorted(theirs)
    for v in ours["modelVariables"]:
        w = theirs[v["name"]]
        assert v["valueReference"] == w.valueReference
        assert v["causality"] == w.causality, v["name"]
        assert v["type"] == w.type, v["name"]
        if w.shape is not None:
            assert v["shape"] == tuple(w.shape), v["name"]
        # fmpy keeps a start value as text ("1 0 0 …" for an array).
        if w.start is not None and w.type in ("Float32", "Float64"):
            expected = [float(x) for x in str(w.start).split()]
            got = v["start"] if isinstance(v["start"], list) else [v["start"]]
            assert got == expected, v["name"]
    if model == "BouncingBall":
        # modelDescription.xml: h and v have intermediateUpdate="true" (fmpy
        # 0.3.32 reads it as False), der(h) has none.
        update = {v["name"]: v["intermediateUpdate"] for v in ours["modelVariables"]}
        assert update["h"] and update["v"] and not update["der(h)"]
    if model == "StateSpace":
        shape = {v["name"]: v["shape"] for v in ours["modelVariables"]}
        assert shape["A"] == (3, 3) and shape["B"] == (3, 3) and shape["x"] == (3,)
        assert shape["m"] == ()
        a = next(v for v in ours["modelVariables"] if v["name"] == "A")
        assert a["start"] == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]


def test_simulate_raises_at_a_nan_output_with_the_partial_result(tmp_path, tether_bin, quirks_fmu):
    # The quirks FMU's output x is NaN from t = 0.05 on: the rows before it are
    # the result, as in the CLI's CSV, and the message is the CLI's.
    args = dict(stop=0.1, step=0.01, parameters={"nan_after": 0.05})
    csv = tmp_path / "quirks.csv"
    proc = cli(tether_bin, "simulate", str(quirks_fmu), "--stop", "0.1", "--step", "0.01",
               "--set", "nan_after=0.05", "--out", str(csv))
    assert proc.returncode == 1
    header, rows, trailer = read_csv(csv)
    with pytest.raises(tether.TetherError) as err:
        tether.simulate(quirks_fmu, **args)
    message = str(err.value)
    assert message == ("instance 'quirks': output 'x' = NaN after fmi2DoStep at t = 0.05 "
                       "(the FMU computed a non-finite value)")
    assert error_line(proc).endswith(": " + message)
    assert trailer == "# incomplete: " + message
    partial = err.value.result
    assert partial is not None and not partial.complete
    assert partial.stats["stop_reason"] == message
    assert partial.stats["macro_steps"] == 4
    assert ["time", *partial.columns] == header
    assert same_bits(partial.to_numpy().view(np.float64).reshape(len(partial), -1), rows)
    assert partial["time"][-1] == 0.04


def test_simulate_ends_normally_when_the_fmu_requests_it(quirks_fmu):
    # stop_after: the step reaching t = 0.05 asks to end (fmi2Discard, fmi2Terminated).
    out = tether.simulate(quirks_fmu, stop=0.1, step=0.01, parameters={"stop_after": 0.05})
    assert out.complete
    assert out.stats["termination"]["requested_at"] == out["time"][-1]
    assert out.stats["macro_steps"] == len(out) - 1 < 10


def test_simulate_of_an_fmi2_fmu_equals_the_cli(tmp_path, tether_bin, oscillator_fmu):
    csv = tmp_path / "oscillator.csv"
    proc = cli(tether_bin, "simulate", str(oscillator_fmu), "--stop", "1", "--step", "1e-3",
               "--set", "m=2", "--out", str(csv))
    assert proc.returncode == 0, proc.stderr
    header, rows, trailer = read_csv(csv)
    assert trailer is None
    out = tether.simulate(oscillator_fmu, stop=1.0, step=1e-3, parameters={"m": 2})
    assert out.complete and out.stats["macro_steps"] == 1000
    assert ["time", *out.columns] == header
    assert same_bits(out.to_numpy().view(np.float64).reshape(len(out), -1), rows)


@pytest.mark.parametrize("model", ["StateSpace", "Stair", "BouncingBall", "VanDerPol", "Feedthrough"])
def test_simulate_of_an_fmi3_fmu_equals_the_cli(tmp_path, tether_bin, fmi3_reference, model):
    fmu = fmi3_reference(model)
    csv = tmp_path / f"{model}.csv"
    proc = cli(tether_bin, "simulate", str(fmu), "--out", str(csv))
    assert proc.returncode == 0, proc.stderr
    header, rows, trailer = read_csv(csv)
    assert trailer is None
    out = tether.simulate(fmu)
    assert out.complete
    assert ["time", *out.columns] == header
    assert same_bits(out.to_numpy().view(np.float64).reshape(len(out), -1), rows)
    if model == "StateSpace":
        assert out.columns == ["y[1]", "y[2]", "y[3]"]
    if model == "Stair":
        # Stair asks to end the simulation at t = 9 (fmi3DoStep, terminateSimulation).
        assert out.stats["termination"]["requested_at"] == out["time"][-1] < 10


def test_start_values_go_after_setup_experiment_as_in_fmpy(fmpy, tether_bin, quirks_fmu, tmp_path):
    # reset_parameters = 1: the quirks FMU resets its parameters in
    # fmi2SetupExperiment, as FMUs of some modelling tools do. Tether sets the
    # start values after it, as FMPy does: the value is taken, bit for bit
    # the well-behaved FMU's result, and equal to FMPy's within its rounding.
    parameters = {"reset_parameters": 1, "m": 2.0, "c": 800.0}
    ours = tether.simulate(quirks_fmu, stop=0.2, step=1e-2, parameters=parameters)
    plain = tether.simulate(quirks_fmu, stop=0.2, step=1e-2, parameters={"m": 2.0, "c": 800.0})
    default = tether.simulate(quirks_fmu, stop=0.2, step=1e-2)
    assert same_bits(ours["x"], plain["x"])
    assert not same_bits(ours["x"], default["x"])
    theirs = fmpy.simulate_fmu(str(quirks_fmu), fmi_type="CoSimulation", start_time=0.0, stop_time=0.2,
                               step_size=1e-2, output_interval=1e-2, start_values=parameters)
    np.testing.assert_allclose(ours["x"], theirs["x"], rtol=1e-12, atol=1e-15)


def test_a_parameter_the_fmu_changes_in_initialization_is_a_warning(tether_bin, quirks_fmu, tmp_path):
    # reset_parameters = 2: reset in fmi2ExitInitializationMode, whatever the
    # order; the CLI's `warning:` lines are Python UserWarnings.
    expected = ["instance 'quirks': the FMU changed parameter 'reset_parameters' in its initialization: "
                "set to 2, reads 0",
                "instance 'quirks': the FMU changed parameter 'm' in its initialization: set to 2, reads 1"]
    with pytest.warns(UserWarning) as caught:
        out = tether.simulate(quirks_fmu, stop=0.1, step=1e-2, parameters={"reset_parameters": 2, "m": 2.0})
    # In the order of the parameters' names (the CLI's: the order of --set).
    assert [str(w.message) for w in caught] == expected[::-1]
    assert out.stats["warnings"] == expected[::-1]
    proc = cli(tether_bin, "simulate", str(quirks_fmu), "--stop", "0.1", "--step", "1e-2",
               "--set", "reset_parameters=2", "--set", "m=2", "--out", str(tmp_path / "q.csv"))
    assert proc.returncode == 0, proc.stderr
    assert [l for l in proc.stderr.splitlines() if l.startswith("warning:")] == [f"warning: {w}" for w in expected]
    system = (tether.System().experiment(stop=0.1, step=1e-2)
              .add_instance("mass", quirks_fmu, {"reset_parameters": 2, "c": 800.0}))
    with pytest.warns(UserWarning) as caught:
        sim = tether.Simulation(system)
    assert [str(w.message) for w in caught] == [
        "instance 'mass': the FMU changed parameter 'c' in its initialization: set to 800, reads 1000",
        "instance 'mass': the FMU changed parameter 'reset_parameters' in its initialization: set to 2, reads 0"]
    sim.close()


def test_an_instance_at_its_own_step_as_on_the_command_line(tether_bin, oscillator_fmu, tmp_path):
    # step = 4·H (docs/system-file.md, "Per-instance steps"): the same CSV as
    # `tether run`, the outputs held between the instance's own steps.
    system = (tether.System().experiment(stop=0.1, step=1e-3)
              .add_instance("mass", oscillator_fmu, {"exact": True}, step=4e-3))
    out = tether.run(system)
    path = tmp_path / "system.toml"
    path.write_text(system.to_toml())
    csv = tmp_path / "run.csv"
    proc = cli(tether_bin, "run", str(path), "--out", str(csv))
    assert proc.returncode == 0, proc.stderr
    header, rows, trailer = read_csv(csv)
    assert trailer is None
    assert same_bits(out.to_numpy().view(np.float64).reshape(len(out), -1), rows)
    x = out["mass.x"]
    assert all(x[n] == x[n - n % 4] for n in range(len(x)))
    assert out.stats["instances"]["mass"]["do_step"] == 25


@pytest.mark.parametrize("model", ["VanDerPol", "Dahlquist", "BouncingBall"])
def test_simulate_through_model_exchange_equals_the_cli_and_agrees_with_fmpy(
        tmp_path, tether_bin, fmpy, fmi3_reference, model):
    """``fmi_type="ModelExchange"`` runs the FMU's model-exchange interface
    with the built-in integrator: the same simulation as ``tether simulate
    --fmi-type model-exchange`` bit for bit, and within 1e-5 of each column's
    peak of fmpy's model-exchange run with CVode at rtol 1e-10 on the output
    grid (BouncingBall: away from its bounces)."""
    fmu = fmi3_reference(model)
    csv = tmp_path / f"{model}.csv"
    proc = cli(tether_bin, "simulate", str(fmu), "--fmi-type", "model-exchange",
               "--tolerance", "1e-8", "--out", str(csv))
    assert proc.returncode == 0, proc.stderr
    header, rows, _ = read_csv(csv)
    ours = tether.simulate(fmu, fmi_type="ModelExchange", tolerance=1e-8)
    assert ours.complete and ["time", *ours.columns] == header
    assert same_bits(ours.to_numpy().view(np.float64).reshape(len(ours), -1), rows)
    step = ours["time"][1] - ours["time"][0]
    theirs = fmpy.simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode",
                               relative_tolerance=1e-10, output_interval=step,
                               stop_time=ours["time"][-1])
    times = theirs["time"]
    for name in ours.columns:
        if name not in theirs.dtype.names:
            continue
        a = ours[name].astype(float)
        b = np.interp(ours["time"], times, theirs[name].astype(float))
        keep = np.ones(len(a), dtype=bool)
        if model == "BouncingBall":
            # Leave out the points within one step of a bounce (v changes sign).
            v = ours["v"]
            jumps = np.nonzero(np.sign(v[1:]) != np.sign(v[:-1]))[0]
            for j in jumps:
                keep[max(j - 1, 0):j + 3] = False
        peak = max(np.max(np.abs(b)), 1e-300)
        deviation = np.max(np.abs(a - b)[keep]) / peak
        assert deviation <= 1e-5, (model, name, deviation)


def test_an_unknown_fmi_type_or_a_missing_interface_is_one_error(quirks_fmu):
    # The quirks FMU has co-simulation only (it exists to lack capabilities).
    with pytest.raises(ValueError, match="CoSimulation"):
        tether.simulate(quirks_fmu, fmi_type="Hybrid")
    with pytest.raises(tether.TetherError, match="ModelExchange"):
        tether.simulate(quirks_fmu, fmi_type="ModelExchange")
