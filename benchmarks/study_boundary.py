"""Monte-Carlo study of errors and intervals at the boundary eps^2 = 0 (not a test).

Run:  python benchmarks/study_boundary.py run --regime whittle --n 1000 --out b_whittle.npz
      python benchmarks/study_boundary.py run --regime exact --n 1000 --out b_exact.npz
      python benchmarks/study_boundary.py report b_whittle.npz b_exact.npz
      python benchmarks/study_boundary.py merge b_exact.npz b_exact_1.npz b_exact_2.npz
      python benchmarks/study_boundary.py compare before.npz after.npz  # Wald, same data

Camera 1500 fps, exposure W = 0.1 dt, eps = 2 nm, k = 0.05 pN/nm, bead radius 1.53 um in water
(gamma = 6 pi 0.00093 Pa s 1.53 um), T = 295 K: eps^2 ends at its bound in ~12 % of the
65 536-frame fits. Regimes: ``whittle`` (65 536 frames, ``calibrate`` default: Whittle
likelihood) and ``exact`` (4096 frames, ``likelihood="exact"``).

The frames are NOT made by blurtrap's simulator: a stationary Gaussian sequence with the exact
autocovariance C(0) = sigma2 S(alpha) + eps2, C(n) = sigma2 B(alpha) rho^n (n >= 1),
B = 2 (cosh(alpha) - 1)/alpha^2, S = 2/alpha - 2 (1 - exp(-alpha))/alpha^2, sampled by circulant
embedding with numpy's FFT (two independent records per FFT: real and imaginary parts).

Per dataset: estimates, reported SEs, ``at_bounds``, ``result.intervals`` and their kinds
(timed on first access), and for the Whittle regime the *unconstrained* maximum-likelihood
estimate (eps^2 allowed below 0 as long as every PSD ordinate stays positive; shifted
parameter eps2 + offset) to tell the bias the bound causes from the estimator's own.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings

import numpy as np

KB = 1.380649e-23
T = 295.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1.0 / 1500.0
W = 0.1 * DT
EPS2 = (2e-9) ** 2
K = 5e-5
TRUE = {"k": K, "gamma": GAMMA, "tracking_var": EPS2}
NAMES = ("k", "gamma", "tracking_var")
#: the per-dataset rows of a run (``run``; ``run_batched`` leaves out the timings)
_ROWS = ("val", "err", "lo", "hi", "profiled", "bound", "unc", "t_fit", "t_int", "ok")
REGIMES = {"whittle": (65536, {"method": "likelihood"}),
           "exact": (4096, {"method": "likelihood", "likelihood": "exact"})}


# ------------------------------------------------------------------------------------------
# independent generator (numpy only)
# ------------------------------------------------------------------------------------------
def autocovariance(k, gamma, w, dt, eps2, n, temp=T):
    """C(0..n) of blurred, sampled, noisy frames (DESIGN section 2 item 5), numpy."""
    s2 = KB * temp / k
    tau = gamma / k
    a = w / tau
    s = 2 / a - 2 * (1 - math.exp(-a)) / a**2 if a > 1e-3 else 1 - a / 3 + a * a / 12
    b = 2 * (math.cosh(a) - 1) / a**2
    c = s2 * b * math.exp(-dt / tau) ** np.arange(n + 1)
    c[0] = s2 * s + eps2
    return c


class CirculantSampler:
    """Exact stationary Gaussian frames with autocovariance ``c[0..n-1]`` by circulant
    embedding (size 2(n-1)+2 = 2n): eigenvalues by FFT, checked non-negative."""

    def __init__(self, c):
        self.n = c.size - 1
        ext = np.concatenate([c, c[-2:0:-1]])
        lam = np.fft.fft(ext).real
        if lam.min() < -1e-10 * lam.max():
            raise ValueError(f"circulant embedding not non-negative: min eigenvalue {lam.min()}")
        self.amp = np.sqrt(np.maximum(lam, 0.0) / ext.size)

    def draw(self, rng, m):
        out = []
        while len(out) < m:
            z = rng.standard_normal(self.amp.size) + 1j * rng.standard_normal(self.amp.size)
            y = np.fft.fft(self.amp * z)
            out += [y.real[: self.n], y.imag[: self.n]]
        return np.array(out[:m])


# ------------------------------------------------------------------------------------------
# unconstrained MLE (Whittle): eps^2 + offset as the positive parameter
# ------------------------------------------------------------------------------------------
def _shifted_nll(p, a):
    from blurtrap.inference._problems import spectral_nll

    args, off = a
    return spectral_nll(p - off, args)


def unconstrained_whittle(rec, fit):
    """Whittle MLE with eps^2 free to go below 0: (k, gamma, eps2) or NaNs."""
    import jax.numpy as jnp

    from blurtrap.inference._fit import fit_ml
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import make_layout
    from blurtrap.inference._spectral import _spectral_args

    mdl = get_model("standard")
    layout = make_layout([rec], "shared", True)
    args = _spectral_args([rec], layout, mdl, 1, None)
    off = jnp.array([0.0, 0.0, 4.0 * EPS2])
    v = np.asarray(fit.values, float).copy()
    start = jnp.asarray(v) + off
    out = fit_ml(_shifted_nll, start, (args, off))
    if not bool(out.success):
        return np.full(3, np.nan)
    return np.asarray(out.value - off)


# ------------------------------------------------------------------------------------------
def run(regime, n, out, seed, every=25, wald_only=False):
    """``calibrate`` per dataset; ``wald_only``: no intervals and no unconstrained refit
    (values, reported errors and bound flags only)."""
    import blurtrap as bt

    bt.enable_x64()
    warnings.simplefilter("ignore")
    n_frames, kw = REGIMES[regime]
    sampler = CirculantSampler(autocovariance(K, GAMMA, W, DT, EPS2, n_frames))
    rng = np.random.default_rng(seed)
    rows = {key: [] for key in _ROWS}
    t_start = time.time()
    done = 0
    while done < n:
        batch = sampler.draw(rng, min(every, n - done))
        for y in batch:
            rec = bt.Recording(y, frame_interval=DT, exposure=W, temperature=T)
            t0 = time.perf_counter()
            try:
                fit = bt.calibrate(rec, **kw)
            except bt.FitError as e:  # counted, never silently dropped
                print("FitError:", str(e)[:120], file=sys.stderr)
                for key, shape in (("val", 3), ("err", 3), ("lo", 3), ("hi", 3),
                                   ("unc", 3)):
                    rows[key].append(np.full(shape, np.nan))
                rows["profiled"].append(np.zeros(3, bool))
                rows["bound"].append(np.zeros(3, bool))
                rows["t_fit"].append(np.nan)
                rows["t_int"].append(np.nan)
                rows["ok"].append(False)
                continue
            t1 = time.perf_counter()
            if wald_only:
                ivs = {nm: (np.nan, np.nan) for nm in NAMES}
                kinds = {nm: "none" for nm in NAMES}
            else:
                ivs, kinds = fit.intervals, fit.interval_kinds
            t2 = time.perf_counter()
            rows["val"].append([fit.params[nm] for nm in NAMES])
            rows["err"].append([float(fit.errors[fit.param_names.index(nm)]) for nm in NAMES])
            rows["lo"].append([ivs[nm][0] for nm in NAMES])
            rows["hi"].append([ivs[nm][1] for nm in NAMES])
            rows["profiled"].append([kinds[nm] == "profile" for nm in NAMES])
            rows["bound"].append([nm in fit.at_bounds for nm in NAMES])
            rows["unc"].append(unconstrained_whittle(rec, fit)
                               if regime == "whittle" and not wald_only else np.full(3, np.nan))
            rows["t_fit"].append(t1 - t0)
            rows["t_int"].append(t2 - t1)
            rows["ok"].append(True)
        done += len(batch)
        np.savez(out, regime=regime, n_frames=n_frames, seed=seed,
                 wall=time.time() - t_start,
                 **{key: np.asarray(v) for key, v in rows.items()})
        print(f"{regime}: {done}/{n} datasets, {time.time() - t_start:.0f} s", flush=True)


# ------------------------------------------------------------------------------------------
# batched (vmapped) Whittle path: the public calibrate_batch (same objective, start values,
# bound rule and at-bound errors as calibrate), Wald errors only
# ------------------------------------------------------------------------------------------
def run_batched(n, out, seed, chunk=64):
    """Whittle regime, ``chunk`` records per ``bt.calibrate_batch`` call: values, reported
    errors, ``at_bound`` and status per record. No intervals (``calibrate``'s
    ``result.intervals`` are unchanged by the batch; see ``run``)."""
    import blurtrap as bt

    bt.enable_x64()
    warnings.simplefilter("ignore")
    n_frames = REGIMES["whittle"][0]
    sampler = CirculantSampler(autocovariance(K, GAMMA, W, DT, EPS2, n_frames))
    rng = np.random.default_rng(seed)
    rows = {key: [] for key in ("val", "err", "lo", "hi", "profiled", "bound", "unc", "ok")}
    t_start = time.time()
    done = 0
    while done < n:
        y = sampler.draw(rng, min(chunk, n - done))
        b = bt.calibrate_batch(y, frame_interval=DT, exposure=W, temperature=T)
        val = np.stack([b.k, b.gamma, b.tracking_var], axis=1)
        err = np.stack([b.k_err, b.gamma_err, b.tracking_var_err], axis=1)
        for i in range(len(y)):
            rows["val"].append(val[i])
            rows["err"].append(err[i])
            rows["lo"].append(np.full(3, np.nan))
            rows["hi"].append(np.full(3, np.nan))
            rows["profiled"].append(np.zeros(3, bool))
            rows["bound"].append(np.array([False, False, bool(b.at_bound[i])]))
            rows["unc"].append(np.full(3, np.nan))
            rows["ok"].append(bool(b.success[i]))
        done += len(y)
        np.savez(out, regime="whittle", n_frames=n_frames, seed=seed,
                 wall=time.time() - t_start, t_fit=np.full(1, np.nan),
                 t_int=np.full(1, np.nan), **{key: np.asarray(v) for key, v in rows.items()})
        print(f"whittle (batched): {done}/{n} datasets, {time.time() - t_start:.0f} s",
              flush=True)


# ------------------------------------------------------------------------------------------
def _cov(lo, hi, truth):
    ok = np.isfinite(lo) & np.isfinite(hi)
    hit = ok & (lo <= truth) & (truth <= hi)
    return hit.mean(), ok.mean()


def report(paths):
    for path in paths:
        d = np.load(path, allow_pickle=False)
        ok = d["ok"]
        val, err, lo, hi = d["val"][ok], d["err"][ok], d["lo"][ok], d["hi"][ok]
        bound, prof, unc = d["bound"][ok], d["profiled"][ok], d["unc"][ok]
        m = len(val)
        fb = bound[:, 2].mean()
        print(f"\n### {d['regime']}: {int(d['n_frames'])} frames, {m} datasets "
              f"({(~ok).sum()} FitError), seed(s) "
              f"{[int(x) for x in d['seeds']] if 'seeds' in d else int(d['seed'])}, "
              f"{float(d['wall']):.0f} s\n")
        print(f"eps^2 at its bound: {fb * 100:.1f} % +- {100 * math.sqrt(fb * (1 - fb) / m):.1f} %;"
              f" fit {np.nanmedian(d['t_fit']) * 1e3:.0f} ms, intervals "
              f"{np.nanmedian(d['t_int']) * 1e3:.0f} ms (medians)\n")
        cse = 100 * math.sqrt(0.95 * 0.05 / m)
        print("| parameter | bias % (MC SE) | SD/SE | SD/SE interior / at bound | Wald "
              "coverage | interval coverage | profiled | interval bias-free check |")
        print("|---|---|---|---|---|---|---|---|")
        for j, nm in enumerate(NAMES):
            t = TRUE[nm]
            rel = val[:, j] / t - 1
            bias, bse = 100 * rel.mean(), 100 * rel.std(ddof=1) / math.sqrt(m)
            sd = val[:, j].std(ddof=1)
            fin = np.isfinite(err[:, j])
            se = np.mean(err[fin, j])
            b = bound[:, 2]
            sdse_in = val[~b, j].std(ddof=1) / np.mean(err[~b, j]) if (~b).sum() > 2 else np.nan
            sdse_b = (val[b, j].std(ddof=1) / np.nanmean(err[b, j])
                      if b.sum() > 2 and np.isfinite(err[b, j]).any() else np.nan)
            wl, wh = val[:, j] - 1.959964 * err[:, j], val[:, j] + 1.959964 * err[:, j]
            wc, wf = _cov(wl, wh, t)
            ic, icf = _cov(lo[:, j], hi[:, j], t)
            below = np.mean(t < lo[:, j]) * 100
            above = np.mean(t > hi[:, j]) * 100
            print(f"| {nm} | {bias:+.2f} ({bse:.2f}) | {sd / se:.3f} | {sdse_in:.3f} / "
                  f"{sdse_b:.3f} | {100 * wc:.1f} (finite {100 * wf:.0f} %) | "
                  f"{100 * ic:.1f} | {100 * prof[:, j].mean():.0f} % | "
                  f"misses low {below:.1f} / high {above:.1f} % |")
        print(f"\nMC SE of a 95 % coverage: {cse:.1f} points.")
        if np.isfinite(unc).all(axis=1).any():
            u = np.isfinite(unc).all(axis=1)
            print("\nUnconstrained Whittle MLE (eps^2 may go below 0), same datasets:\n")
            print("| parameter | bias % unconstrained (MC SE) | bias % constrained | "
                  "constrained - unconstrained, mean over at-bound fits x fraction |")
            print("|---|---|---|---|")
            for j, nm in enumerate(NAMES):
                t = TRUE[nm]
                ru = unc[u, j] / t - 1
                rc = val[u, j] / t - 1
                diff = (val[u, j] - unc[u, j]) / t
                print(f"| {nm} | {100 * ru.mean():+.2f} ({100 * ru.std(ddof=1) / math.sqrt(u.sum()):.2f})"
                      f" | {100 * rc.mean():+.2f} | {100 * diff.mean():+.3f} |")
            neg = (unc[u, 2] < 0).mean()
            print(f"\nunconstrained eps^2 < 0 in {100 * neg:.1f} % of the fits")


def compare(before, after):
    """Wald coverage with the errors of two runs on the same datasets (same seed and size):
    ``before`` and ``after`` a change of the reported errors. The estimates must agree."""
    d0, d1 = np.load(before, allow_pickle=False), np.load(after, allow_pickle=False)
    m = min(len(d0["ok"]), len(d1["ok"]))
    ok = d0["ok"][:m] & d1["ok"][:m]
    v0, v1 = d0["val"][:m][ok], d1["val"][:m][ok]
    if not np.allclose(v0, v1, rtol=1e-6, atol=0):
        print(f"WARNING: estimates differ (max rel {np.nanmax(np.abs(v1 / v0 - 1)):.2g})")
    bound = d1["bound"][:m][ok][:, 2]
    n, nb = len(v1), int(bound.sum())
    print(f"\n### {d1['regime']}: {int(d1['n_frames'])} frames, {n} datasets, eps^2 at its "
          f"bound in {nb} ({100 * nb / n:.1f} %)\n")
    print(f"| parameter | errors | Wald coverage % (all) | at bound (n = {nb}) | interior | "
          "mean SE at bound / interior | SD / mean SE |")
    print("|---|---|---|---|---|---|---|")
    for j, nm in enumerate(NAMES[:2]):
        t = TRUE[nm]
        for label, d in (("before", d0), ("after", d1)):
            err = d["err"][:m][ok][:, j]
            hit = np.abs(v1[:, j] - t) <= 1.959964 * err  # NaN error: a miss
            sd = v1[:, j].std(ddof=1)
            print(f"| {nm} | {label} | {100 * hit.mean():.1f} | "
                  f"{100 * hit[bound].mean() if nb else math.nan:.1f} | "
                  f"{100 * hit[~bound].mean():.1f} | "
                  f"{np.mean(err[bound]) / np.mean(err[~bound]) if nb else math.nan:.3f} | "
                  f"{sd / np.mean(err):.3f} |")
    print(f"\nMC SE of a 95 % coverage: {100 * math.sqrt(0.95 * 0.05 / n):.1f} points "
          f"(all), {100 * math.sqrt(0.95 * 0.05 / max(nb, 1)):.1f} (at bound).")


def merge(out, paths):
    """Runs of one regime with different seeds (e.g. one per core) as one file: the rows
    concatenated, the wall times summed, the first seed kept (all listed in ``seeds``)."""
    ds = [np.load(p, allow_pickle=False) for p in paths]
    regimes = {str(d["regime"]) for d in ds}
    if len(regimes) != 1:
        raise SystemExit(f"merge: runs of different regimes {sorted(regimes)}")
    seeds = [int(d["seed"]) for d in ds]
    if len(set(seeds)) != len(seeds):
        raise SystemExit(f"merge: the same seed twice {seeds} (the same datasets)")
    np.savez(out, regime=ds[0]["regime"], n_frames=ds[0]["n_frames"], seed=seeds[0],
             seeds=np.asarray(seeds), wall=sum(float(d["wall"]) for d in ds),
             **{key: np.concatenate([d[key] for d in ds]) for key in _ROWS})
    print(f"{out}: {sum(len(d['ok']) for d in ds)} datasets from seeds {seeds}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--regime", choices=sorted(REGIMES), required=True)
    r.add_argument("--n", type=int, default=1000)
    r.add_argument("--seed", type=int, default=20261125)
    r.add_argument("--out", required=True)
    r.add_argument("--batched", action="store_true",
                   help="whittle regime only: vmapped fits and profiles (same code paths)")
    r.add_argument("--wald-only", action="store_true",
                   help="no intervals and no unconstrained refit (errors only)")
    p = sub.add_parser("report")
    p.add_argument("paths", nargs="+")
    m = sub.add_parser("merge", help="runs of one regime with different seeds as one file")
    m.add_argument("out")
    m.add_argument("paths", nargs="+")
    c = sub.add_parser("compare", help="Wald coverage before/after on the same datasets")
    c.add_argument("before")
    c.add_argument("after")
    a = ap.parse_args(argv)
    if a.cmd == "run" and a.batched:
        if a.regime != "whittle":
            ap.error("--batched is for the whittle regime")
        run_batched(a.n, a.out, a.seed)
    elif a.cmd == "run":
        run(a.regime, a.n, a.out, a.seed, wald_only=a.wald_only)
    elif a.cmd == "merge":
        merge(a.out, a.paths)
    elif a.cmd == "compare":
        compare(a.before, a.after)
    else:
        report(a.paths)


if __name__ == "__main__":
    main()
