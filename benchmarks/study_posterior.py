"""Posterior sampling study: speed, compilation, and credible-interval coverage.

Run:  python benchmarks/study_posterior.py [--datasets 200] [--steps 2000] [--out DIR]
                                          [--timing-steps 2000]

1. Timing on one 65 536-frame camera recording (dt = W = 1/1500 s):
   - per-call cost of the batched log-posterior (16 and 32 walkers: the two shapes emcee
     uses) for the closed-form Whittle evaluation that ``sample_posterior`` uses (lag sums),
     the generic per-ordinate Whittle form on P_d (the previous evaluation), the expected-
     periodogram form of ``calibrate`` (used when the record is short compared with tau),
     and a plain NumPy reference of the same log-posterior in the same process (values
     checked to agree);
   - compile time of both batch shapes, wall time of 32 walkers x 2000 steps after
     compilation, and a trace counter showing exactly two compiled batch shapes that new data
     of the same shapes reuse.
2. Coverage: ``--datasets`` independent simulated recordings at the full spec (65 536 frames,
   32 walkers, ``--steps`` steps; eps = 2 nm, gamma = 6 pi 0.00093 Pa s 1.53 um, k
   log-uniform in 0.005-0.1 pN/nm; default priors). Central 68 % / 95 % credible intervals
   of k, gamma and
   eps^2 against the truth, with the binomial standard error and the acceptance bands of
   issue 5 (68 +- 4 %, 95 +- 2 %). Per dataset it also records the ML estimate and Fisher SE
   (Wald coverage on the same data; posterior SD / Fisher SE; (median - ML) / SE).

Every dataset gets its own PRNG key (``jax.random.split``): a single key for a grid of k
values gives *common random numbers* (``simulate``'s documented behaviour), which made the
datasets of a chunk strongly correlated in an earlier version of this study.

Per-dataset results are appended to ``DIR/posterior_coverage.jsonl`` as they finish; a rerun
with the same arguments resumes where it stopped. The summary goes to
``DIR/posterior_study.json`` and a markdown table is printed.
"""

from __future__ import annotations

import argparse
import dataclasses
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
from _machine import cpu_model

import blurtrap

DT = 1.0 / 1500.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
EPS = 2e-9
N_FRAMES = 65536
NAMES = ("k", "gamma", "tracking_var")
BANDS = {"0.68": 0.04, "0.95": 0.02}  # issue 5: 68 +- 4 %, 95 +- 2 %


def machine_info() -> dict:
    import emcee
    import equinox
    import jaxlib

    cpu = cpu_model()
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
    """One independent recording per k (its own key: no common random numbers)."""
    ks = np.asarray(ks, dtype=float)
    keys = jax.random.split(jax.random.key(seed), ks.size)
    x = blurtrap.simulate(ks, GAMMA, DT, DT, N_FRAMES, key=keys, method="exact_frames",
                          tracking_std=EPS, n_traces=1)
    return np.asarray(x, dtype=float).reshape(ks.size, N_FRAMES)


def rec(y):
    return blurtrap.Recording(y, frame_interval=DT, exposure=DT)


# ------------------------------------------------------------------------------------------
# timing
# ------------------------------------------------------------------------------------------
def numpy_log_posterior(thetas, f, power, weight, log_ref, temperature=295.0):
    """Plain NumPy reference: the literal Whittle log-posterior (closed-form P_d(f), DESIGN
    item 5) with the default priors, vectorised over walkers."""
    from blurtrap.inference._priors import DEFAULT_BOUNDS

    p = np.exp(thetas)
    k, gamma, eps2 = p[:, :1], p[:, 1:2], p[:, 2:3]
    kt = blurtrap.BOLTZMANN * temperature
    sigma2, tau = kt / k, gamma / k
    a, r = DT / tau, DT / tau
    s = 2.0 / a * (1.0 + np.expm1(-a) / a)
    rho = np.exp(-r)
    b = (np.sinh(a / 2) / (a / 2)) ** 2
    c0 = sigma2 * s + eps2
    th = 2.0 * np.pi * f[None, :] * DT
    psd = DT * (c0 + 2.0 * sigma2 * b * (rho * np.cos(th) - rho**2)
                / (1.0 - 2.0 * rho * np.cos(th) + rho**2))
    ll = -np.sum(weight * (np.log(psd) - log_ref + power / psd), axis=1)
    lp = np.zeros(len(p))
    for i, name in enumerate(NAMES):
        lo, hi = DEFAULT_BOUNDS[name]
        inside = (p[:, i] >= lo) & (p[:, i] <= hi)
        if name == "tracking_var":  # default Uniform(0, 1e-10)
            lp += np.where(inside & (p[:, i] > 0), -np.log(hi - lo), -np.inf)
        else:  # default LogUniform
            lp += np.where(inside, -np.log(p[:, i]) - np.log(np.log(hi / lo)), -np.inf)
    return ll + lp + np.sum(thetas, axis=1)


