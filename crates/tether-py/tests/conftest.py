"""Shared fixtures: the repository, its FMUs (``cargo xtask fmus``) and the
``tether`` binary (``cargo build --release -p tether-cli``, or $TETHER_BIN)."""

import csv
import importlib
import os
import platform
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]


def need_tool(module: str):
    """The third-party `module` a test runs against (fmpy, dask, plotly,
    pandas): without it the test fails on CI (`CI` set: .ci/run installs every
    tool) and elsewhere is skipped, saying why."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        why = f"{module} is not installed ({e}); .ci/run installs it"
        if os.environ.get("CI"):
            pytest.fail(f"{why}: needed on CI")
        pytest.skip(why)


def _need(path: Path, how: str) -> Path:
    if not path.exists():
        pytest.fail(f"{path} is missing: {how}")
    return path


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def oscillator_fmu() -> Path:
    return _need(ROOT / "target" / "fmus" / "oscillator.fmu", "run `cargo xtask fmus`")


@pytest.fixture(scope="session")
def quirks_fmu() -> Path:
    return _need(ROOT / "target" / "fmus" / "quirks.fmu", "run `cargo xtask fmus`")


@pytest.fixture(scope="session")
def fmi3_reference():
    """The FMI 3.0 Reference FMU `model` (third-party FMUs vendored in
    tests/fixtures/reference-fmus/fmi3, as the CLI tests use them). Their binaries
    are built for x86_64 Linux: elsewhere the test is skipped, saying why, and
    fails on CI."""

    def fmu(model: str) -> Path:
        if (platform.system(), platform.machine()) != ("Linux", "x86_64"):
            why = (f"reference-fmus/fmi3/{model}.fmu: its binaries are built for x86_64 "
                   f"Linux and this host is {platform.machine()} {platform.system()}")
            if os.environ.get("CI"):
                pytest.fail(f"{why}: needed on CI")
            pytest.skip(why)
        return _need(ROOT / "tests" / "fixtures" / "reference-fmus" / "fmi3" / f"{model}.fmu",
                     "it is vendored in the repository: is the checkout complete?")

    return fmu


@pytest.fixture(scope="session")
def oscillator_toml(oscillator_fmu) -> Path:
    return ROOT / "examples" / "oscillator.toml"


@pytest.fixture(scope="session")
def tether_bin() -> Path:
    given = os.environ.get("TETHER_BIN")
    path = Path(given) if given else ROOT / "target" / "release" / "tether"
    return _need(path, "run `cargo build --release -p tether-cli` or set TETHER_BIN")


def read_csv(path: Path):
    """(columns, rows as float64 array, trailer comment or None) of a tether CSV."""
    lines = path.read_text().splitlines()
    trailer = None
    if lines and lines[-1].startswith("#"):
        trailer = lines.pop()
    table = list(csv.reader(lines))
    header = table[0]
    rows = np.array([[float(x) for x in row] for row in table[1:]], dtype=np.float64)
    return header, rows.reshape(len(table) - 1, len(header)), trailer


def cli(tether_bin: Path, *args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(tether_bin), *args], capture_output=True, text=True, cwd=cwd, check=False
    )


def error_line(proc: subprocess.CompletedProcess) -> str:
    """The CLI's one-line error without its `error: ` prefix."""
    lines = [l for l in proc.stderr.splitlines() if l.startswith("error: ")]
    assert lines, proc.stderr
    return lines[-1][len("error: ") :]


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint64), b.view(np.uint64)))
