"""Monte-Carlo study of errors and intervals at the boundary eps^2 = 0 (not a test).

Run:  python benchmarks/study_boundary.py run --regime whittle --n 1000 --out b_whittle.npz
      python benchmarks/study_boundary.py run --regime exact --n 1000 --out b_exact.npz
      python benchmarks/study_boundary.py report b_whittle.npz b_exact.npz

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
def run(regime, n, out, seed, every=25):
    import blurtrap as bt

    bt.enable_x64()
    warnings.simplefilter("ignore")
    n_frames, kw = REGIMES[regime]
    sampler = CirculantSampler(autocovariance(K, GAMMA, W, DT, EPS2, n_frames))
    rng = np.random.default_rng(seed)
    rows = {key: [] for key in ("val", "err", "lo", "hi", "profiled", "bound", "unc",
                                "t_fit", "t_int", "ok")}
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
            ivs, kinds = fit.intervals, fit.interval_kinds
            t2 = time.perf_counter()
            rows["val"].append([fit.params[nm] for nm in NAMES])
            rows["err"].append([float(fit.errors[fit.param_names.index(nm)]) for nm in NAMES])
            rows["lo"].append([ivs[nm][0] for nm in NAMES])
            rows["hi"].append([ivs[nm][1] for nm in NAMES])
            rows["profiled"].append([kinds[nm] == "profile" for nm in NAMES])
            rows["bound"].append([nm in fit.at_bounds for nm in NAMES])
            rows["unc"].append(unconstrained_whittle(rec, fit) if regime == "whittle"
                               else np.full(3, np.nan))
            rows["t_fit"].append(t1 - t0)
            rows["t_int"].append(t2 - t1)
            rows["ok"].append(True)
        done += len(batch)
        np.savez(out, regime=regime, n_frames=n_frames, seed=seed,
                 wall=time.time() - t_start,
                 **{key: np.asarray(v) for key, v in rows.items()})
        print(f"{regime}: {done}/{n} datasets, {time.time() - t_start:.0f} s", flush=True)


# ------------------------------------------------------------------------------------------
# batched (vmapped) Whittle path: the same fit and interval code as calibrate, many records
# per compiled call
# ------------------------------------------------------------------------------------------
def _batch_functions():
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from blurtrap.inference import _profile
    from blurtrap.inference._fit import _newton
    from blurtrap.inference._problems import spectral_nll

    def with_data(shared, pw, lr):
        return eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw, lr))

    @eqx.filter_jit
    def profiles(shared, power, log_ref, scale, x_hat, cov, at_bound):
        def one(pw, lr, s, xh, c, ab):
            return _profile._profile_ends(spectral_nll, with_data(shared, pw, lr), s, xh, c,
                                          ab, "auto")

        return jax.vmap(one)(power, log_ref, scale, x_hat, cov, at_bound)

    @eqx.filter_jit
    def unconstrained(shared, power, log_ref, start, off):
        def one(pw, lr, s):
            x_hat, _, _, _, _, ok, _ = _newton(_shifted_nll, s, (with_data(shared, pw, lr), off),
                                               1e-9, 1e-9, 64)
            return jnp.where(ok, s * jnp.exp(x_hat) - off, jnp.nan)

        return jax.vmap(one)(power, log_ref, start)

    return profiles, unconstrained


def run_batched(n, out, seed, chunk=32):
    """Whittle regime, ``chunk`` records per vmapped call: fits as ``calibrate_batch`` (its
    own vmapped Newton fit, same objective, start values and bound rule as ``calibrate``),
    intervals as ``CalibrationResult.intervals`` (profile where ``needs_profile`` says so,
    else Wald), profiles of all records of a chunk in one vmapped call."""
    import equinox as eqx
    import jax.numpy as jnp

    import blurtrap as bt
    from blurtrap.inference import _batch, _profile
    from blurtrap.inference._fit import fit_ml
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import RecMeta, SpectralArgs, make_layout, spectral_nll

    bt.enable_x64()
    warnings.simplefilter("ignore")
    n_frames = REGIMES["whittle"][0]
    sampler = CirculantSampler(autocovariance(K, GAMMA, W, DT, EPS2, n_frames))
    rng = np.random.default_rng(seed)
    mdl = get_model("standard")
    m = n_frames
    f = np.arange(1, m // 2 + 1) / (m * DT)
    weight = np.full(f.shape, 1.0)
    weight[-1] = 0.5
    layout = make_layout([_batch._Rec(DT, W, T)], "shared", True)
    shared = SpectralArgs(
        layout=layout, model=mdl,
        meta=RecMeta(dt=jnp.asarray([DT]), w=jnp.asarray([W]), temp=jnp.asarray([T])),
        f=jnp.asarray(f[None]), s2=jnp.asarray(np.sin(np.pi * f * DT)[None] ** 2),
        power=jnp.zeros((1, f.size)), weight=jnp.asarray(weight[None]),
        log_ref=jnp.asarray(0.0), block_len=jnp.asarray([float(m)]))
    profiles, unconstrained = _batch_functions()
    off = jnp.array([0.0, 0.0, 4.0 * EPS2])
    rows = {key: [] for key in ("val", "err", "lo", "hi", "profiled", "bound", "unc", "ok")}
    t_start = time.time()
    done = 0
    while done < n:
        y = sampler.draw(rng, min(chunk, n - done))
        b = len(y)
        power, starts, log_ref = _batch._prepare(y, np.zeros(b, bool), 1, m, DT, W, T, True)
        pw, lr, st = jnp.asarray(power[:, None, :]), jnp.asarray(log_ref), jnp.asarray(starts)
        fo = _batch._batch_fit(st, pw, lr, shared)
        val, cov = np.array(fo.value), np.array(fo.cov)
        bound, success = np.array(fo.at_bound), np.array(fo.success)
        for i in np.flatnonzero(~success):  # as calibrate_batch: refit alone
            a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw[i], lr[i]))
            one = fit_ml(spectral_nll, st[i], a)
            val[i], cov[i] = np.asarray(one.value), np.asarray(one.cov)
            bound[i], success[i] = np.asarray(one.at_bound), bool(one.success)
        x_hat = np.maximum(np.log(np.maximum(val, 1e-300) / starts), _profile._LOG_ZERO)
        low, high, ok_lo, ok_hi, _ = profiles(shared, pw, lr, st, jnp.asarray(x_hat),
                                              jnp.asarray(np.nan_to_num(cov)),
                                              jnp.asarray(bound))
        low, high = np.asarray(low), np.asarray(high)
        okp = np.asarray(ok_lo) & np.asarray(ok_hi)
        unc = np.asarray(unconstrained(shared, pw, lr, jnp.asarray(val) + off, off))
        for i in range(b):
            err = np.sqrt(np.diag(cov[i]))
            need = _profile.needs_profile(
                spectral_nll, eqx.tree_at(lambda z: (z.power, z.log_ref), shared,
                                          (pw[i], lr[i])), val[i], cov[i], bound[i])
            lo = np.where(need, np.where(okp[i], low[i], np.nan), val[i] - 1.959964 * err)
            hi = np.where(need, np.where(okp[i], high[i], np.nan), val[i] + 1.959964 * err)
            rows["val"].append(val[i])
            rows["err"].append(err)
            rows["lo"].append(lo)
            rows["hi"].append(hi)
            rows["profiled"].append(need)
            rows["bound"].append(bound[i])
            rows["unc"].append(unc[i])
            rows["ok"].append(bool(success[i]))
        done += b
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
              f"({(~ok).sum()} FitError), seed {int(d['seed'])}, {float(d['wall']):.0f} s\n")
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
    p = sub.add_parser("report")
    p.add_argument("paths", nargs="+")
    a = ap.parse_args(argv)
    if a.cmd == "run" and a.batched:
        if a.regime != "whittle":
            ap.error("--batched is for the whittle regime")
        run_batched(a.n, a.out, a.seed)
    elif a.cmd == "run":
        run(a.regime, a.n, a.out, a.seed)
    else:
        report(a.paths)


if __name__ == "__main__":
    main()
