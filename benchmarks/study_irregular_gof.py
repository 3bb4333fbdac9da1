"""The goodness of fit of fits at irregular frame times (dropped frames): its p-values on
correct data, and its power against an effect the model lacks.

Frames: a regular exact sequence by circulant embedding of the frame autocovariance (numpy,
not blurtrap's simulator) with a fraction of frames removed at random; the time stamps are
the kept frames' times. Camera W = dt at 1500 fps, k = 0.02 pN/nm, gamma = 0.01 pN s/um
(tau = 0.5 ms), eps = 2 nm.

    python benchmarks/study_irregular_gof.py --n 100 --frames 8192
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from study_boundary import CirculantSampler, autocovariance

import blurtrap as bt

K, GAMMA, DT, EPS2 = 2e-5, 1e-8, 1 / 1500, 4e-18


def recording(seed, n, frac, line=0.0):
    rng = np.random.default_rng(seed)
    total = int(n / (1 - frac)) + 200
    y = CirculantSampler(autocovariance(K, GAMMA, DT, DT, EPS2, total)).draw(rng, 1)[0]
    keep = rng.random(total) >= frac
    t = (np.arange(total) * DT)[keep][:n]
    y = y[keep][:n] + line * np.sin(2 * np.pi * 120.0 * t)
    return bt.Recording(y, frame_interval=DT, exposure=DT, temperature=295.0, times=t,
                        allow_irregular=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--frames", type=int, default=8192)
    a = ap.parse_args(argv)
    bt.enable_x64()
    t0 = time.time()
    print("| dropped | injected | datasets | p < 0.05 | p < 0.01 | p < 1e-3 | mean p | k z mean, SD |")
    print("|---|---|---|---|---|---|---|---|")
    for frac, line, n in ((0.1, 0.0, a.n), (0.02, 0.0, a.n), (0.1, 3e-9, a.n // 5),
                          (0.1, 6e-9, a.n // 5)):
        p, z = [], []
        for s in range(n):
            r = bt.calibrate(recording(1000 + s, a.frames, frac, line))
            p.append(r.gof["p_value"])
            z.append((r.k - K) / r.k_err)
        p, z = np.array(p), np.array(z)
        print(f"| {frac:.0%} | {'line ' + format(line * 1e9, 'g') + ' nm' if line else 'none'} | {n} "
              f"| {np.mean(p < 0.05):.2f} | {np.mean(p < 0.01):.2f} | {np.mean(p < 1e-3):.2f} "
              f"| {p.mean():.2f} | {z.mean():+.2f}, {z.std():.2f} |", flush=True)
    print(f"({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