def _per_call_ms(fn, th, repeats=7, inner=50):
    fn(th)
    best = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn(th)
        best.append((time.perf_counter() - t0) / inner * 1e3)
    return float(min(best)), float(np.median(best))


def per_call_study(y) -> dict:
    from blurtrap.inference import _log_posterior as lp
    from blurtrap.inference._models import get_model
    from blurtrap.inference._posterior_priors import _resolve_priors
    from blurtrap.inference._problems import make_layout
    from blurtrap.inference._spectral import _spectral_args
    from blurtrap.inference._whittle_closed import _rational_args

    r = rec(y)
    lay = make_layout([r], "shared", True)
    spec = _spectral_args([r], lay, get_model(None), 1, None)
    rat = _rational_args([r], spec)
    pri = _resolve_priors(lay, None)[0]
    ml = blurtrap.calibrate(r, method="likelihood", likelihood="whittle")
    rng = np.random.default_rng(0)
    out = {}
    for nw in (16, 32):
        th = np.log(ml.values)[None, :] + 0.01 * rng.standard_normal((nw, 3))
        row = {}
        ref_vals = numpy_log_posterior(th, np.asarray(spec.f)[0], np.asarray(spec.power)[0],
                                       np.asarray(spec.weight)[0], float(spec.log_ref))
        row["numpy_reference_ms"] = _per_call_ms(
            lambda t: numpy_log_posterior(t, np.asarray(spec.f)[0], np.asarray(spec.power)[0],
                                          np.asarray(spec.weight)[0], float(spec.log_ref)),
            th, repeats=3, inner=3)
        plain = dataclasses.replace(spec, block_len=None)  # P_d per ordinate (as numpy)
        for label, lik in (("jax_closed_form_lags_ms", rat),
                           ("jax_generic_ordinates_ms", plain),
                           ("jax_expected_periodogram_ms", spec)):
            args = lp._PostArgs(lik=lik, priors=pri, names=lay.names, user_log_prior=(),
                                chunk=1)
            fn = lp._compiled_log_posterior(args)
            vals = fn(th)
            row[label] = _per_call_ms(fn, th)
            if lik is not spec:  # the expected periodogram differs by design (leakage)
                row[label.replace("_ms", "_max_abs_diff_vs_numpy")] = float(
                    np.max(np.abs(vals - ref_vals)))
        out[f"{nw}_walkers"] = row
    out["note"] = "(min, median) ms per call over 7 repeats; numpy reference: 3 repeats"
    return out


def timing_study(n_steps: int = 2000) -> dict:
    from blurtrap.inference import _log_posterior as lp
    from blurtrap.inference import _posterior as pm

    ys = simulate([2e-5, 2e-5, 3e-5], seed=99)
    n0 = lp.trace_count()
    t0 = time.perf_counter()
    first = pm.sample_posterior(rec(ys[0]), n_walkers=32, n_steps=n_steps, seed=0)
    t_first = time.perf_counter() - t0
    n_first = lp.trace_count() - n0
    runs = []
    for i in (1, 2, 1, 2):
        t0 = time.perf_counter()
        p = pm.sample_posterior(rec(ys[i]), n_walkers=32, n_steps=n_steps, seed=i)
        runs.append({"total_s": time.perf_counter() - t0, **p.timing,
                     "load_average": os.getloadavg()[0]})
    return {
        "n_steps": n_steps,
        "compile_s": first.timing["compile_s"],
        "first_call_total_s": t_first,
        "first_call_sampling_s": first.timing["sampling_s"],
        "traces_after_first_call": n_first,
        "traces_after_five_calls": lp.trace_count() - n0,
        "runs_after_compilation": runs,
        "autocorr_time": first.autocorr_time,
        "acceptance": float(np.mean(first.acceptance_fraction)),
        "per_call": per_call_study(ys[0]),
    }


