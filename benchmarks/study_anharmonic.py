"""Coverage of ``blurtrap.calibrate_anharmonic`` on a quartic trap seen by a camera.

Run:  nice -n 10 python benchmarks/study_anharmonic.py [--seeds 50] [--betas 0,0.05,0.1]
                                                      [--out anharmonic_study.json]
      nice -n 10 python benchmarks/study_anharmonic.py --photodiode --seeds 20 --betas 0.1
(``--photodiode``: instantaneous samples, W = 1e-3 dt in the model, dt = tau/16, 65 536
samples per record, 4 substeps per sample: the W -> 0 path.)

The hidden quartic trap of benchmarks/study_diagnose.py: camera at 1500 fps, W = dt,
16 384 frames, k = 0.01 pN/nm (tau = 4.0 frames), 1.53 um bead, eps = 2 nm, beta = k4 kT/k^2.
Frames come from an independent numpy generator (not blurtrap's simulator or moments):
Strang splitting with 16 substeps per frame (h = tau/64): exact flow of the cubic force
``dx/dt = -k4 x^3/gamma`` for h/2, an exact Ornstein-Uhlenbeck step, the cubic flow for h/2
(weak error O(h^2)); the exposure average is the trapezoid rule over the substeps; 200 frames
of burn-in. All seeds of one beta are simulated together (one vector per substep).

Per seed: ``calibrate_anharmonic`` (default options) and the harmonic ``calibrate``
(default: standard model). Reported per beta: mean relative bias of k and gamma, SD of the
estimates over the mean SE, coverage of |est - truth| < 2 SE and < 3 SE, the J test's
rejection rate at 5 %, and the fit time. Seeds: 5000 + 100 * (index of beta) + i.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time

import numpy as np
from _machine import cpu_model

import blurtrap as bt
from blurtrap.physics import BOLTZMANN

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1 / 1500
K = 1e-5
N = 16384
EPS = 2e-9
TEMP = 295.0
KT = BOLTZMANN * TEMP


def quartic_frames(beta, n_traces, seed, n=N, substeps=16, burn=200, dt=DT, blur=True):
    """(n_traces, n) frames [m] of U = k x^2/2 + k4 x^4/4: camera (W = dt) or, with
    ``blur=False``, instantaneous samples at the frame starts (photodiode, W -> 0)."""
    rng = np.random.default_rng(seed)
    h = dt / (GAMMA / K) / substeps
    c, s = math.exp(-h), math.sqrt(-math.expm1(-2 * h))
    x = rng.standard_normal(n_traces) / math.sqrt(1 + 3 * beta)
    out = np.empty((n + burn, n_traces))
    for i in range(n + burn):
        z = rng.standard_normal((substeps, n_traces))
        acc, x0 = 0.5 * x, x
        for j in range(substeps):
            x = x / np.sqrt(1.0 + beta * x * x * h)
            x = c * x + s * z[j]
            x = x / np.sqrt(1.0 + beta * x * x * h)
            acc = acc + (0.5 * x if j == substeps - 1 else x)
        out[i] = acc / substeps if blur else x0
    frames = out[burn:].T * math.sqrt(KT / K)
    return frames + EPS * rng.standard_normal(frames.shape)


def fit_one(x, dt=DT, exposure=DT):
    rec = bt.Recording(x, frame_interval=dt, exposure=exposure, temperature=TEMP)
    t0 = time.perf_counter()
    a = bt.calibrate_anharmonic(rec)
    t_a = time.perf_counter() - t0
    h = bt.calibrate(rec)
    return {"k": a.k, "k_err": a.k_err, "gamma": a.gamma, "gamma_err": a.gamma_err,
            "beta": a.beta, "beta_err": a.beta_err, "eps2": a.tracking_var,
            "gof_p": a.gof["p_value"], "converged": a.converged, "time_s": t_a,
            "h_k": h.k, "h_k_err": h.k_err, "h_gamma": h.gamma, "h_gamma_err": h.gamma_err}


def summarise(rows, beta):
    out = {"beta": beta, "n": len(rows)}
    for pre, name, truth in (("", "k", K), ("", "gamma", GAMMA), ("h_", "k", K),
                             ("h_", "gamma", GAMMA)):
        est = np.array([r[pre + name] for r in rows])
        se = np.array([r[pre + name + "_err"] for r in rows])
        pull = (est - truth) / se
        key = ("harmonic " if pre else "") + name
        out[key] = {"bias_pct": 100 * (est.mean() / truth - 1),
                    "bias_se_pct": 100 * est.std(ddof=1) / truth / math.sqrt(len(est)),
                    "sd_over_se": est.std(ddof=1) / se.mean(),
                    "cover2": float(np.mean(np.abs(pull) < 2)),
                    "cover3": float(np.mean(np.abs(pull) < 3))}
    b = np.array([r["beta"] for r in rows])
    be = np.array([r["beta_err"] for r in rows])
    out["beta_hat"] = {"mean": b.mean(), "sd": b.std(ddof=1), "mean_se": be.mean(),
                       "cover2": float(np.mean(np.abs(b - beta) < 2 * be))}
    out["j_reject_5pct"] = float(np.mean([r["gof_p"] < 0.05 for r in rows]))
    out["converged"] = int(sum(r["converged"] for r in rows))
    t = np.array([r["time_s"] for r in rows])
    out["time_s"] = {"median": float(np.median(t)), "max": float(t.max()), "first": float(t[0])}
    return out


def table(summaries):
    lines = ["| beta | fit | param | bias % (+- MC) | SD/SE | within 2 SE | within 3 SE |",
             "|---|---|---|---|---|---|---|"]
    for s in summaries:
        for key in ("k", "gamma", "harmonic k", "harmonic gamma"):
            v = s[key]
            fit = "harmonic calibrate" if key.startswith("harmonic") else "anharmonic"
            lines.append(f"| {s['beta']} | {fit} | {key.split()[-1]} | {v['bias_pct']:+.2f} "
                         f"(+- {v['bias_se_pct']:.2f}) | {v['sd_over_se']:.2f} | "
                         f"{v['cover2']:.2f} | {v['cover3']:.2f} |")
    lines.append("")
    lines.append("| beta | mean beta_hat | SD | mean SE | beta within 2 SE | J test p < 0.05 | "
                 "converged | fit time median / max (s) |")
    lines.append("|---|---|---|---|---|---|---|---|")
    for s in summaries:
        b = s["beta_hat"]
        lines.append(f"| {s['beta']} | {b['mean']:.4f} | {b['sd']:.4f} | {b['mean_se']:.4f} | "
                     f"{b['cover2']:.2f} | {s['j_reject_5pct']:.2f} | {s['converged']}/{s['n']} "
                     f"| {s['time_s']['median']:.1f} / {s['time_s']['max']:.1f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--betas", default="0,0.05,0.1")
    ap.add_argument("--out", default="anharmonic_study.json")
    ap.add_argument("--photodiode", action="store_true",
                    help="W -> 0 (1e-3 dt), dt = tau/16, 65 536 samples, 4 substeps each")
    args = ap.parse_args(argv)
    bt.enable_x64()
    betas = [float(b) for b in args.betas.split(",")]
    result = {"cpu": cpu_model(), "photodiode": args.photodiode,
              "n_frames": 4 * N if args.photodiode else N, "seeds": args.seeds, "summaries": [],
              "rows": {}}
    for ib, beta in enumerate(betas):
        seed = 5000 + 100 * ib
        t0 = time.perf_counter()
        if args.photodiode:
            dt, w = GAMMA / K / 16, GAMMA / K / 16e3
            frames = quartic_frames(beta, args.seeds, seed, n=4 * N, substeps=4, dt=dt,
                                    blur=False)
        else:
            dt, w = DT, DT
            frames = quartic_frames(beta, args.seeds, seed)
        print(f"beta = {beta}: simulated {args.seeds} x {frames.shape[1]} frames in "
              f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
        rows = []
        for i in range(args.seeds):
            rows.append(fit_one(frames[i], dt, w) | {"seed": seed, "trace": i})
        result["rows"][str(beta)] = rows
        result["summaries"].append(summarise(rows, beta))
        pathlib.Path(args.out).write_text(json.dumps(result, indent=1, default=float))
    print(f"CPU: {result['cpu']}; {result['n_frames']} frames per record, {args.seeds} records "
          f"per beta{' (photodiode)' if args.photodiode else ''}\n")
    print(table(result["summaries"]))


if __name__ == "__main__":
    main()
