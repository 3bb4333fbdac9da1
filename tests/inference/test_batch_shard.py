"""calibrate_batch over several local devices (two CPU devices forced with XLA_FLAGS, in a
fresh subprocess: the device count is fixed when the backend starts) equals the one-device
run item for item (estimates and errors bit for bit, goodness of fit to rounding), and its
progress bar (tqdm) advances per chunk."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import blurtrap

SCRIPT = textwrap.dedent(
    """
    import json, os
    import jax
    import numpy as np
    import blurtrap
    from blurtrap.inference import _batch

    blurtrap.enable_x64()
    blurtrap.enable_compilation_cache(os.environ["BLURTRAP_TEST_CACHE_DIR"])
    rng = np.random.default_rng(4)
    rho, n = 0.4, 2048
    y = np.zeros((5, n))  # AR(1) rows with white noise, one row NaN (checked, not fitted)
    e = rng.normal(size=(5, n)) * 2e-8
    for i in range(1, n):
        y[:, i] = rho * y[:, i - 1] + e[:, i]
    y += rng.normal(size=y.shape) * 3e-9
    y[3, 100] = np.nan
    kw = dict(frame_interval=1e-3, exposure=1e-3)
    mesh = _batch._batch_mesh("auto")
    placed = _batch._rows_on(mesh)(np.zeros((4, 3)))
    one = blurtrap.calibrate_batch(y, shard=False, **kw)
    two = blurtrap.calibrate_batch(y, **kw)
    out = {"devices": len(jax.devices()), "mesh": None if mesh is None else mesh.size,
           "placed_on": len(placed.sharding.device_set),
           "status": [list(one.status), list(two.status)]}
    for name in ("k", "k_err", "gamma", "gamma_err", "tracking_var", "gof_p"):
        a, b = getattr(one, name), getattr(two, name)
        out[name] = bool(np.array_equal(a, b, equal_nan=True))
        out[name + "_rel"] = float(np.nanmax(np.abs(a - b) / np.abs(a)))
    print(json.dumps(out))
    """
)


def test_rows_split_over_two_devices_give_the_one_device_results():
    env = dict(os.environ)
    env["XLA_FLAGS"] = env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env["JAX_PLATFORMS"] = "cpu"
    env.setdefault("BLURTRAP_TEST_CACHE_DIR",
                   os.path.join(os.path.dirname(__file__), "..", "..", ".pytest_cache", "jax"))
    res = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["devices"] == 2 and out["mesh"] == 2 and out["placed_on"] == 2
    assert out["status"][0] == out["status"][1]
    assert out["status"][0][3].startswith("invalid") and out["status"][0].count("ok") == 4
    for name in ("k", "k_err", "gamma", "gamma_err", "tracking_var"):
        assert out[name], (name, out[name + "_rel"])  # the fits bit for bit
    assert out["gof_p_rel"] < 1e-12  # the goodness-of-fit sums to rounding (measured 9e-15)


def test_one_device_is_no_mesh_and_bad_shard_is_named():
    from blurtrap.inference import _batch

    assert _batch._batch_mesh(True) is None or len(_batch.jax.local_devices()) > 1
    assert _batch._batch_mesh(False) is None and _batch._batch_mesh(np.False_) is None
    for bad in ("yes", 1, None):
        with pytest.raises(ValueError, match="shard must be 'auto', True or False"):
            blurtrap.calibrate_batch(np.zeros((2, 64)), frame_interval=1e-3, exposure=1e-3,
                                     shard=bad)


def test_progress_bar_advances_per_chunk(capsys, monkeypatch):
    from blurtrap.inference import _batch

    monkeypatch.setattr(_batch, "_CHUNK", 4)
    rng = np.random.default_rng(1)
    y = rng.normal(size=(10, 512)) * 1e-8
    for i in range(1, 512):
        y[:, i] += 0.5 * y[:, i - 1]
    blurtrap.calibrate_batch(y, frame_interval=1e-3, exposure=1e-3, progress=True,
                             shard=False)  # 3 chunks of 4 rows on one device
    err = capsys.readouterr().err
    assert "calibrate_batch" in err and all(f"| {i}/3 [" in err for i in range(4)), err
    blurtrap.calibrate_batch(y, frame_interval=1e-3, exposure=1e-3)
    assert capsys.readouterr().err == ""
