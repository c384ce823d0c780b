"""Every Python block of README.md and docs/python.md runs as written, in
order, each file's blocks in one namespace (a block may use the names of the
ones before it), in a scratch folder where `examples`, `target`, `docs` and
`tests` (the vendored Reference FMUs) are the repository's. A block that cannot run here has a visible
`(Not run in tests: reason.)` line before it (crates/tether-cli/tests/
docs_blocks.rs runs the shell and TOML blocks)."""

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
MARKER = re.compile(r"^\(Not run in tests: (.+)\.\)$")


def python_blocks(path):
    lines = path.read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].startswith("```python"):
            j = i + 1
            while not lines[j].startswith("```"):
                j += 1
            skipped = i > 0 and MARKER.match(lines[i - 1].strip())
            blocks.append((i + 1, "\n".join(lines[i + 1:j]), skipped))
            i = j
        i += 1
    return blocks


@pytest.mark.parametrize("doc", ["README.md", "docs/python.md"])
def test_every_python_block_runs_as_written(doc, tmp_path, monkeypatch):
    for name in ("examples", "target", "docs", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__docs__"}
    ran = 0
    for line, code, skipped in python_blocks(ROOT / doc):
        if skipped:
            assert skipped.group(1).strip(), f"{doc}:{line}: say why it is not run"
            continue
        try:
            exec(compile(code, f"{doc}:{line}", "exec"), namespace)
        except Exception as e:  # the block and its error, in one line
            pytest.fail(f"{doc}:{line}: {type(e).__name__}: {e}")
        ran += 1
    assert ran >= 1
