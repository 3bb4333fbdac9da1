"""calibrate_batch on records where eps^2 runs to its bound: the items the first vmapped
Newton pass leaves unconverged continued together (now) vs refitted one by one (before).

    python benchmarks/bench_batch_bound.py [--batch 2000] [--sweep 65536]

Same process, same records, on the default JAX device: ``_batch._CONTINUE_PASSES = 0`` is the
previous behaviour (every unconverged item refitted alone by the host-driven Newton-then-BFGS
fit of ``calibrate``), the default continues them in chunks with the batch's own compiled fit.
Records: blurtrap's exact frame sampler, 4096 frames, camera 1500 fps, W = 0.1 dt (eps^2 at its
bound in ~10 % of the records) and W = dt, eps = 2 nm, k = 0.05 pN/nm. Also times a streamed
``bt.sweep`` (simulate + calibrate_batch) of ``--sweep`` trajectories of 1024 frames. Prints a
markdown table with the wall times (one call after a compiling call) and their ratio.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time

import jax
import numpy as np

import blurtrap as bt
from blurtrap.inference import _batch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_peers import machine_info, machine_line  # noqa: E402

bt.enable_x64()
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
K, DT, EPS = 5e-5, 1.0 / 1500.0, 2e-9


def frames(b, w, seed):
    return np.asarray(bt.simulate(K, GAMMA, w, DT, 4096, n_traces=b, tracking_std=EPS,
                                  method="exact_frames", key=jax.random.key(seed)))


def timed(fn, repeat=1):
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return min(ts), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=2000)
    ap.add_argument("--sweep", type=int, default=65536)
    a = ap.parse_args(argv)
    print(f"{machine_line(machine_info())}; device {jax.devices()[0]}")
    print("| records | passes | wall [s] | records/s | items refitted alone | at bound | "
          "ratio before/now |")
    print("|---|---|---|---|---|---|---|")
    for label, w in (("W = 0.1 dt", 0.1 * DT), ("W = dt", DT)):
        y = frames(a.batch, w, seed=3)
        row = {}
        for passes in (0, _batch._CONTINUE_PASSES):
            alone = []
            real = _batch._refit_alone
            _batch._refit_alone = lambda i, *r, real=real: (alone.append(i), real(i, *r))
            old, _batch._CONTINUE_PASSES = _batch._CONTINUE_PASSES, passes
            try:
                t, r = timed(lambda y=y: bt.calibrate_batch(y, frame_interval=DT, exposure=w))
            finally:
                _batch._refit_alone, _batch._CONTINUE_PASSES = real, old
            row[passes] = (t, r, len(alone) // 2)
        t0, t1 = row[0][0], row[_batch._CONTINUE_PASSES][0]
        same = np.allclose(row[0][1].k, row[_batch._CONTINUE_PASSES][1].k, rtol=1e-8)
        for passes, (t, r, n_alone) in row.items():
            print(f"| {a.batch} x 4096, {label} | {passes} | {t:.2f} | {a.batch / t:.3g} | "
                  f"{n_alone} | {int(r.at_bound.sum())} | "
                  f"{(t0 / t1) if passes else 1.0:.2f} (k equal: {same}) |", flush=True)
    chunk = min(a.sweep, 16384)
    grid = {"k": K, "gamma": GAMMA, "exposure": DT, "frame_interval": DT, "tracking_std": EPS}
    bt.sweep(grid, n_frames=1024, n_traces=chunk, chunk_traces=chunk, key=jax.random.key(5),
             progress=False)
    t0 = time.perf_counter()
    bt.sweep(grid, n_frames=1024, n_traces=a.sweep, chunk_traces=chunk, key=jax.random.key(6),
             progress=False)
    t = time.perf_counter() - t0
    print(f"sweep {a.sweep} traces x 1024 frames (chunks of {chunk}): {t:.2f} s, "
          f"{a.sweep / t:.3g} fits/s")


if __name__ == "__main__":
    main()