# ------------------------------------------------------------------------------------------
# coverage
# ------------------------------------------------------------------------------------------
def one_dataset(i, y, k_true, n_steps) -> dict:
    from blurtrap.inference._posterior import ShortChainWarning, sample_posterior

    truth = {"k": float(k_true), "gamma": GAMMA, "tracking_var": EPS**2}
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always", ShortChainWarning)
        p = sample_posterior(rec(y), n_walkers=32, n_steps=n_steps, seed=int(i))
    row = {"i": int(i), "k_true": float(k_true), "wall_s": time.perf_counter() - t0,
           "short_chain_warning": any(issubclass(x.category, ShortChainWarning) for x in w),
           "max_tau": max(p.autocorr_time.values()), "min_ess": min(p.ess.values()),
           "acceptance": float(np.mean(p.acceptance_fraction)), "burn_in": p.burn_in}
    for j, n in enumerate(NAMES):
        s = p.samples[n]
        q = np.quantile(s, [0.025, 0.16, 0.5, 0.84, 0.975])
        row[n] = {"truth": truth[n], "q": [float(v) for v in q], "sd": float(np.std(s)),
                  "ml": float(p.ml.values[j]), "se": float(p.ml.errors[j])}
    return row


def coverage_study(n_data: int, n_steps: int, out: pathlib.Path, chunk: int = 20) -> list:
    rng = np.random.default_rng(20240601)
    ks = np.exp(rng.uniform(np.log(5e-6), np.log(1e-4), n_data))
    path = out / "posterior_coverage.jsonl"
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if r.get("n_steps") == n_steps:
                    done[r["i"]] = r
    t_start = time.perf_counter()
    with path.open("a") as fh:
        for c0 in range(0, n_data, chunk):
            idx = [i for i in range(c0, min(c0 + chunk, n_data)) if i not in done]
            if not idx:
                continue
            ys = simulate(ks[c0:c0 + chunk], seed=1000 + c0)  # same data on a resumed run
            for i in idx:
                row = one_dataset(i, ys[i - c0], ks[i], n_steps)
                row["n_steps"] = n_steps
                fh.write(json.dumps(row) + "\n")
                fh.flush()
                done[i] = row
            el = time.perf_counter() - t_start
            print(f"  {len(done)}/{n_data} datasets, {el:.0f} s this run, load "
                  f"{os.getloadavg()[0]:.1f}", flush=True)
    return [done[i] for i in range(n_data)]


