"""A direct-feedthrough loop of signal connections from Python
(docs/algorithm.md, "Signal connections"): examples/control_loop.toml, a PI
controller and a plant with feedthrough, solved at T_0 and closed at the macro
points. The results are the CLI's bit for bit, and the setup's note on the
loop, which the CLI prints as `note: …`, reaches Python as a ``tether.Note``
warning and in ``stats["notes"]``."""

import warnings

import numpy as np
import pytest

import tether
from conftest import _need, cli, read_csv, same_bits


@pytest.fixture(scope="session")
def control_loop(root):
    for fmu in ("lti", "controller"):
        _need(root / "target" / "fmus" / f"{fmu}.fmu", "run `cargo xtask fmus`")
    return root / "examples" / "control_loop.toml"


def cli_notes(proc):
    """The CLI's notes, each joined from its lines (wrapped within 100
    characters, the continuation lines indented)."""
    notes, in_note = [], False
    for line in proc.stderr.splitlines():
        if line.startswith("note: "):
            notes.append(line[len("note: "):])
            in_note = True
        elif in_note and line.startswith("  "):
            notes[-1] += " " + line.strip()
        else:
            in_note = False
    return notes


def test_control_loop_equals_cli_and_notes_the_loop(tmp_path, tether_bin, control_loop):
    csv = tmp_path / "cli.csv"
    proc = cli(tether_bin, "run", str(control_loop), "--out", str(csv), "--quiet")
    assert proc.returncode == 0, proc.stderr
    header, rows, trailer = read_csv(csv)
    assert trailer is None
    notes = cli_notes(proc)
    assert len(notes) == 1 and notes[0].startswith("direct-feedthrough loop through controller, plant"), notes

    with pytest.warns(tether.Note) as caught:
        result = tether.run(control_loop)
    assert [str(w.message) for w in caught if w.category is tether.Note] == notes
    assert result.stats["notes"] == notes
    assert result.complete
    assert ["time"] + result.columns == header
    assert same_bits(result.to_numpy().view(np.float64).reshape(len(result), -1), rows)

    # Step by step: the same note when the run is set up, the same rows.
    with pytest.warns(tether.Note) as caught:
        sim = tether.Simulation(control_loop)
    assert [str(w.message) for w in caught if w.category is tether.Note] == notes
    assert sim.stats["notes"] == notes
    while not sim.done:
        sim.step()
    assert same_bits(sim.result().to_numpy().view(np.float64).reshape(len(result), -1), rows)


def test_a_loop_run_that_diverges_notes_the_loop_first(control_loop):
    """Loop gain d1·kp = 2 (kp = 4): solved at T_0 by Newton, unstable when
    closed at the macro points. The note, which says why, comes before the
    DivergenceError, and its partial result carries it too."""
    with pytest.warns(tether.Note) as caught:
        with pytest.raises(tether.DivergenceError) as err:
            tether.run(control_loop, parameters={"controller.kp": 4.0})
    assert [str(w.message) for w in caught if w.category is tether.Note] == err.value.result.stats["notes"]
    assert len(err.value.result.stats["notes"]) == 1


def test_a_system_without_loops_has_no_notes(oscillator_toml):
    with warnings.catch_warnings():
        warnings.simplefilter("error", tether.Note)
        result = tether.run(oscillator_toml, stop=0.01)
    assert result.stats["notes"] == []
