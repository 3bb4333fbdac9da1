"""The small sweep the tests run, in this process or in subprocesses (devices, processes).

Run as a script: ``python _sweep_case.py OUT.npz [PROCESS_ID NUM_PROCESSES PORT]`` writes the
sweep's statistics to OUT.npz; with a process id it first joins a ``jax.distributed`` run on
127.0.0.1:PORT.
"""

import os
import sys
from typing import Any

import numpy as np

K, TAU = 5e-5, 0.537e-3
DT = TAU / 2
GRID = {"k": [K, 2 * K, 4 * K], "gamma": K * TAU, "exposure": [0.25 * DT, DT],
        "frame_interval": DT, "tracking_std": 0.5e-9}
KW: dict[str, Any] = dict(n_frames=2048, n_traces=16, chunk_traces=8,
                          models=("naive", "standard"), methods=("whittle", "psd:16"),
                          progress=False, gof_threshold=0.0)
#: the blocks of the blocked-PSD method per k of GRID: one count (one compiled shape per model;
#: the per-cell default of "psd" is tested on its own in test_sweep.py)
PSD_BLOCKS = (16, 16, 16)


def run(**extra):
    import jax

    import blurtrap as bt

    return bt.sweep(GRID, key=jax.random.key(11), **{**KW, **extra})


def save(result, path):
    arrays: dict[str, Any] = {k: np.asarray(v) for k, v in result.data.items()}
    np.savez(path, **arrays)


if __name__ == "__main__":
    import jax

    if len(sys.argv) > 2:
        pid, n, port = (int(a) for a in sys.argv[2:5])
        jax.distributed.initialize(coordinator_address=f"127.0.0.1:{port}", num_processes=n,
                                   process_id=pid)
    import blurtrap as bt

    bt.enable_x64()
    bt.enable_compilation_cache(os.environ["BLURTRAP_TEST_CACHE_DIR"])
    res = run()
    assert res.attrs["processes"] == jax.process_count()
    save(res, sys.argv[1])
    print("devices", len(jax.local_devices()), "processes", jax.process_count())
