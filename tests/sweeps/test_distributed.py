"""The same sweep on 2 forced host devices and on 2 jax.distributed processes (localhost,
CPU collectives through gloo) equals the single-device, single-process run bit for bit."""

import os
import pathlib
import socket
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _sweep_case import run  # noqa: E402

SCRIPT = str(pathlib.Path(__file__).with_name("_sweep_case.py"))
ROOT = str(pathlib.Path(__file__).resolve().parents[2])


@pytest.fixture(scope="module")
def single():
    return run()


def _env(devices=1):
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "")
                        + f" --xla_force_host_platform_device_count={devices}")
    env["JAX_PLATFORMS"] = "cpu"
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("BLURTRAP_TEST_CACHE_DIR",
                   os.path.join(ROOT, ".pytest_cache", "jax"))
    return env


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _assert_bitwise(path, single):
    with np.load(path) as z:
        assert set(z.files) == set(single.data)
        for k in z.files:
            assert np.array_equal(z[k], single.data[k], equal_nan=True), k


@pytest.mark.slow
def test_two_local_devices_equal_one(single, tmp_path):
    out = tmp_path / "dev2.npz"
    res = subprocess.run([sys.executable, SCRIPT, str(out)], capture_output=True, text=True,
                         env=_env(2), timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "devices 2 processes 1" in res.stdout
    _assert_bitwise(out, single)


@pytest.mark.slow
def test_two_processes_equal_one(single, tmp_path):
    port = str(_free_port())
    procs = [subprocess.Popen([sys.executable, SCRIPT, str(tmp_path / f"p{i}.npz"), str(i),
                               "2", port], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=_env(1)) for i in range(2)]
    outs = []
    try:
        for p in procs:
            outs.append(p.communicate(timeout=900))
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    for p, (stdout, stderr) in zip(procs, outs):
        assert p.returncode == 0, stderr[-3000:]
        assert "devices 1 processes 2" in stdout
    for i in range(2):  # every process returns the whole, gathered result
        _assert_bitwise(tmp_path / f"p{i}.npz", single)
