"""Whittle vs exact likelihood when the relaxation time is not short compared with the record.

    python benchmarks/study_whittle_leakage.py

8 seeds per T/tau; prints the mean z = (estimate - truth)/SE of k and gamma for both
likelihoods on the same data. Results: benchmarks/RESULTS_calibration.md.
"""

import jax
import numpy as np

import blurtrap as bt

GAMMA = 6 * np.pi * 9.5e-4 * 0.765e-6
DT, N = 1 / 1500, 65536


def sim(k, seed):
    x = bt.simulate(k, GAMMA, DT, DT, N, key=jax.random.key(seed), method="exact_frames",
                    tracking_std=2e-9)
    return bt.Recording(np.asarray(x).reshape(-1), frame_interval=DT, exposure=DT)


def main():
    bt.enable_x64()
    T = N * DT
    for ratio in [30, 100, 300, 1000, 3000]:
        k = GAMMA / (T / ratio)
        res = {"whittle": [], "exact": []}
        for s in range(8):
            rec = sim(k, s)
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
            print(f"T/tau={ratio} index={np.sqrt(N) / ratio:.3g} {lk}: mean z_k={m[0]:+.2f} "
                  f"z_g={m[1]:+.2f} rel k={m[2]:+.3f} gamma={m[3]:+.3f} "
                  f"nfail={int(np.isnan(v[:, 0]).sum())}", flush=True)


if __name__ == "__main__":
    main()
