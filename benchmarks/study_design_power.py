"""Validate the power series of ``bt.design(..., laser_powers=...)`` by simulation: the
predicted relative SE of c (k = c P; = SE of k at the power k is given at) and of gamma
against the SD of log c and log gamma over simulated experiments fitted as a user would,
``bt.calibrate(recordings with laser_power set, k="linear_power", method="likelihood")``.

Setting (issue 21): camera 1500 fps, 1.53 um bead in water at 295 K, k = 0.05 pN/nm at the
reference power P0 (p = 1), available powers (0.5, 1, 2) P0, 2 nm tracking noise, 65 536
frames' time in all (43.7 s). Designs simulated, each one of bt.design's candidates:

- ``pw_dt``   the power series at W = dt (each power 21 845 frames);
- ``pw_opt``  the power series with each power's exposure optimised by bt.design;
- ``single``  bt.design's best single power (its whole time at one power; fitted with the
              same k="linear_power", so its c is k_i / p_i).
- ``tau_opt`` dt >> tau: camera 500 fps, k = 0.5 pN/nm at P0 (dt/tau = 18-72 over the
              powers), 131 s in all, target "determinant": the optimised power series, the
              only candidate that identifies both k and gamma there.

Frames: ``bt.simulate(..., method="exact_frames")`` (the exact frame law), per design and
chunk one key ``jax.random.key(seed_base + 1000 * index + chunk)`` split over the recordings.
Laser powers are p * 0.1 W on the recordings (only ratios matter).

Run:  python benchmarks/study_design_power.py --n 200 [--only pw_dt,pw_opt] [--out DIR]
Writes ``design_power_study.json`` in --out (default: a temporary folder name printed) and
prints a markdown table.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import pathlib
import platform
import sys
import tempfile
import time

import jax
import numpy as np
from _machine import cpu_model

import blurtrap as bt

bt.enable_x64()

from blurtrap.physics import water_viscosity  # noqa: E402

T = 295.0
GAMMA = 6 * math.pi * float(water_viscosity(T)) * 1.53e-6
K = 5e-5
DT = 1 / 1500
EPS = 2e-9
POWERS = (0.5, 1.0, 2.0)
P0 = 0.1  # W: the reference power; the recordings carry p * P0
INDEX = {"pw_dt": 0, "pw_opt": 1, "single": 2, "tau_opt": 3}
#: the bt.design calls (k at P0, fastest frame rate, total time, target)
CASES = {"camera": (K, 1500.0, 65536 * DT, "k"), "dt_tau": (5e-4, 500.0, 65536 / 500,
                                                             "determinant")}
#: design -> (case, start of the candidate's label)
PICK = {"pw_dt": ("camera", "power series"), "pw_opt": ("camera", "optimised power series"),
        "single": ("camera", "best single power"),
        "tau_opt": ("dt_tau", "optimised power series")}


def run_designs(names):
    """bt.design with the powers available, for the cases of ``names``: (results by case,
    name -> (k at P0, candidate label, [(dt, W, N, p)], predicted relative SE of c, gamma))."""
    results, out = {}, {}
    for case in sorted({PICK[n][0] for n in names}):
        k, fps, total, target = CASES[case]
        t0 = time.perf_counter()
        results[case] = bt.design(k=k, gamma=GAMMA, max_fps=fps, total_time=total,
                                  tracking_std=EPS, laser_powers=POWERS, series=(1,),
                                  target=target)
        print(results[case].summary(), f"\n(bt.design: {time.perf_counter() - t0:.0f} s)\n",
              flush=True)
    for name in names:
        case, start = PICK[name]
        c = next(c for c in results[case].candidates if c.label.startswith(start))
        recs = [(dt, w, int(round(n)), p) for (dt, w, n), p in zip(c.recordings, c.laser_powers)]
        out[name] = (CASES[case][0], c.label, recs,
                     {"k": float(np.max(c.predicted_se["k"])),
                      "gamma": float(np.max(c.predicted_se["gamma"]))})
    return results, out


def simulate(k, recs, n, key):
    keys = jax.random.split(key, len(recs))
    return [np.asarray(bt.simulate(k * p, GAMMA, w, dt, nf, key=kk, n_traces=n,
                                   method="exact_frames", tracking_std=EPS)).reshape(n, nf)
            for (dt, w, nf, p), kk in zip(recs, keys)]


def fit(recs, xs, i):
    """log c, log gamma, relative SE of c of experiment i (NaNs when the fit fails)."""
    recordings = [bt.Recording(x[i], frame_interval=dt, exposure=w, temperature=T,
                               laser_power=p * P0) for x, (dt, w, _, p) in zip(xs, recs)]
    try:
        r = bt.calibrate(recordings, k="linear_power", method="likelihood")
    except Exception as exc:  # a failed fit is counted, not fatal
        print(f"  fit {i} failed: {exc!s:.120}", flush=True)
        return math.nan, math.nan, math.nan
    c, c_err = r.params["c"], float(r.errors[r.param_names.index("c")])
    return math.log(c * P0), math.log(r.gamma), c_err / c


def run_one(name, k, label, recs, pred, n, chunk, seed_base):
    t0 = time.perf_counter()
    rows = []
    for ci, start in enumerate(range(0, n, chunk)):
        m = min(chunk, n - start)
        xs = simulate(k, recs, m, jax.random.key(seed_base + 1000 * INDEX[name] + ci))
        rows += [fit(recs, xs, i) for i in range(m)]
        print(f"  {name}: {start + m}/{n} ({time.perf_counter() - t0:.0f} s)", flush=True)
    a = np.array(rows)
    ok = np.all(np.isfinite(a), axis=1)
    nok = int(ok.sum())
    sd = {"k": float(np.std(a[ok, 0], ddof=1)), "gamma": float(np.std(a[ok, 1], ddof=1))}
    bias = {"k": float(np.mean(a[ok, 0]) - math.log(k)),
            "gamma": float(np.mean(a[ok, 1]) - math.log(GAMMA))}
    return {"name": name, "label": label, "k_at_P0": k, "gamma": GAMMA,
            "recordings": [{"frame_interval_s": dt, "exposure_s": w, "n_frames": nf,
                            "laser_power_relative": p} for dt, w, nf, p in recs],
            "n": n, "n_ok": nok, "failures": n - nok, "predicted_se": pred, "measured_sd": sd,
            "mean_log_bias": bias, "mean_fit_rel_se_c": float(np.mean(a[ok, 2])),
            "mc_rel_uncertainty_of_sd": math.sqrt(1 / (2 * (nok - 1))),
            "seed_base": seed_base, "seconds": time.perf_counter() - t0,
            "log_c_P0": [float(v) for v in a[:, 0]], "log_gamma": [float(v) for v in a[:, 1]]}


def table(rows) -> str:
    out = ["| design | param | predicted SE % | measured SD % | ratio | MC unc. of SD | "
           "n ok | failures | mean bias of log % |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for p, name in (("k", "c (= k at P0)"), ("gamma", "gamma")):
            pr, sd = r["predicted_se"][p], r["measured_sd"][p]
            out.append(f"| {r['name']} | {name} | {100 * pr:.3g} | {100 * sd:.3g} | "
                       f"{sd / pr:.3f} | {100 * r['mc_rel_uncertainty_of_sd']:.1f} % | "
                       f"{r['n_ok']} | {r['failures']} | {100 * r['mean_log_bias'][p]:+.2g} |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--chunk", type=int, default=50)
    ap.add_argument("--seed-base", type=int, default=0)
    ap.add_argument("--only", default=None,
                    help="comma-separated: pw_dt, pw_opt, single, tau_opt (default all)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    out = pathlib.Path(a.out or tempfile.mkdtemp(prefix="design_power_"))
    out.mkdir(parents=True, exist_ok=True)
    print("output:", out, flush=True)
    names = a.only.split(",") if a.only else list(PICK)
    res, designs = run_designs(names)
    rows = []
    for name in names:
        k, label, recs, pred = designs[name]
        print(f"{name}: {label}: {recs}", flush=True)
        rows.append(run_one(name, k, label, recs, pred, a.n, a.chunk, a.seed_base))
        meta = {"date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
                "cpu": cpu_model(), "processor": platform.processor(),
                "nproc": os.cpu_count(), "python": sys.version.split()[0],
                "jax": jax.__version__, "command": " ".join(sys.argv)}
        (out / "design_power_study.json").write_text(json.dumps(
            {"meta": meta, "designs": {c: r.to_dict() for c, r in res.items()},
             "rows": rows}, indent=1))
        print(table(rows[-1:]), flush=True)
    print(table(rows))
    for r in rows:
        print(f"{r['name']}: mean SE of c reported by calibrate {100 * r['mean_fit_rel_se_c']:.3g} "
              f"%, {r['seconds']:.0f} s")


if __name__ == "__main__":
    main()
