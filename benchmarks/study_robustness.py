"""Adversarial calibration campaign (issue 8): extreme stiffness, blur, noise and length.

Every fit must either raise a clear error (``FitError``/``ValueError`` whose message names
the problem) or return finite values whose standard errors are honest: the truth within
``Z_MAX`` standard errors for k and gamma. Anything else (NaN, a confident wrong answer) is a
silent failure and is listed. The simulation is blurtrap's exact frame sampler.

    python benchmarks/study_robustness.py            # quick grid (~10 min on 2 cores)
    python benchmarks/study_robustness.py --seeds 3  # more seeds
    python benchmarks/study_robustness.py --smoke    # 3 stiffnesses x 2 blurs x 2 noises, 2048
                                                     # frames, all three methods (~36 fits)

Writes a table to stdout and (with ``--out``) a JSON file of every case.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
import warnings

import jax
import numpy as np

import blurtrap as bt
from blurtrap.inference import FitError

Z_MAX = 5.0
KB_T = 1.380649e-23 * 295.0
GAMMA = 6 * math.pi * 9.5e-4 * 0.765e-6  # 1.53 um bead diameter in water


def run_case(k, w_over_dt, eps, n, seed, method, likelihood):
    dt = 1 / 1500
    w = w_over_dt * dt
    x = bt.simulate(k, GAMMA, w, dt, n, key=jax.random.key(seed), method="exact_frames",
                    tracking_std=eps)
    rec = bt.Recording(np.asarray(x).reshape(-1), frame_interval=dt, exposure=w)
    kw = {"method": method}
    if method == "likelihood":
        kw["likelihood"] = likelihood
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            r = bt.calibrate(rec, **kw)
    except (FitError, ValueError) as exc:
        return {"outcome": "clear error", "error": f"{type(exc).__name__}: {exc}"}
    except Exception as exc:  # anything else is a bug
        return {"outcome": "crash", "error": f"{type(exc).__name__}: {exc}"}
    vals = [r.k, r.k_err, r.gamma, r.gamma_err]
    if not all(math.isfinite(v) for v in vals):
        return {"outcome": "NaN", "values": vals}
    zk = (r.k - k) / r.k_err
    zg = (r.gamma - GAMMA) / r.gamma_err
    ok = abs(zk) < Z_MAX and abs(zg) < Z_MAX
    return {"outcome": "honest" if ok else "confident wrong", "z_k": zk, "z_gamma": zg,
            "k": r.k, "k_err": r.k_err, "gamma": r.gamma, "gamma_err": r.gamma_err,
            "notes": list(r.notes)}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--out", default=None)
    ap.add_argument("--smoke", action="store_true",
                    help="smallest grid that still covers every method and both extremes")
    a = ap.parse_args(argv)
    bt.enable_x64()
    ks = np.logspace(-11, -3, 9)  # 1e-8 ... 1 pN/nm
    eps_grid, lengths = (0.0, 2e-9, 20e-9), (2048, 65536)
    if a.smoke:
        ks, eps_grid, lengths = np.logspace(-11, -3, 3), (0.0, 20e-9), (2048,)
    grid = list(itertools.product(ks, (0.02, 1.0), eps_grid, lengths,
                                  range(a.seeds),
                                  (("auto", None), ("likelihood", "exact"), ("psd", None))))
    rows, t0 = [], time.time()
    for k, wr, eps, n, seed, (method, lk) in grid:
        res = run_case(k, wr, eps, n, seed, method, lk)
        res.update(k_true=k, w_over_dt=wr, eps=eps, n=n, seed=seed, method=method,
                   likelihood=lk, alpha=wr / 1500 * k / GAMMA)
        rows.append(res)
        if res["outcome"] in ("NaN", "confident wrong", "crash"):
            print("FAIL", json.dumps(res, default=str), flush=True)
    counts = {}
    for r in rows:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    print(f"{len(rows)} adversarial fits in {time.time() - t0:.0f} s: {counts}")
    by_method = {}
    for r in rows:
        key = r["method"] + ("/" + r["likelihood"] if r["likelihood"] else "")
        by_method.setdefault(key, {}).setdefault(r["outcome"], 0)
        by_method[key][r["outcome"]] += 1
    for m, c in by_method.items():
        print(f"  {m}: {c}")
    if a.out:
        with open(a.out, "w") as f:
            json.dump(rows, f, default=float, indent=1)


if __name__ == "__main__":
    main()
