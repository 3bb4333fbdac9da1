"""Sharding of the traces axis across devices (two CPU devices forced with XLA_FLAGS).

The device count of a JAX process is fixed when its backend starts, so the check runs in a fresh
subprocess with ``XLA_FLAGS=--xla_force_host_platform_device_count=2``.
"""

import json
import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import json
    import os

    import jax
    import numpy as np
    import blurtrap
    from blurtrap.simulate import TimingJitter, simulate

    blurtrap.enable_x64()
    blurtrap.enable_compilation_cache(os.environ["BLURTRAP_TEST_CACHE_DIR"])
    K, TAU = 5e-5, 0.537e-3
    out = {"devices": len(jax.devices()), "cases": []}
    cases = [
        ("exact", dict(substeps=8, chunk_frames=5)),
        ("exact_frames", dict(injections=(TimingJitter(0.05 * TAU),))),  # segment law
        ("exact_frames", dict(chunk_frames=5)),  # innovations form
    ]
    for method, extra in cases:
        kw = dict(key=jax.random.key(3), n_traces=8, method=method, **extra)
        args = (np.array([K, 2 * K]), K * TAU, 0.5 * TAU, TAU, 12)
        auto = simulate(*args, **kw)  # shard="auto": both devices
        sharded = simulate(*args, shard=True, **kw)
        plain = simulate(*args, shard=False, **kw)
        a, s, p = (np.asarray(v) for v in (auto, sharded, plain))
        out["cases"].append({
            "method": method,
            "shape": list(a.shape),
            "max_abs_diff": float(np.max(np.abs(s - p))),
            "max_abs": float(np.max(np.abs(p))),
            "auto_equals_sharded": bool(np.array_equal(a, s)),
            "devices_used": len(auto.sharding.device_set),
            "plain_devices_used": len(plain.sharding.device_set),
            "shard_slices": sorted(
                [sh.index[1].start, sh.index[1].stop] for sh in auto.addressable_shards
            ),
        })
    try:
        simulate(K, K * TAU, 0.5 * TAU, TAU, 3, key=jax.random.key(0), n_traces=3, shard=True)
        out["odd_error"] = None
    except ValueError as err:
        out["odd_error"] = str(err)
    print(json.dumps(out))
    """
)


def test_sharded_call_equals_unsharded_on_two_devices():
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2")
    env["JAX_PLATFORMS"] = "cpu"
    env.setdefault("BLURTRAP_TEST_CACHE_DIR",  # the suite's compile cache (tests/conftest.py)
                   os.path.join(os.path.dirname(__file__), "..", "..", ".pytest_cache", "jax"))
    res = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["devices"] == 2
    assert len(out["cases"]) == 3
    for case in out["cases"]:
        assert case["shape"] == [2, 8, 12], case
        # the same numbers (same counters per trajectory), to float tolerance
        assert case["max_abs_diff"] <= 1e-13 * case["max_abs"], case
        assert case["auto_equals_sharded"], case
        # the traces axis is split over both devices; shard=False stays on one
        assert case["devices_used"] == 2, case
        assert case["shard_slices"] == [[0, 4], [4, 8]], case
        assert case["plain_devices_used"] == 1, case
    assert out["odd_error"] is not None and "multiple of the 2 devices" in out["odd_error"]
