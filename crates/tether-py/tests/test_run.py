"""tether.run against the CLI's CSV, bit for bit, and the Result API."""

import numpy as np
import pytest

import tether
from conftest import cli, need_tool, read_csv, same_bits

VARIANTS = [
    {},
    {"method": "weighted", "a": 1e-3, "b": 1e-7},
    {"method": "explicit", "mu": 5e-3, "step": 2e-3},
    {"beta": 5e-3, "gamma": 2e-6, "order": 2, "epsilon": 1e-6, "parameters": {"mass2.m": 3.0, "mass1.d": 0}},
    {"stop": 0.25, "order": 1, "parallel": "off", "parameters": {"mass1.m": 2}},
    {"stop": 0.1, "parallel": "on", "threads": 2},
    {"method": "weighted", "index": 2, "iterations": 2, "jacobian": "reuse",
     "output_interval": 0.002, "output_variables": "mass1.*,link.g"},
    {"index": 3, "step_rtol": 1e-4, "step_atol": 1e-6, "stop": 0.1},
]


def flags(overrides):
    out = []
    for key, value in overrides.items():
        if key == "parameters":
            for target, v in value.items():
                out += ["--set", f"{target}={v}"]
        else:
            out += [f"--{key.replace('_', '-')}", str(value)]
    return out


@pytest.mark.parametrize("overrides", VARIANTS, ids=lambda o: ",".join(o) or "file")
def test_run_equals_cli_csv_bit_for_bit(tmp_path, tether_bin, oscillator_toml, overrides):
    csv = tmp_path / "cli.csv"
    proc = cli(tether_bin, "run", str(oscillator_toml), "--out", str(csv), "--quiet", *flags(overrides))
    assert proc.returncode == 0, proc.stderr
    header, rows, trailer = read_csv(csv)
    assert trailer is None

    result = tether.run(oscillator_toml, **overrides)
    assert result.complete
    assert ["time"] + result.columns == header
    assert same_bits(result.time, rows[:, 0])
    for i, name in enumerate(header):
        assert same_bits(result[name], rows[:, i]), name
    table = result.to_numpy()
    assert list(table.dtype.names) == header
    assert same_bits(table.view(np.float64).reshape(len(table), -1), rows)


def test_double_pendulum_equals_cli(tmp_path, tether_bin, root, oscillator_fmu):
    system = root / "examples" / "double_pendulum.toml"
    csv = tmp_path / "cli.csv"
    proc = cli(tether_bin, "run", str(system), "--out", str(csv), "--quiet", "--stop", "0.2")
    assert proc.returncode == 0, proc.stderr
    header, rows, _ = read_csv(csv)
    result = tether.run(system, stop=0.2)
    assert ["time"] + result.columns == header
    assert same_bits(result.to_numpy().view(np.float64).reshape(len(result), -1), rows)


def test_result_gives_columns_as_float_arrays_and_the_run_stats(oscillator_toml):
    result = tether.run(oscillator_toml, stop=0.1)
    assert len(result) == 101
    assert "mass1.x" in result and "time" in result and "nope" not in result
    assert list(result) == ["time"] + result.columns
    x = result["mass1.x"]
    assert x.dtype == np.float64 and x.shape == (101,) and x.flags.writeable
    with pytest.raises(KeyError, match="no column 'nope'"):
        result["nope"]
    stats = result.stats
    assert stats["macro_steps"] == 100
    assert stats["stop_reason"] == "completed"
    assert stats["jacobian_solves"] > 0
    assert stats["wall_time"] > 0
    assert set(stats["instances"]) == {"mass1", "mass2"}
    assert stats["instances"]["mass1"]["do_step"] > 100
    assert set(stats["instances"]["mass1"]) == {
        "do_step", "get_fmu_state", "set_fmu_state", "set_real", "get_real",
        "get_integer", "get_boolean", "set_integer", "set_boolean", "get_string", "set_string",
        "set_real_input_derivatives", "get_real_output_derivatives", "round_trips",
    }
    assert set(stats["times"]) >= {"setup", "predictor", "jacobian", "solve", "corrector", "recording"}
    assert "macro steps: 100" in stats["summary"]


def test_fmpy_write_csv_accepts_the_result(tmp_path, oscillator_toml):
    fmpy_util = need_tool("fmpy.util")
    result = tether.run(oscillator_toml, stop=0.05)
    out = tmp_path / "fmpy.csv"
    fmpy_util.write_csv(str(out), result.to_numpy())
    lines = out.read_text().splitlines()
    assert lines[0].replace('"', "").split(",") == ["time"] + result.columns
    assert len(lines) == 1 + len(result)
    first = [float(v) for v in lines[2].split(",")]
    assert np.allclose(first, result.to_numpy()[1].tolist(), rtol=1e-15, atol=0)


