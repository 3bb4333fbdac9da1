"""Joint fits whose recordings differ in tracking noise: the refit with one eps^2 per
recording, how often its note appears, and how far the shared-eps^2 fit and the refit are
from the truth.

Generator independent of blurtrap: exact Ornstein-Uhlenbeck substeps in numpy (16 substeps
per exposure W = dt/2, the frame the mean of the positions at the substep midpoints), plus
Gaussian tracking noise. Four laser powers 0.25, 0.5, 1, 2 W, k = c P (c = 0.05 pN/nm/W),
gamma = 9.4e-9 N s/m (0.0094 pN s/um), 2000 fps, 16 384 frames each, fitted with
k='linear_power' (Whittle). Cases: ``photon`` (eps = 2 nm / sqrt(P/W): 4, 2.8, 2, 1.4 nm, an
independent pass's case), ``strong`` (3 nm / sqrt(P/W)) and ``equal`` (2.8 nm on every
recording: the false-alarm control).

Run: ``python benchmarks/study_noise_pooling.py [--n 30]``.
"""

from __future__ import annotations

import argparse
import math
import re
import time

import numpy as np
from scipy.signal import lfilter

import blurtrap as bt

KT = 1.380649e-23 * 295.0
C, GAMMA, DT, N = 5e-5, 9.4e-9, 1 / 2000, 16384
POWERS = np.array([0.25, 0.5, 1.0, 2.0])
CASES = {"photon": 2e-9 / np.sqrt(POWERS), "strong": 3e-9 / np.sqrt(POWERS),
         "equal": np.full(4, 2e-9 / math.sqrt(0.5))}


def frames(k, eps, rng, m=16):
    """Frames averaged over W = dt/2 from exact OU substeps h = W/m (2m substeps a frame)."""
    tau, var, h = GAMMA / k, KT / k, DT / 2 / m
    a = math.exp(-h / tau)
    e = rng.standard_normal(N * 2 * m) * math.sqrt(var * (1 - a * a))
    e[0] = rng.standard_normal() * math.sqrt(var)
    x = lfilter([1.0], [1.0, -a], e).reshape(N, 2 * m)[:, :m].mean(axis=1)
    return x + eps * rng.standard_normal(N)


def one(case, seed):
    rng = np.random.default_rng(seed)
    recs = [bt.Recording(frames(C * p, e, rng), frame_interval=DT, exposure=DT / 2, temperature=295.0,
                         laser_power=float(p)) for p, e in zip(POWERS, CASES[case])]
    res = bt.calibrate(recs, k="linear_power", likelihood="whittle")
    se = np.sqrt(np.diag(res.covariance))
    z = ((res.values[0] - C) / se[0], (res.values[1] - GAMMA) / se[1])
    note = next((n for n in res.notes if n.startswith("the recordings' tracking noise differs")), None)
    refit = None
    if note:
        c = float(re.search(r"c = ([\d.e+-]+) pN/nm/W", note)[1]) * 1e-3
        g = float(re.search(r"gamma = ([\d.e+-]+) pN s/um", note)[1]) * 1e-6
        refit = ((c - C) / se[0], (g - GAMMA) / se[1])
    return z, note is not None, refit


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=30)
    n = ap.parse_args().n
    print("| case | datasets | mean z(c), z(gamma) of the joint fit | note | refit - truth in joint SE "
          "(c, gamma; mean over noted) |")
    print("|---|---|---|---|---|")
    for case in CASES:
        t0 = time.perf_counter()
        rows = [one(case, 1000 * (i + 1) + len(case)) for i in range(n)]
        zc = np.mean([r[0][0] for r in rows])
        zg = np.mean([r[0][1] for r in rows])
        fired = sum(r[1] for r in rows)
        ref = [r[2] for r in rows if r[2] is not None]
        shown = (f"{np.mean([r[0] for r in ref]):+.2f}, {np.mean([r[1] for r in ref]):+.2f}" if ref else "-")
        print(f"| {case} | {n} | {zc:+.2f}, {zg:+.2f} | {fired}/{n} | {shown} |  ({time.perf_counter() - t0:.0f} s)",
              flush=True)


if __name__ == "__main__":
    main()
