"""Experiment design with the friction known (``bt.design(..., friction_error=...)``): the
predicted SEs against the scatter of simulated experiments fitted as a user would.

Two cases (issue 21: "a validated dt >> tau design" and "the force-sensitivity target"):

- ``dt_tau``: camera 500 fps, k = 0.5 pN/nm, 1.53 um bead (dt/tau ~ 36), 2 nm tracking noise,
  131 s in all. Without the friction no design identifies k and gamma (RESULTS_design.md,
  design d); with it known exactly, ``bt.design`` recommends an exposure series; each
  simulated experiment is fitted by ``bt.calibrate(recordings, fixed={"gamma": gamma})``.
- ``volts``: camera 1500 fps, W = dt, 65 536 frames, k = 0.05 pN/nm, 2 nm noise, positions
  in volts (Rd = 100 nm/V), friction known from the bead (``friction: stokes``); the predicted
  SE of the force sensitivity Rf = k Rd (``predicted_se["force_sensitivity"]`` of the user's
  ``current`` design) against the SD of log Rf of ``bt.calibrate`` on the volts traces.

Frames: ``bt.simulate(..., method="exact_frames")`` (the exact frame law). Usage:
``python benchmarks/study_design_known.py dt_tau 200`` / ``... dt_tau_paper 200`` (the paper's
series on the same trap, for the predicted ratio) / ``... volts 200``.
"""

from __future__ import annotations

import math
import sys
import time
import warnings

import jax
import numpy as np

import blurtrap as bt

T = 295.0
RADIUS = 1.53e-6


def _gamma():
    return 6 * math.pi * float(bt.physics.water_viscosity(T)) * RADIUS


def dt_tau(n_exp: int, label=None):
    """``label``: fit this candidate instead of the recommended one."""
    gamma, k = _gamma(), 5e-4
    r = bt.design(k=k, gamma=gamma, max_fps=500, total_time=65536 / 500, tracking_std=2e-9,
                  friction_error=0.0)
    print(r.summary())
    cand = r.best if label is None else next(c for c in r.candidates if c.label == label)
    print("fitted:", cand.label)
    ks, fails = [], 0
    for e in range(n_exp):
        recs = []
        for i, (dt, w, n) in enumerate(cand.recordings):
            x = bt.simulate(k, gamma, w, dt, int(n), key=jax.random.key(1000 * e + i),
                            method="exact_frames", tracking_std=2e-9)
            recs.append(bt.Recording(np.asarray(x).ravel(), frame_interval=dt, exposure=w,
                                     temperature=T))
        try:
            ks.append(bt.calibrate(recs, fixed={"gamma": gamma}).k)
        except bt.FitError:
            fails += 1
    return {"k": (float(np.max(cand.predicted_se["k"])), np.log(np.asarray(ks) / k))}, fails


def volts(n_exp: int):
    gamma, k, dt, n, rd = _gamma(), 5e-5, 1 / 1500, 65536, 1e-7
    r = bt.design(k=k, gamma=gamma, max_fps=1500, n_frames=n, tracking_std=2e-9,
                  target="force_sensitivity", friction_error=0.0, current=[(dt, dt, n)],
                  series=())
    cur = next(c for c in r.candidates if c.label == "your current design")
    print(r.summary())
    x = np.asarray(bt.simulate(k, gamma, dt, dt, n, key=jax.random.key(7), n_traces=n_exp,
                               method="exact_frames", tracking_std=2e-9)).reshape(n_exp, n)
    meta = {"detector": "camera", "friction": "stokes", "bead_radius_m": RADIUS,
            "viscosity_Pa_s": float(bt.physics.water_viscosity(T))}
    rf, kk, fails = [], [], 0
    for row in x:
        rec = bt.Recording(row / rd, frame_interval=dt, exposure=dt, temperature=T,
                           position_unit="V", metadata=meta)
        try:
            # the simulator's friction does not depend on frequency: say so (the default,
            # hydrodynamics="auto", would add the known bead's hydrodynamics here)
            res = bt.calibrate(rec, hydrodynamics=False)
        except bt.FitError:
            fails += 1
            continue
        d = dict(zip(res.param_names, map(float, res.values)))
        rf.append(d["force_sensitivity"])
        kk.append(res.k)
    rf_true = k * rd
    return {"force_sensitivity": (float(cur.predicted_se["force_sensitivity"][0]),
                                  np.log(np.asarray(rf, dtype=float) / rf_true)),
            "k (volts: k' gamma0 / gamma', not the design's metres k)":
                (float(cur.predicted_se["k"][0]), np.log(np.asarray(kk) / k))}, fails


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    case, n_exp = argv[0], int(argv[1])
    bt.enable_x64()
    warnings.simplefilter("ignore")
    t0 = time.time()
    cases = {"dt_tau": dt_tau, "volts": volts,
             "dt_tau_paper": lambda n: dt_tau(n, "the paper's exposure series")}
    rows, fails = cases[case](n_exp)
    print(f"\ncase {case}: {n_exp} experiments, {fails} failed fits, {time.time() - t0:.0f} s")
    print("| quantity | predicted SE % | SD of log % | SD / SE | MC unc. of SD | mean log bias % | n |")
    print("|---|---|---|---|---|---|---|")
    for q, (pred, logs) in rows.items():
        logs = logs[np.isfinite(logs)]
        sd = float(np.std(logs, ddof=1))
        print(f"| {q} | {100 * pred:.3g} | {100 * sd:.3g} | {sd / pred:.3f} | "
              f"{1 / math.sqrt(2 * (len(logs) - 1)):.1%} | {100 * np.mean(logs):+.2f} | "
              f"{len(logs)} |")


if __name__ == "__main__":
    main()