def summarise(rows: list) -> dict:
    n = len(rows)
    res = {"n_datasets": n, "n_steps": rows[0]["n_steps"], "n_walkers": 32,
           "n_frames": N_FRAMES, "rates": {}, "hits": {}, "binomial_se": {}, "z": {},
           "within_band": {}, "wald_rates": {}}
    for lev, (lo_i, hi_i), zq in (("0.68", (1, 3), 1.0), ("0.95", (0, 4), 1.959964)):
        q = float(lev)
        se = math.sqrt(q * (1 - q) / n)
        res["binomial_se"][lev] = se
        res["hits"][lev], res["rates"][lev], res["z"][lev] = {}, {}, {}
        res["within_band"][lev], res["wald_rates"][lev] = {}, {}
        for name in NAMES:
            h = sum(int(r[name]["q"][lo_i] <= r[name]["truth"] <= r[name]["q"][hi_i])
                    for r in rows)
            wald = sum(int(abs(r[name]["ml"] - r[name]["truth"]) <= zq * r[name]["se"])
                       for r in rows)
            res["hits"][lev][name] = h
            res["rates"][lev][name] = h / n
            res["z"][lev][name] = (h / n - q) / se
            res["within_band"][lev][name] = bool(abs(h / n - q) <= BANDS[lev])
            res["wald_rates"][lev][name] = wald / n
    res["pull_mean"], res["pull_sd"], res["sd_over_se"], res["median_minus_ml_over_se"] = (
        {}, {}, {}, {})
    for name in NAMES:
        pulls = np.array([(r[name]["q"][2] - r[name]["truth"]) / r[name]["sd"] for r in rows])
        ratio = np.array([r[name]["sd"] / r[name]["se"] for r in rows])
        dmed = np.array([(r[name]["q"][2] - r[name]["ml"]) / r[name]["se"] for r in rows])
        res["pull_mean"][name] = float(np.mean(pulls))
        res["pull_sd"][name] = float(np.std(pulls, ddof=1))
        res["sd_over_se"][name] = {"mean": float(np.mean(ratio)), "min": float(np.min(ratio)),
                                   "max": float(np.max(ratio))}
        res["median_minus_ml_over_se"][name] = {"mean": float(np.mean(dmed)),
                                                "min": float(np.min(dmed)),
                                                "max": float(np.max(dmed))}
    res["max_tau_mean"] = float(np.mean([r["max_tau"] for r in rows]))
    res["max_tau_max"] = float(np.max([r["max_tau"] for r in rows]))
    res["min_ess_mean"] = float(np.mean([r["min_ess"] for r in rows]))
    res["min_ess_min"] = float(np.min([r["min_ess"] for r in rows]))
    res["acceptance_mean"] = float(np.mean([r["acceptance"] for r in rows]))
    res["short_chain_warnings"] = int(sum(r["short_chain_warning"] for r in rows))
    res["wall_s_per_dataset_mean"] = float(np.mean([r["wall_s"] for r in rows]))
    return res


def markdown(cov: dict) -> str:
    lines = ["| quantity | 68 % coverage | 95 % coverage | Wald (ML +- SE) 68 % / 95 % |",
             "|---|---|---|---|"]
    for n in NAMES:
        cells = []
        for lev in ("0.68", "0.95"):
            r, z, h = cov["rates"][lev][n], cov["z"][lev][n], cov["hits"][lev][n]
            ok = "in band" if cov["within_band"][lev][n] else "OUT of band"
            cells.append(f"{r:.3f} ({h}/{cov['n_datasets']}, {z:+.1f} SE, {ok})")
        wald = f"{cov['wald_rates']['0.68'][n]:.3f} / {cov['wald_rates']['0.95'][n]:.3f}"
        lines.append(f"| {n} | {cells[0]} | {cells[1]} | {wald} |")
    lines.append(f"\nbinomial SE: 68 %: {cov['binomial_se']['0.68']:.3f}, "
                 f"95 %: {cov['binomial_se']['0.95']:.3f}")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", type=int, default=200, help="0: timing only")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--out", default="benchmarks/out")
    ap.add_argument("--skip-timing", action="store_true")
    ap.add_argument("--timing-steps", type=int, default=2000,
                    help="steps of the 32-walker timing runs (smoke runs: fewer)")
    a = ap.parse_args(argv)
    blurtrap.enable_x64()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    res = {"machine": machine_info()}
    print(json.dumps(res["machine"], indent=1), flush=True)
    if not a.skip_timing:
        res["timing"] = timing_study(a.timing_steps)
        print(json.dumps(res["timing"], indent=1), flush=True)
        (out / "posterior_study.json").write_text(json.dumps(res, indent=1))
    if a.datasets > 0:
        t0 = time.perf_counter()
        rows = coverage_study(a.datasets, a.steps, out)
        res["coverage"] = summarise(rows)
        res["coverage"]["wall_s_this_run"] = time.perf_counter() - t0
    res["machine"]["load_average_end"] = os.getloadavg()
    (out / "posterior_study.json").write_text(json.dumps(res, indent=1))
    if a.datasets > 0:
        print(json.dumps(res["coverage"], indent=1))
        print(markdown(res["coverage"]))


if __name__ == "__main__":
    main()
