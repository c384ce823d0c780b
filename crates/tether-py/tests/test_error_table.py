"""docs/python.md's table of error classes says what Python raises: each
mistake below raises the class whose row names it."""

import re

import pytest

import tether


def _rows(root):
    """Class name → the text of its row in docs/python.md, "## Errors"."""
    text = (root / "docs" / "python.md").read_text()
    section = text.split("## Errors", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        m = re.match(r"\| `(\w+)`[^|]*\| (.*) \|$", line)
        if m:
            rows[m.group(1)] = m.group(2)
    return rows


def _system(tmp_path, oscillator_toml, old, new):
    text = oscillator_toml.read_text()
    assert old in text, old
    path = tmp_path / "system.toml"
    path.write_text(text.replace(old, new).replace(
        "../target/fmus/oscillator.fmu", str(oscillator_toml.parent.parent / "target/fmus/oscillator.fmu")))
    return path


# (what the table says, a change of examples/oscillator.toml, or a call)
CASES = [
    ("a misspelled variable name", ('position = "mass2.x - mass1.x"', 'position = "mass2.xx - mass1.x"')),
    ("an unknown instance", ('position = "mass2.x - mass1.x"', 'position = "mass3.x - mass1.x"')),
    ("a variable of the wrong kind", ('position = "mass2.x - mass1.x"', 'position = "mass2.F - mass1.x"')),
    ("units that do not fit", ('position = "mass2.x - mass1.x"', 'position = "mass2.x - mass1.v"')),
    ("a missing constraint level", ('velocity = "mass2.v - mass1.v"\n', "")),
    ("is not there", ("../target/fmus/oscillator.fmu", "../target/fmus/nowhere.fmu")),
    ("unknown method", {"method": "nonsense"}),
    ("a missing system file", "missing"),
]


@pytest.mark.parametrize("phrase,change", CASES, ids=[c[0] for c in CASES])
def test_the_error_table_names_the_class_python_raises(root, tmp_path, oscillator_toml, phrase, change):
    rows = _rows(root)
    documented = [name for name, row in rows.items() if phrase in row]
    assert len(documented) == 1, f"{phrase!r} in rows {documented}"
    if change == "missing":
        call = lambda: tether.run(tmp_path / "nope.toml")
    elif isinstance(change, dict):
        call = lambda: tether.run(oscillator_toml, **change)
    else:
        old, new = change
        if "nowhere" in new:
            text = oscillator_toml.read_text().replace(old, str(tmp_path / "nowhere.fmu"))
            path = tmp_path / "system.toml"
            path.write_text(text)
        else:
            path = _system(tmp_path, oscillator_toml, old, new)
        call = lambda: tether.run(path)
    with pytest.raises(tether.TetherError) as err:
        call()
    assert type(err.value).__name__ == documented[0], f"{phrase}: {err.value}"
