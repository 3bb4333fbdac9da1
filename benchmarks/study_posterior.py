"""Posterior sampling study: speed, compilation, and credible-interval coverage.

Run:  python benchmarks/study_posterior.py [--datasets 200] [--steps 800] [--out DIR]

1. Timing on one 65 536-frame camera recording (dt = W = 1/1500 s): compile time of the
   batched log-posterior (both batch shapes), wall time of 32 walkers x 2000 steps after
   compilation, and a trace counter showing exactly two compiled batch shapes (full and half
   ensemble) that new data of the same shapes reuse.
2. Coverage: ``--datasets`` simulated recordings at the full spec (65 536 frames, 32
   walkers; eps = 2 nm, gamma = 6 pi 0.00093 Pa s 1.53 um, k log-uniform in 0.005-0.1
   pN/nm), central 68 % / 95 % intervals of k, gamma and eps^2 against the truth, with the
   binomial standard error.

Writes ``posterior_study.json`` (and prints a markdown table) in ``--out``.
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
import time
import warnings

import jax
import numpy as np

import blurtrap

DT = 1.0 / 1500.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
EPS = 2e-9
N_FRAMES = 65536
NAMES = ("k", "gamma", "tracking_var")


def machine_info() -> dict:
    import emcee
    import equinox
    import jaxlib

    cpu = platform.processor()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:  # pragma: no cover
        pass
    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "numpy": np.__version__,
        "emcee": emcee.__version__,
        "equinox": equinox.__version__,
        "blurtrap": blurtrap.__version__,
        "device": str(jax.devices()[0]),
        "load_average_start": os.getloadavg(),
    }


def simulate(ks, seed):
    x = blurtrap.simulate(np.asarray(ks), GAMMA, DT, DT, N_FRAMES, key=jax.random.key(seed),
                          method="exact_frames", tracking_std=EPS, n_traces=1)
    return np.asarray(x, dtype=float).reshape(len(ks), N_FRAMES)


def rec(y):
    return blurtrap.Recording(y, frame_interval=DT, exposure=DT)


def timing_study() -> dict:
    from blurtrap.inference import _posterior as pm

    ys = simulate([2e-5, 2e-5, 3e-5], seed=99)
    n0 = pm.trace_count()
    t0 = time.perf_counter()
    first = pm.sample_posterior(rec(ys[0]), n_walkers=32, n_steps=2000, seed=0)
    t_first = time.perf_counter() - t0
    n_first = pm.trace_count() - n0
    runs = []
    for i in (1, 2):
        t0 = time.perf_counter()
        p = pm.sample_posterior(rec(ys[i]), n_walkers=32, n_steps=2000, seed=i)
        runs.append({"total_s": time.perf_counter() - t0, **p.timing})
    return {
        "compile_s": first.timing["compile_s"],
        "first_call_total_s": t_first,
        "first_call_sampling_s": first.timing["sampling_s"],
        "traces_after_first_call": n_first,
        "traces_after_three_calls": pm.trace_count() - n0,
        "runs_after_compilation": runs,
        "autocorr_time": first.autocorr_time,
        "acceptance": float(np.mean(first.acceptance_fraction)),
    }


def coverage_study(n_data: int, n_steps: int, chunk: int = 20) -> dict:
    from blurtrap.inference._posterior import ShortChainWarning, sample_posterior

    rng = np.random.default_rng(20240601)
    ks = np.exp(rng.uniform(np.log(5e-6), np.log(1e-4), n_data))
    hits = {q: {n: 0 for n in NAMES} for q in (0.68, 0.95)}
    taus, esss, accs, short, pulls = [], [], [], 0, {n: [] for n in NAMES}
    t_start = time.perf_counter()
    for c0 in range(0, n_data, chunk):
        ys = simulate(ks[c0:c0 + chunk], seed=1000 + c0)
        for j, y in enumerate(ys):
            i = c0 + j
            truth = {"k": ks[i], "gamma": GAMMA, "tracking_var": EPS**2}
            with warnings.catch_warnings(record=True) as w:
                warnings.simplefilter("always", ShortChainWarning)
                p = sample_posterior(rec(y), n_walkers=32, n_steps=n_steps, seed=i)
            short += any(issubclass(x.category, ShortChainWarning) for x in w)
            for q in (0.68, 0.95):
                for n in NAMES:
                    lo, hi = p.interval(n, q)
                    hits[q][n] += int(lo <= truth[n] <= hi)
            for n in NAMES:
                s = p.samples[n]
                pulls[n].append(float((np.median(s) - truth[n]) / np.std(s)))
            taus.append(max(p.autocorr_time.values()))
            esss.append(min(p.ess.values()))
            accs.append(float(np.mean(p.acceptance_fraction)))
        done = min(c0 + chunk, n_data)
        el = time.perf_counter() - t_start
        print(f"  {done}/{n_data} datasets, {el:.0f} s", flush=True)
    rates = {str(q): {n: hits[q][n] / n_data for n in NAMES} for q in hits}
    se = {str(q): math.sqrt(q * (1 - q) / n_data) for q in hits}
    return {
        "n_datasets": n_data,
        "n_steps": n_steps,
        "n_walkers": 32,
        "n_frames": N_FRAMES,
        "hits": {str(q): v for q, v in hits.items()},
        "rates": rates,
        "binomial_se": se,
        "max_tau_mean": float(np.mean(taus)),
        "max_tau_max": float(np.max(taus)),
        "min_ess_mean": float(np.mean(esss)),
        "min_ess_min": float(np.min(esss)),
        "acceptance_mean": float(np.mean(accs)),
        "short_chain_warnings": int(short),
        "pull_mean": {n: float(np.mean(v)) for n, v in pulls.items()},
        "pull_sd": {n: float(np.std(v, ddof=1)) for n, v in pulls.items()},
        "wall_s": time.perf_counter() - t_start,
    }


def markdown(res: dict) -> str:
    cov = res["coverage"]
    lines = ["| quantity | 68 % coverage | 95 % coverage |", "|---|---|---|"]
    for n in NAMES:
        r68 = cov["rates"]["0.68"][n]
        r95 = cov["rates"]["0.95"][n]
        z68 = (r68 - 0.68) / cov["binomial_se"]["0.68"]
        z95 = (r95 - 0.95) / cov["binomial_se"]["0.95"]
        lines.append(f"| {n} | {r68:.3f} ({z68:+.1f} SE) | {r95:.3f} ({z95:+.1f} SE) |")
    lines.append(f"\nbinomial SE: 68 %: {cov['binomial_se']['0.68']:.3f}, "
                 f"95 %: {cov['binomial_se']['0.95']:.3f}")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", type=int, default=200, help="0: timing only")
    ap.add_argument("--steps", type=int, default=800)
    ap.add_argument("--out", default="benchmarks/out")
    ap.add_argument("--skip-timing", action="store_true")
    a = ap.parse_args(argv)
    blurtrap.enable_x64()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    res = {"machine": machine_info()}
    print(json.dumps(res["machine"], indent=1), flush=True)
    if not a.skip_timing:
        res["timing"] = timing_study()
        print(json.dumps(res["timing"], indent=1), flush=True)
        (out / "posterior_study.json").write_text(json.dumps(res, indent=1))
    if a.datasets > 0:
        res["coverage"] = coverage_study(a.datasets, a.steps)
    res["machine"]["load_average_end"] = os.getloadavg()
    (out / "posterior_study.json").write_text(json.dumps(res, indent=1))
    if a.datasets > 0:
        print(json.dumps(res["coverage"], indent=1))
        print(markdown(res))


if __name__ == "__main__":
    main()
