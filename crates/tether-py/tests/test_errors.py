"""Error classes and their messages: the CLI's one-line messages."""

import os
import signal
import threading

import numpy as np
import pytest

import tether
from conftest import cli, error_line, read_csv, same_bits


def test_every_error_is_a_tether_error_and_interrupted_a_keyboard_interrupt():
    for cls in (tether.FmuError, tether.SystemFileError, tether.SettingsError,
                tether.DivergenceError, tether.Interrupted):
        assert issubclass(cls, tether.TetherError)
    assert issubclass(tether.Interrupted, KeyboardInterrupt)
    assert issubclass(tether.SettingsError, ValueError)


def test_a_missing_system_file_raises_the_clis_error_line(tmp_path, tether_bin):
    path = tmp_path / "nope.toml"
    proc = cli(tether_bin, "run", str(path), "--quiet")
    with pytest.raises(tether.SystemFileError) as err:
        tether.run(path)
    assert str(err.value) == error_line(proc)
    assert err.value.result is None


def test_a_malformed_system_file_raises_the_clis_error_line(tmp_path, tether_bin):
    path = tmp_path / "bad.toml"
    path.write_text("[experiment]\nstop = 1\n")
    proc = cli(tether_bin, "run", str(path), "--quiet")
    with pytest.raises(tether.SystemFileError) as err:
        tether.run(path)
    assert str(err.value) == error_line(proc)
    with pytest.raises(tether.SystemFileError):
        tether.System.from_file(path)


def test_a_fifo_as_the_system_file_or_ssp_is_refused_at_once(tmp_path, tether_bin):
    # Opening a FIFO would wait for a writer that never comes: refused before.
    for name in ("system.toml", "system.ssp"):
        path = tmp_path / name
        os.mkfifo(path)
        proc = cli(tether_bin, "run", str(path), "--quiet")
        assert "is a FIFO" in error_line(proc)
        with pytest.raises(tether.SystemFileError) as err:
            tether.run(path)
        assert str(err.value) == error_line(proc)


def test_a_missing_fmu_raises_the_clis_error_line(tmp_path, tether_bin, oscillator_toml):
    text = oscillator_toml.read_text().replace("../target/fmus/oscillator.fmu", str(tmp_path / "gone.fmu"))
    path = tmp_path / "system.toml"
    path.write_text(text)
    proc = cli(tether_bin, "run", str(path), "--quiet", "--out", str(tmp_path / "x.csv"))
    with pytest.raises(tether.FmuError) as err:
        tether.run(path)
    assert str(err.value) == error_line(proc)


def test_an_unknown_parameter_instance_raises_the_clis_error_line(tether_bin, oscillator_toml):
    proc = cli(tether_bin, "run", str(oscillator_toml), "--quiet", "--set", "mass3.m=2")
    with pytest.raises(tether.SettingsError) as err:
        tether.run(oscillator_toml, parameters={"mass3.m": 2.0})
    assert str(err.value) == error_line(proc)


def test_an_unknown_fmu_parameter_names_the_instance_and_suggests(tmp_path, tether_bin, oscillator_toml):
    proc = cli(tether_bin, "run", str(oscillator_toml), "--quiet", "--set", "mass2.mass=4",
               "--out", str(tmp_path / "x.csv"))
    with pytest.raises(tether.FmuError) as err:
        tether.run(oscillator_toml, parameters={"mass2.mass": 4.0})
    where = "instance 'mass2' (oscillator.fmu) has no variable 'mass'; did you mean 'm'?"
    assert str(err.value) == "parameters: " + where
    assert error_line(proc) == "--set mass2.mass: " + where


def test_a_negative_step_raises_the_clis_error_line(tether_bin, oscillator_toml):
    proc = cli(tether_bin, "run", str(oscillator_toml), "--quiet", "--step", "-1")
    with pytest.raises(tether.SettingsError) as err:
        tether.run(oscillator_toml, step=-1.0)
    assert str(err.value) == error_line(proc)


def test_an_unknown_method_or_keyword_is_refused():
    with pytest.raises(tether.SettingsError, match="unknown method 'rk4'"):
        tether.run("unused.toml", method="rk4")
    with pytest.raises(TypeError, match="unexpected keyword"):
        tether.run("unused.toml", alpha=1.0)


def test_divergence_keeps_the_partial_result(tmp_path, tether_bin, oscillator_toml):
    # Index 3 with linear polynomials is unstable (the paper's conclusion).
    csv = tmp_path / "unstable.csv"
    proc = cli(tether_bin, "run", str(oscillator_toml), "--beta", "0", "--gamma", "0",
               "--order", "1", "--out", str(csv), "--quiet")
    assert proc.returncode != 0
    header, rows, trailer = read_csv(csv)
    with pytest.raises(tether.DivergenceError) as err:
        tether.run(oscillator_toml, beta=0, gamma=0, order=1)
    # The CLI's line and the exception go on with the known-unstable
    # formulation's advice; the trailer and the stop reason are the condition.
    text = str(err.value)
    message = err.value.result.stats["stop_reason"]
    assert "diverged" in message
    assert text.startswith(message + "; ")
    assert "index 3 with k = 1 is unstable" in text[len(message):]
    assert error_line(proc).endswith(": " + text)
    assert trailer == "# incomplete: " + message
    partial = err.value.result
    assert partial is not None and not partial.complete
    assert partial.stats["stop_reason"] == message
    assert same_bits(partial.to_numpy().view(np.float64).reshape(len(partial), -1), rows)

    sim = tether.Simulation(oscillator_toml, beta=0, gamma=0, order=1)
    with pytest.raises(tether.DivergenceError) as err:
        sim.run()
    assert str(err.value) == text
    assert same_bits(err.value.result["mass1.x"], rows[:, 1])


def test_ctrl_c_raises_interrupted_with_the_partial_result(tmp_path, monkeypatch, oscillator_toml):
    # The FMUs are unpacked into TMPDIR; nothing may be left there.
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(tether.Interrupted) as err:
            tether.run(oscillator_toml, stop=1e3)
    finally:
        timer.cancel()
    assert isinstance(err.value, KeyboardInterrupt)
    assert str(err.value).startswith("interrupted (Ctrl-C or termination signal) at t = ")
    partial = err.value.result
    assert partial is not None and not partial.complete and len(partial) > 1
    assert partial.stats["stop_reason"] == str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_in_run_until_keeps_the_rows_and_close_removes_the_extractions(tmp_path, monkeypatch, oscillator_toml):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    sim = tether.Simulation(oscillator_toml, stop=1e3)
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(tether.Interrupted) as err:
            sim.run_until(1e3)
    finally:
        timer.cancel()
    assert len(err.value.result) == sim.steps + 1 > 1
    assert list(tmp_path.iterdir()) != []  # the unpacked FMUs, until closed
    sim.close()
    assert list(tmp_path.iterdir()) == []
    assert sim.closed and len(sim.result()) == len(err.value.result)
    with pytest.raises(tether.TetherError, match="closed"):
        sim.step()
    with pytest.raises(tether.TetherError, match="closed"):
        sim.outputs


def test_a_simulation_closes_as_a_context_manager_and_removes_its_extractions(tmp_path, monkeypatch, oscillator_toml):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    with tether.Simulation(oscillator_toml, stop=0.01) as sim:
        sim.run()
    assert sim.closed and list(tmp_path.iterdir()) == []
    assert sim.stats["stop_reason"] == "completed"
