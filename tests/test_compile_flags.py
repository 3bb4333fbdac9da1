"""``faster_compilation``: when it sets XLA's flag, when it must not, and that results do not
depend on it (the test-suite runs with it; a Python user may run without it)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from blurtrap import _config
from blurtrap._config import FAST_COMPILE_FLAG, faster_compilation

KNOWN = ((0, 5, 3), (0, 10, 2), (0, 10, 99))  # releases inside the range the code trusts


@pytest.fixture
def fresh(monkeypatch):
    """faster_compilation as in a process whose backends have not started, with $XLA_FLAGS
    and the opt-out unset and a jaxlib known to accept the flag; restored afterwards."""
    from jax._src import xla_bridge

    for name in ("XLA_FLAGS", _config.NO_FAST_COMPILE_ENV):
        monkeypatch.setenv(name, "")  # recorded, so that teardown restores the original
        monkeypatch.delenv(name)
    monkeypatch.setattr(xla_bridge, "backends_are_initialized", lambda: False)
    monkeypatch.setattr(_config, "_jaxlib_release", lambda: (0, 10, 2))
    return monkeypatch


def test_sets_the_flag_before_the_backends_start(fresh):
    assert faster_compilation()
    assert os.environ["XLA_FLAGS"] == FAST_COMPILE_FLAG
    assert faster_compilation()  # again: already there, not added twice
    assert os.environ["XLA_FLAGS"] == FAST_COMPILE_FLAG


def test_keeps_the_users_other_flags(fresh):
    fresh.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    assert faster_compilation()
    assert os.environ["XLA_FLAGS"].split() == ["--xla_force_host_platform_device_count=2",
                                               FAST_COMPILE_FLAG]


@pytest.mark.parametrize("flags, in_effect", [
    ("--xla_cpu_use_fusion_emitters=true", False),
    ("--xla_cpu_use_fusion_emitters=False", True),
    ("--xla_cpu_use_fusion_emitters=0", True),
    ("--xla_cpu_use_fusion_emitters", False),
    ("--xla_cpu_use_fusion_emitters=false --xla_cpu_use_fusion_emitters=true", False),
    ("--xla_cpu_use_fusion_emitters=true --xla_cpu_use_fusion_emitters=false", True),
])
def test_the_users_own_setting_wins(fresh, flags, in_effect):
    fresh.setenv("XLA_FLAGS", flags)
    assert faster_compilation() is in_effect  # the last value wins, as in XLA
    assert os.environ["XLA_FLAGS"] == flags  # never changed


def test_the_opt_out(fresh):
    fresh.setenv(_config.NO_FAST_COMPILE_ENV, "1")
    assert not faster_compilation()
    assert "XLA_FLAGS" not in os.environ
    fresh.setenv(_config.NO_FAST_COMPILE_ENV, "0")
    assert faster_compilation()


@pytest.mark.parametrize("release", [(0,), (0, 5, 0), (0, 5, 1), (0, 11, 0), (1, 0, 0)])
def test_a_jaxlib_outside_the_known_range_is_left_alone(fresh, release):
    # XLA aborts the whole process on a flag it does not know: never guess
    fresh.setattr(_config, "_jaxlib_release", lambda: release)
    assert not faster_compilation()
    assert "XLA_FLAGS" not in os.environ


@pytest.mark.parametrize("release", KNOWN)
def test_a_jaxlib_inside_the_known_range_gets_the_flag(fresh, release):
    fresh.setattr(_config, "_jaxlib_release", lambda: release)
    assert faster_compilation()


def test_not_after_the_backends_started(fresh):
    from jax._src import xla_bridge

    fresh.setattr(xla_bridge, "backends_are_initialized", lambda: True)
    assert not faster_compilation()  # too late: XLA has read its flags
    assert "XLA_FLAGS" not in os.environ


@pytest.mark.parametrize("text, release", [
    ("0.10.2", (0, 10, 2)), ("0.10.2.dev20261101", (0, 10, 2)), ("0.5.3rc1", (0, 5, 3)),
    ("0.10.2+cuda12", (0, 10, 2)), ("0.6", (0, 6)),
])
def test_the_release_is_read(monkeypatch, text, release):
    import importlib.metadata

    monkeypatch.setattr(importlib.metadata, "version", lambda name: text)
    assert _config._jaxlib_release() == release


def test_the_installed_release_is_read():
    import jaxlib.version

    expected = tuple(int(p) for p in jaxlib.version.__version__.split(".")[:3])
    assert _config._jaxlib_release() == expected


def test_xla_reads_flags_set_after_import_jax(tmp_path):
    """What faster_compilation relies on: $XLA_FLAGS set after ``import jax`` but before the
    first computation reaches XLA (here a dump folder that XLA fills)."""
    code = ("import os, sys, jax\n"
            f"os.environ['XLA_FLAGS'] = '--xla_dump_to={tmp_path}'\n"
            "print(jax.jit(lambda x: 2 * x)(1.0))")
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    assert any(tmp_path.iterdir())


_SCRIPT = r"""
import json, os, sys
import jax, numpy as np
import blurtrap as bt
from blurtrap._config import faster_compilation
on = faster_compilation() if sys.argv[1] == "on" else False
bt.enable_x64()
gamma = 6 * np.pi * 0.00093 * 1.53e-6
x = np.asarray(bt.simulate(5e-5, gamma, 1 / 1500, 1 / 1500, 4096, key=jax.random.key(3),
                           method="exact_frames", tracking_std=2e-9))[0]