def test_fmpy_plot_result_accepts_the_result(tmp_path, oscillator_toml):
    # fmpy 0.3's plot_result draws with plotly: create_plotly_figure is its
    # whole reading of the result (writing an image then needs kaleido).
    fmpy_util = need_tool("fmpy.util")
    need_tool("plotly")
    result = tether.run(oscillator_toml, stop=0.05)
    figure = fmpy_util.create_plotly_figure(result.to_numpy(), names=["mass1.x", "link.lambda"])
    out = tmp_path / "plot.html"
    figure.write_html(str(out))
    assert out.stat().st_size > 0
    assert len(figure.data) == 2
    assert np.array_equal(np.asarray(figure.data[0].y), result["mass1.x"])


def test_to_pandas_gives_a_frame_with_the_columns_in_order(oscillator_toml):
    pd = need_tool("pandas")
    frame = tether.run(oscillator_toml, stop=0.01).to_pandas()
    assert isinstance(frame, pd.DataFrame)
    assert list(frame.columns)[:2] == ["time", "mass1.x"]


def test_system_from_file_runs_the_same(oscillator_toml):
    system = tether.System.from_file(oscillator_toml)
    assert [i["name"] for i in system.instances] == ["mass1", "mass2"]
    text = system.to_toml()
    assert "[[constraint]]" in text and "kind = \"baumgarte\"" in text
    a = tether.run(oscillator_toml, stop=0.2)
    b = tether.run(system, stop=0.2)
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))


# The rigid link of the two-mass oscillator (examples/oscillator.toml).
LINK = dict(
    position="mass2.x - mass1.x",
    velocity="mass2.v - mass1.v",
    acceleration="mass2.a - mass1.a",
    drives="mass1.F - mass2.F",
)


