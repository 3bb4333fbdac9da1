"""Whittle vs exact likelihood when the relaxation time is not short compared with the record.

    python benchmarks/study_whittle_leakage.py [--seeds 8] [--ratios 30 100 300 1000 3000]
                                               [--frames 65536]

8 seeds per T/tau (record length T over relaxation time tau); prints the mean
z = (estimate - truth)/SE of k and gamma for both likelihoods on the same data.
Results: benchmarks/RESULTS_calibration.md.
"""

import argparse

import jax
import numpy as np

import blurtrap as bt

GAMMA = 6 * np.pi * 9.5e-4 * 0.765e-6
DT, N = 1 / 1500, 65536


def sim(k, seed, n=N):
    x = bt.simulate(k, GAMMA, DT, DT, n, key=jax.random.key(seed), method="exact_frames",
                    tracking_std=2e-9)
    return bt.Recording(np.asarray(x).reshape(-1), frame_interval=DT, exposure=DT)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=8, help="seeds per T/tau")
    ap.add_argument("--ratios", type=float, nargs="+", default=[30, 100, 300, 1000, 3000],
                    help="record length over relaxation time, T/tau")
    ap.add_argument("--frames", type=int, default=N, help="frames per record")
    a = ap.parse_args(argv)
    bt.enable_x64()
    n = a.frames
    T = n * DT
    for ratio in a.ratios:
        k = GAMMA / (T / ratio)
        res = {"whittle": [], "exact": []}
        for s in range(a.seeds):
            rec = sim(k, s, n)
            for lk in res:
                try:
                    r = bt.calibrate(rec, method="likelihood", likelihood=lk)
                    res[lk].append(((r.k - k) / r.k_err, (r.gamma - GAMMA) / r.gamma_err,
                                    r.k / k - 1, r.gamma / GAMMA - 1))
                except bt.FitError:
                    res[lk].append((np.nan,) * 4)
        for lk, v in res.items():
            v = np.array(v)
            m = np.nanmean(v, axis=0)
            print(f"T/tau={ratio:g} index={np.sqrt(n) / ratio:.3g} {lk}: mean z_k={m[0]:+.2f} "
                  f"z_g={m[1]:+.2f} rel k={m[2]:+.3f} gamma={m[3]:+.3f} "
                  f"nfail={int(np.isnan(v[:, 0]).sum())}", flush=True)


if __name__ == "__main__":
    main()