rec = bt.Recording(x, frame_interval=1 / 1500, exposure=1 / 1500)
out = {"on": on, "flags": os.environ.get("XLA_FLAGS", ""), "x": x[:64].tolist()}
for lik in ("whittle", "exact"):
    r = bt.calibrate(rec, likelihood=lik)
    out[lik] = [r.params[p] for p in ("k", "gamma", "tracking_var")]
print(json.dumps(out))
"""


def _run(mode):
    env = {k: v for k, v in os.environ.items()
           if k not in ("XLA_FLAGS", _config.NO_FAST_COMPILE_ENV)}
    out = subprocess.run([sys.executable, "-c", _SCRIPT, mode], capture_output=True,
                         text=True, timeout=600, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_results_do_not_depend_on_the_flag():
    """Two fresh processes, XLA's defaults and the flag: the same frames and the same fits
    (to rounding; the two compilers may order floating-point operations differently)."""
    default, fast = _run("off"), _run("on")
    assert not default["on"] and FAST_COMPILE_FLAG not in default["flags"]
    assert fast["on"] == _config.fusion_emitters_option_known()
    np.testing.assert_allclose(fast["x"], default["x"], rtol=1e-12, atol=1e-22)
    for lik in ("whittle", "exact"):
        np.testing.assert_allclose(fast[lik], default[lik], rtol=1e-10, err_msg=lik)
    # and the fit is a fit, not two equal failures
    assert 2e-5 < default["exact"][0] < 2e-4


def test_the_command_line_runs_with_the_flag(tmp_path):
    """The CLI sets the flag itself (a process of its own, before its first computation) and
    still works end to end."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("XLA_FLAGS", _config.NO_FAST_COMPILE_ENV)}
    code = ("import os, sys\nfrom blurtrap.cli import main\n"
            f"rc = main(['simulate', '--k', '0.03', '--radius', '1.53', '--exposure-ms', '0.5', '--fps', '1500', "
            f"'--frames', '1024', '--seed', '1', '--out', {str(tmp_path / 'sim')!r}, '--json'])\n"
            "print(os.environ.get('XLA_FLAGS', ''))\nsys.exit(rc)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    assert (tmp_path / "sim" / "manifest.json").exists()
    if _config.fusion_emitters_option_known():
        assert out.stdout.strip().splitlines()[-1] == FAST_COMPILE_FLAG