def test_system_built_in_code_runs_like_the_file(tmp_path, oscillator_toml, oscillator_fmu):
    system = (
        tether.System("two-mass oscillator")
        .experiment(stop=0.2, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .coupling(order=0, epsilon=1e-5)
        .add_instance("mass1", oscillator_fmu, {"m": 1.0, "c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0})
        .add_instance("mass2", oscillator_fmu, {"m": 2.0, "c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0})
        .add_constraint("link", **LINK, initial="consistent")
    )
    a = tether.run(oscillator_toml, stop=0.2)
    b = tether.run(system)
    assert a.columns == b.columns
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))
    # The text is a system file the CLI reads too.
    path = tmp_path / "built.toml"
    system.save(path)
    c = tether.run(path)
    assert same_bits(a.to_numpy().view(np.float64), c.to_numpy().view(np.float64))


def test_threads_and_an_instance_kept_on_the_main_thread_from_the_builder(oscillator_toml, oscillator_fmu):
    """``parallel=False`` on an instance and ``threads`` on the coupling: mass 1
    stays on the main thread, mass 2 goes to the one worker, and the run is
    the file's bit for bit."""
    system = (
        tether.System("two-mass oscillator")
        .experiment(stop=0.2, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .coupling(order=0, epsilon=1e-5, parallel="on", threads=3)
        .add_instance("mass1", oscillator_fmu, {"m": 1.0, "c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0},
                      parallel=False)
        .add_instance("mass2", oscillator_fmu, {"m": 2.0, "c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0})
        .add_constraint("link", **LINK, initial="consistent")
    )
    a = tether.run(oscillator_toml, stop=0.2, parallel="off")
    b = tether.run(system)
    assert b.stats["parallel"]["workers"] == 1
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))


def test_model_exchange_instances_from_the_builder(tmp_path, tether_bin, oscillator_fmu):
    """``fmi_type`` and ``integrator`` on an instance: the pair through the
    oscillator's model-exchange interface equals the CLI's run of the saved
    system file bit for bit, and fmpy's spelling is accepted."""
    system = (
        tether.System("two-mass oscillator")
        .experiment(stop=0.2, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .add_instance("mass1", oscillator_fmu, {"m": 1.0, "c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0},
                      fmi_type="ModelExchange", integrator={"method": "rk45", "rtol": 1e-12})
        .add_instance("mass2", oscillator_fmu, {"m": 2.0, "c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0},
                      fmi_type="model_exchange", integrator={"method": "rk45", "rtol": 1e-12})
        .add_constraint("link", **LINK, initial="consistent")
    )
    result = tether.run(system)
    assert "steps integrated" in result.stats["summary"]
    path = tmp_path / "me.toml"
    system.save(path)
    proc = cli(tether_bin, "run", str(path), "--out", str(tmp_path / "me.csv"))
    assert proc.returncode == 0, proc.stderr
    header, rows, _ = read_csv(tmp_path / "me.csv")
    assert ["time"] + result.columns == header
    table = result.to_numpy()
    assert same_bits(table.view(np.float64).reshape(len(table), -1), rows)
    with pytest.raises(tether.SystemFileError, match="fmi_type"):
        tether.run(system.add_instance("mass3", oscillator_fmu, fmi_type="scheduled"))


def test_system_without_experiment_is_an_error():
    with pytest.raises(tether.SystemFileError, match="no experiment"):
        tether.System().to_toml()


def test_stats_have_the_schema_of_the_cli_summary_json(tmp_path, tether_bin, oscillator_toml):
    """result.stats is the run summary `tether run --summary-json` writes
    (docs/run-summary.md), plus the text `summary` and the setup's `notes`
    and `warnings`."""
    import json

    summary = tmp_path / "summary.json"
    cli(tether_bin, "run", str(oscillator_toml), "--stop", "0.1", "--out", str(tmp_path / "r.csv"),
        "--summary-json", str(summary))
    theirs = json.loads(summary.read_text())
    ours = tether.run(oscillator_toml, stop=0.1).stats
    assert set(ours) == set(theirs) | {"summary", "notes", "warnings"}
    assert ours["schema"] == theirs["schema"] == "tether-run-summary/1"
    for key in ["method", "order", "step", "stop", "completed", "stop_reason", "end_time",
                "macro_steps", "jacobian_solves", "max_abs_g", "instances"]:
        assert ours[key] == theirs[key], key


def test_signal_connections_built_in_code_run_like_the_file(root):
    """The controlled oscillator (examples/controlled_oscillator.toml: a rigid
    link, a PI controller without rollback on signal connections) built with
    add_connection gives the file's results bit for bit, and from_file keeps
    the connections, and output() selects what is recorded."""
    fmus = root / "target" / "fmus"
    masses = {"c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 0.0}
    system = (
        tether.System("controlled two-mass oscillator")
        .experiment(stop=0.2, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .coupling(order=1)
        .signals("jacobi")
        .add_instance("ctrl", fmus / "controller.fmu", {"kp": 1000.0, "ki": 10000.0, "r": 0.1})
        .add_instance("mass1", fmus / "oscillator.fmu", {"m": 1.0, **masses})
        .add_instance("mass2", fmus / "oscillator.fmu", {"m": 2.0, **masses})
        .add_constraint("link", **LINK)
        .add_connection("mass1.x", "ctrl.y")
        .add_connection("ctrl.u", "mass1.F_ext")
    )
    example = root / "examples" / "controlled_oscillator.toml"
    a = tether.run(example, stop=0.2)
    b = tether.run(system)
    assert a.columns == b.columns
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))
    # The controller moved the masses: the connections took effect.
    assert np.max(np.abs(b["mass1.x"])) > 1e-3
    loaded = tether.System.from_file(example).output(interval=2e-3, variables=["mass1.*"])
    text = loaded.to_toml()
    assert text.count("[[connection]]") == 2  # [signals] is left out when it is the default
    c = tether.run(loaded, stop=0.2)
    assert c.columns == [col for col in a.columns if col.startswith("mass1.")]
    assert same_bits(c["mass1.x"], a["mass1.x"][::2])


def test_isolated_instances_run_in_python_hosts_bit_for_bit(oscillator_toml):
    """isolation = "process" from Python: the hosts are `python -m
    tether._fmi_host` processes (no extra executable), and the results are
    those of the in-process run bit for bit."""
    system = tether.System.from_file(oscillator_toml)
    for inst in system.instances:
        inst["isolation"] = "process"
    a = tether.run(oscillator_toml, stop=0.05)
    b = tether.run(system, stop=0.05)
    assert a.columns == b.columns
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))


def test_fmpy_names_mean_the_same_and_both_names_are_an_error(oscillator_toml):
    ours = tether.run(oscillator_toml, stop=0.05, parameters={"mass2.m": 3.0},
                      output_variables=["mass1.x", "link.*"])
    fmpy = tether.run(oscillator_toml, stop_time=0.05, start_values={"mass2.m": 3.0},
                      output=["mass1.x", "link.*"])
    assert ours.columns == fmpy.columns == ["mass1.x", "link.lambda", "link.g"]
    for name in ["time"] + ours.columns:
        assert same_bits(ours[name], fmpy[name]), name
    with pytest.raises(TypeError, match="stop and stop_time are the same setting; give one of them"):
        tether.run(oscillator_toml, stop=0.05, stop_time=0.05)
    with pytest.raises(TypeError, match="parameters and start_values are the same setting"):
        tether.run(oscillator_toml, parameters={}, start_values={})
    with pytest.raises(TypeError, match="output_variables and output are the same setting"):
        tether.run(oscillator_toml, output_variables="link.g", output="link.g")


def test_isolate_and_call_timeout_are_keywords(oscillator_toml):
    inline = tether.run(oscillator_toml, stop=0.02)
    isolated = tether.run(oscillator_toml, stop=0.02, isolate=True, call_timeout=30.0)
    for name in ["time"] + inline.columns:
        assert same_bits(inline[name], isolated[name]), name


def test_version_is_the_packages():
    assert tether.__version__ == "0.1.0"


def test_to_toml_keeps_the_order_of_the_file(tmp_path, oscillator_toml):
    """A loaded system writes its sections in the file's order, also an
    unusual one (instances first, the method last)."""
    text = oscillator_toml.read_text()
    sections = text.split("\n[")
    head, tables = sections[0], ["[" + t for t in sections[1:]]
    method = [t for t in tables if t.startswith("[method]")]
    rest = [t for t in tables if not t.startswith("[method]")]
    experiment = [t for t in rest if t.startswith("[experiment]")]
    others = [t for t in rest if not t.startswith("[experiment]")]
    reordered = tmp_path / "reordered.toml"
    fmu_dir = oscillator_toml.parent
    body = "\n".join([head] + others + experiment + method)
    reordered.write_text(body.replace('"../target', '"' + str(fmu_dir / "../target")))
    def order(t):
        names = [line.strip("[]").split(".")[0] for line in t.splitlines() if line.startswith("[")]
        return [n for i, n in enumerate(names) if i == 0 or names[i - 1] != n]
    written = tether.System.from_file(reordered).to_toml()
    assert order(written) == order(reordered.read_text()), written
    # The keys inside a table too: [experiment] is start, stop, step in the
    # file (not alphabetical), and so is the written text.
    def keys(t, table):
        lines = t.split("[" + table + "]\n", 1)[1].split("\n[", 1)[0].splitlines()
        return [line.split("=")[0].strip() for line in lines
                if "=" in line and not line.startswith("#")]
    assert keys(written, "experiment") == keys(reordered.read_text(), "experiment") == [
        "start", "stop", "step"], written
    # And it runs as the original does.
    a = tether.run(oscillator_toml, stop=0.05)
    b = tether.run(tether.System.from_file(reordered), stop=0.05)
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))


def test_iterated_signals_from_the_builder(root, tmp_path):
    """The control loop through direct feedthrough with a PI controller that
    can roll back (fmus/lti), iterated by Newton (signals(iterations=...,
    solver="newton")): the same rows as the same system file, bit for bit,
    and the summary's iteration counts; iterations=1 with strict=True fails
    the run with one line."""
    lti = root / "target" / "fmus" / "lti.fmu"
    pi = {"a": 0.0, "b1": 1.0, "b2": -1.0, "c": 2.0, "d1": 1.0, "d2": -1.0, "x0": 0.0, "u1": 1.0}
    plant = {"a": -1.0, "b1": 1.0, "b2": 1.0, "c": 1.0, "d1": 0.5, "d2": 0.5, "x0": 0.0}

    def loop(**signals):
        return (
            tether.System("iterated loop")
            .experiment(stop=0.1, step=1e-2)
            .signals(tolerance=1e-12, **signals)
            .add_instance("source", lti, {"a": -2.0, "b1": 0.0, "c": 1.0, "x0": 1.0})
            .add_instance("controller", lti, pi)
            .add_instance("plant", lti, plant)
            .add_connection("source.y", "plant.u2")
            .add_connection("controller.y", "plant.u1")
            .add_connection("plant.y", "controller.u2")
        )

    system = loop(iterations=10, solver="newton")
    path = tmp_path / "loop.toml"
    path.write_text(system.to_toml())
    assert 'solver = "newton"' in path.read_text()
    a = tether.run(system)
    b = tether.run(path)
    assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))
    counts = a.stats["signals"]
    assert counts["solver"] == "newton"
    assert counts["not_converged"] == 0
    assert 1 <= counts["max_iterations"] <= 2
    plain = tether.run(loop(scheme="jacobi"))
    assert "signals" not in plain.stats
    assert np.max(np.abs(plain["plant.y"] - a["plant.y"])) > 1e-4
    with pytest.raises(tether.DivergenceError) as failed:
        tether.run(loop(iterations=1, strict=True))
    assert str(failed.value).startswith("[signals] strict: the macro step from t = 0 did not converge")
