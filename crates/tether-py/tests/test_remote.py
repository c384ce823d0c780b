"""Instances on a remote host (docs/remote.md) from Python: a real `tether
host` process on 127.0.0.1, the System builder's host keywords, results bit
for bit as in process."""
import os
import re
import secrets
import subprocess

import numpy as np

import tether
from conftest import same_bits

MASS = {"c": 1000.0, "d": 10.0, "x0": 0.0, "v0": 100.0}
LINK = dict(position="mass2.x - mass1.x", velocity="mass2.v - mass1.v",
            acceleration="mass2.a - mass1.a", drives="mass1.F - mass2.F")


def pair(oscillator_fmu, **mass2):
    return (
        tether.System("two-mass oscillator")
        .experiment(stop=0.2, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .add_instance("mass1", oscillator_fmu, {"m": 1.0, **MASS})
        .add_instance("mass2", oscillator_fmu, {"m": 2.0, **MASS}, **mass2)
        .add_constraint("link", **LINK, initial="consistent")
    )


def token_file(path):
    """A token file only its owner may read."""
    path.write_text(secrets.token_hex(32))
    os.chmod(path, 0o600)
    return path


def start_host(tether_bin, token):
    """A `tether host` on a free port of 127.0.0.1: the process and its address."""
    host = subprocess.Popen(
        [str(tether_bin), "host", "--listen", "127.0.0.1:0", "--token-file", str(token)],
        stderr=subprocess.PIPE, text=True)
    line = host.stderr.readline()
    found = re.search(r"listening on (127\.0\.0\.1:\d+)", line)
    if not found:
        host.kill()
        raise AssertionError(line)
    return host, f"tcp://{found.group(1)}"


def test_an_instance_on_a_remote_host_runs_bit_for_bit(tmp_path, tether_bin, oscillator_fmu):
    token = token_file(tmp_path / "host.token")
    host, address = start_host(tether_bin, token)
    try:
        remote = pair(oscillator_fmu, host=address, token_file=token)
        assert 'host = "tcp://127.0.0.1:' in remote.to_toml()
        a = tether.run(pair(oscillator_fmu))
        b = tether.run(remote)
        assert a.columns == b.columns
        assert same_bits(a.to_numpy().view(np.float64), b.to_numpy().view(np.float64))
    finally:
        host.kill()
        host.wait()


def test_a_wrong_token_is_one_clear_error(tmp_path, tether_bin, oscillator_fmu):
    host, address = start_host(tether_bin, token_file(tmp_path / "host.token"))
    try:
        system = pair(oscillator_fmu, host=address, token_file=token_file(tmp_path / "wrong.token"))
        try:
            tether.run(system)
        except tether.TetherError as e:
            assert "mass2" in str(e) and "token" in str(e) and "\n" not in str(e), str(e)
        else:
            raise AssertionError("a wrong token ran")
    finally:
        host.kill()
        host.wait()
