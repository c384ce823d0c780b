"""An in-process FMU that ends the process from inside a call (the faults FMU,
fmus/faults: mode 3 calls exit(0), mode 4 exit(3), mode 2 abort() inside
fmi2DoStep at t = 0.5, as mass 2 of the oscillator example): Python never
ends silently. The process ends with a non-zero status and one line naming
the instance, the call and t; the statements after the run do not run; no
extraction folder is left. Isolated, the same fault is an exception."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import tether
from conftest import ROOT, _need

LINE = ("error: the Python process ends: FMU instance 'mass2' called {called} inside "
        "fmi2DoStep at t=0.5 (an in-process FMU shares Python's process; with "
        "isolation = \"process\" this is an exception)")


@pytest.fixture(scope="session")
def faults_fmu() -> Path:
    return _need(ROOT / "target" / "fmus" / "faults.fmu", "run `cargo xtask fmus`")


def faults_system(tmp_path: Path, faults_fmu: Path, mode: int, isolate: bool = False) -> Path:
    """The oscillator example with mass 2 replaced by the faults FMU in `mode`."""
    text = (ROOT / "examples" / "oscillator.toml").read_text()
    osc = (ROOT / "target" / "fmus" / "oscillator.fmu").as_posix()
    mass2 = 'fmu = "../target/fmus/oscillator.fmu"\nparameters = { m = 2.0'
    assert mass2 in text
    text = text.replace(mass2, f'fmu = "{faults_fmu.as_posix()}"\nparameters = {{ mode = {mode}, m = 2.0')
    text = text.replace('"../target/fmus/oscillator.fmu"', f'"{osc}"')
    if isolate:
        text = text.replace('name = "mass2"\n', 'name = "mass2"\nisolation = "process"\n')
    path = tmp_path / f"faults{mode}.toml"
    path.write_text(text)
    return path


def run_in_python(tmp_path: Path, system: Path) -> subprocess.CompletedProcess:
    """`tether.run(system)` in a fresh Python with its own TMPDIR; prints
    `after` if the statement after the run is reached, and `atexit` from an
    atexit handler."""
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    code = (
        "import atexit, sys, tether\n"
        "atexit.register(lambda: print('atexit', flush=True))\n"
        f"tether.run({str(system)!r})\n"
        "print('after', flush=True)\n"
    )
    env = dict(os.environ, TMPDIR=str(tmp))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=300, check=False)


@pytest.mark.parametrize("mode,called", [(3, "exit(0)"), (4, "exit(3)")])
def test_exit_inside_an_fmu_ends_python_with_status_1(tmp_path, faults_fmu, mode, called):
    proc = run_in_python(tmp_path, faults_system(tmp_path, faults_fmu, mode))
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.splitlines()[-1] == LINE.format(called=called)
    assert "after" not in proc.stdout
    assert list((tmp_path / "tmp").iterdir()) == []


def test_abort_inside_an_fmu_ends_python_by_sigabrt(tmp_path, faults_fmu):
    proc = run_in_python(tmp_path, faults_system(tmp_path, faults_fmu, 2))
    assert proc.returncode == -signal.SIGABRT, proc.stderr
    assert LINE.format(called="abort()") in proc.stderr.splitlines()
    assert "after" not in proc.stdout
    assert list((tmp_path / "tmp").iterdir()) == []


def test_a_normal_exit_of_python_is_left_alone(tmp_path, faults_fmu):
    """Mode 0: the run completes, Python goes on and exits 0 as it would."""
    proc = run_in_python(tmp_path, faults_system(tmp_path, faults_fmu, 0))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["after", "atexit"]
    assert proc.stderr == ""


def test_exit_of_an_isolated_fmu_is_an_exception(tmp_path, faults_fmu):
    system = faults_system(tmp_path, faults_fmu, 3, isolate=True)
    with pytest.raises(tether.FmuError, match="its host process exited with code 0 during fmi2DoStep at t=0.5") as err:
        tether.run(system)
    partial = err.value.result
    assert partial is not None and partial.time[-1] == 0.5


def test_exit_in_a_forked_worker_is_not_silent(tmp_path, faults_fmu):
    """A child of os.fork() (as a multiprocessing pool makes) is a Python
    program of its own: the FMU's exit(0) there ends it with status 1 and the
    line too."""
    system = faults_system(tmp_path, faults_fmu, 3)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    code = (
        "import os, sys, tether\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        f"    tether.run({str(system)!r})\n"
        "    os._exit(7)\n"
        "_, status = os.waitpid(pid, 0)\n"
        "print(os.waitstatus_to_exitcode(status), flush=True)\n"
    )
    env = dict(os.environ, TMPDIR=str(tmp))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "1", proc.stderr
    assert proc.stderr.splitlines()[-1] == LINE.format(called="exit(0)")
    assert list(tmp.iterdir()) == []
