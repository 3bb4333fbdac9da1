"""Monte-Carlo validation study of blurtrap's calibration layer (not a test).

Run:  python benchmarks/study_calibration.py [--quick] [--seeds 400] [--exact-seeds 100]
                                             [--grid-seeds 200] [--fig benchmarks/calibration_study.png]

Simulated camera data (exact frame sampler): 1500 fps, W = dt, 65 536 frames, tracking error
eps = 2 nm, bead radius 1.53 um in water (gamma = 6 pi 0.00093 Pa s 1.53 um), T = 295 K,
k = 0.01 and 0.05 pN/nm. For every method: bias of k and gamma (% and in Monte-Carlo SE),
observed SD, mean reported SE / observed SD; efficiency against the Cramer-Rao bound (CRB) from
the expected Fisher information, computed independently of the package's fitting code:

- Whittle expected Fisher  F = sum_j w_j (dlog P_j/dtheta)(dlog P_j/dtheta)^T over the Fourier
  frequencies j/(N dt), j = 1..N/2 (w = 1/2 at Nyquist), with jax.jacfwd of
  blurtrap.psd_measured (closed-form aliased PSD), theta = (k, gamma, eps2);
- checked against the exact Gaussian Fisher  F_ab = 1/2 tr(S^-1 S_a S^-1 S_b)  of the dense
  Toeplitz covariance at a small N (numpy, finite-difference derivatives of the autocovariance).

Prints markdown tables (pasted into benchmarks/RESULTS_calibration.md) and saves a figure.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import blurtrap as bt
from blurtrap.physics._constants import BOLTZMANN, DEFAULT_TEMPERATURE

bt.enable_x64()

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6  # N s/m
DT = 1.0 / 1500.0
EPS = 2e-9  # m
EPS2 = EPS**2
N_FRAMES = 65536
T = DEFAULT_TEMPERATURE
KT = BOLTZMANN * T

METHODS = [  # label, calibrate kwargs (None = calibrate_batch)
    ("default (Whittle)", None),
    ("exact likelihood", dict(method="likelihood", likelihood="exact")),
    ("blocked PSD, standard", dict(method="psd")),
    ("blocked PSD, standard, 16 blocks", dict(method="psd", n_blocks=16)),
    ("blocked PSD, naive", dict(method="psd", model="naive")),
    ("blocked PSD, naive_aliased", dict(method="psd", model="naive_aliased")),
    ("naive equipartition", dict(method="equipartition")),
]


# ------------------------------------------------------------------------------------------
# Cramer-Rao bound
# ------------------------------------------------------------------------------------------
def whittle_fisher(k, gamma, eps2, w, dt, n):
    """Expected Whittle Fisher information of (k, gamma, eps2) for n frames."""
    m = n // 2
    f = jnp.arange(1, m + 1) / (n * dt)
    wt = jnp.ones(m).at[-1].set(0.5 if n % 2 == 0 else 1.0)
    theta0 = jnp.array([k, gamma, eps2])
    scale = theta0  # differentiate in relative units for conditioning

    def logp(u):
        th = u * scale
        return jnp.log(bt.psd_measured(f, th[0], th[1], w, T, frame_interval=dt,
                                       tracking_var=th[2]))

    with jax.enable_x64(True):
        g = jax.jacfwd(logp)(jnp.ones(3))  # (m, 3), d log P / d log theta
        fish_rel = (g * wt[:, None]).T @ g
    fish_rel = np.asarray(fish_rel)
    s = np.asarray(scale)
    return fish_rel / np.outer(s, s)  # natural units


def crb(k, gamma, eps2, w, dt, n):
    """Relative CRB (fraction) of k, gamma, eps2."""
    cov = np.linalg.inv(whittle_fisher(k, gamma, eps2, w, dt, n))
    return np.sqrt(np.diag(cov)) / np.array([k, gamma, eps2])


def _acov_np(k, gamma, eps2, w, dt, n):
    """Frame autocovariance C(0..n-1) from DESIGN item 5, written in numpy."""
    sigma2 = KT / k
    tau = gamma / k
    a, r = w / tau, dt / tau
    s = 2 / a - 2 * (-math.expm1(-a)) / a**2
    b = (math.sinh(a / 2) / (a / 2)) ** 2
    c = sigma2 * b * np.exp(-r * np.arange(n))
    c[0] = sigma2 * s + eps2
    return c


def exact_fisher_dense(k, gamma, eps2, w, dt, n):
    """Exact Gaussian Fisher of (k, gamma, eps2), known zero mean, dense Toeplitz (numpy)."""
    from scipy.linalg import toeplitz

    th = np.array([k, gamma, eps2])
    sig = toeplitz(_acov_np(*th, w, dt, n))
    sinv = np.linalg.inv(sig)
    ders = []
    for i in range(3):
        h = th[i] * 1e-5
        tp, tm = th.copy(), th.copy()
        tp[i] += h
        tm[i] -= h
        ders.append(sinv @ ((toeplitz(_acov_np(*tp, w, dt, n))
                             - toeplitz(_acov_np(*tm, w, dt, n))) / (2 * h)))
    fish = np.array([[0.5 * np.sum(ders[a] * ders[b].T) for b in range(3)] for a in range(3)])
    return fish


# ------------------------------------------------------------------------------------------
# simulation and fitting
# ------------------------------------------------------------------------------------------
def simulate(k, w, n_traces, seed, chunk=100):
    out = []
    for i, start in enumerate(range(0, n_traces, chunk)):
        b = min(chunk, n_traces - start)
        y = bt.simulate(k, GAMMA, w, DT, N_FRAMES, key=jax.random.key(seed * 1000 + i),
                        method="exact_frames", tracking_std=EPS, n_traces=b)
        out.append(np.asarray(y, dtype=np.float64))
    return np.concatenate(out, axis=0)


def fit_method(y, w, kwargs, n_max):
    """Return arrays k, k_err, gamma, gamma_err (NaN where a fit failed) and #failures."""
    n = min(n_max, y.shape[0])
    if kwargs is None:
        b = bt.calibrate_batch(y[:n], frame_interval=DT, exposure=w)
        bad = ~b.success
        res = np.stack([b.k, b.k_err, b.gamma, b.gamma_err, b.tracking_var,
                        b.tracking_var_err], 1)
        res[bad] = np.nan
        return res, int(bad.sum())
    res = np.full((n, 6), np.nan)
    fails = 0
    for i in range(n):
        rec = bt.Recording(y[i], frame_interval=DT, exposure=w)
        try:
            r = bt.calibrate(rec, **kwargs)
        except bt.FitError:
            fails += 1
            continue
        res[i] = [r.k, r.k_err, r.gamma, r.gamma_err, r.tracking_var, r.tracking_var_err]
    return res, fails


def summarise(vals, errs, true, crb_rel=None):
    ok = np.isfinite(vals)
    v, e = vals[ok], errs[ok]
    n = v.size
    mean, sd = v.mean(), v.std(ddof=1)
    mcse = sd / math.sqrt(n)
    out = dict(n=n, bias_pct=100 * (mean - true) / true, bias_z=(mean - true) / mcse,
               sd_pct=100 * sd / true, se_sd=float(np.mean(e)) / sd if np.all(np.isfinite(e))
               else float("nan"), se_sd_err=1.0 / math.sqrt(2 * (n - 1)),
               mcse_pct=100 * mcse / true,
               se_sd_med=float(np.median(e)) / sd if np.all(np.isfinite(e)) else float("nan"))
    if crb_rel is not None:
        out["crb_pct"] = 100 * crb_rel
        out["sd_crb"] = out["sd_pct"] / out["crb_pct"]
    return out


def fmt(x, p=2):
    return "—" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{p}f}"


# ------------------------------------------------------------------------------------------
def main(argv=None):
    global N_FRAMES
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="few seeds (smoke run, ~2 min)")
    ap.add_argument("--seeds", type=int, default=300, help="seeds per k for the loop methods")
    ap.add_argument("--default-seeds", type=int, default=1000,
                    help="seeds per k for the default method (calibrate_batch; cheap)")
    ap.add_argument("--exact-seeds", type=int, default=100)
    ap.add_argument("--grid-seeds", type=int, default=200)
    ap.add_argument("--fig", default="benchmarks/calibration_study.png")
    ap.add_argument("--frames", type=int, default=N_FRAMES, help="frames per recording")
    ap.add_argument("--smoke", action="store_true",
                    help="every code path at the smallest sizes (8192 frames, 2-5 seeds); the "
                         "numbers are meaningless")
    a = ap.parse_args(argv)
    if a.quick:
        a.seeds, a.default_seeds, a.exact_seeds, a.grid_seeds = 40, 60, 8, 40
    if a.smoke:  # >= 5 default seeds: the batch-vs-single check uses 5 rows
        a.seeds, a.default_seeds, a.exact_seeds, a.grid_seeds, a.frames = 3, 5, 2, 3, 8192
    N_FRAMES = a.frames
    nf = f"{N_FRAMES:,}".replace(",", " ")
    a.default_seeds = max(a.default_seeds, a.seeds)
    warnings.simplefilter("ignore", bt.SubstepBiasWarning)
    t_start = time.time()
    print(f"# study_calibration: seeds={a.seeds} default_seeds={a.default_seeds} exact_seeds={a.exact_seeds} "
          f"grid_seeds={a.grid_seeds}, N={N_FRAMES}, dt=W={DT:.6g} s, eps={EPS:.1e} m, "
          f"gamma={GAMMA:.5e} N s/m, T={T} K")

    # ---- CRB cross-check: Whittle expected Fisher vs exact dense Fisher at small N ----------
    print("\n## CRB check: Whittle expected Fisher vs exact dense Toeplitz Fisher\n")
    print("| k [pN/nm] | N | CRB k, Whittle [%] | CRB k, exact [%] | CRB gamma, Whittle [%] "
          "| CRB gamma, exact [%] | CRB eps2, Whittle [%] | CRB eps2, exact [%] |")
    print("|---|---|---|---|---|---|---|---|")
    n_chk = 1024 if (a.quick or a.smoke) else 2048
    for k in (1e-5, 5e-5):
        cw = crb(k, GAMMA, EPS2, DT, DT, n_chk)
        ce = np.sqrt(np.diag(np.linalg.inv(exact_fisher_dense(k, GAMMA, EPS2, DT, DT, n_chk))))
        ce = ce / np.array([k, GAMMA, EPS2])
        print(f"| {k * 1e3:g} | {n_chk} | {100 * cw[0]:.3f} | {100 * ce[0]:.3f} | "
              f"{100 * cw[1]:.3f} | {100 * ce[1]:.3f} | {100 * cw[2]:.3f} | {100 * ce[2]:.3f} |")
    sys.stdout.flush()

    # ---- main study -------------------------------------------------------------------------
    study = {}
    for ik, k in enumerate((1e-5, 5e-5)):
        tau = GAMMA / k
        cr = crb(k, GAMMA, EPS2, DT, DT, N_FRAMES)
        t0 = time.time()
        y = simulate(k, DT, a.default_seeds, seed=10 + ik)
        print(f"\n[k={k * 1e3:g} pN/nm] tau={tau * 1e3:.4f} ms alpha=W/tau={DT / tau:.4f} "
              f"simulated {y.shape} in {time.time() - t0:.1f} s; CRB k {100 * cr[0]:.3f} %, "
              f"gamma {100 * cr[1]:.3f} %, eps2 {100 * cr[2]:.3f} %", flush=True)
        study[k] = {"crb": cr, "rows": {}, "raw": {}}
        for label, kw in METHODS:
            t0 = time.time()
            nmax = (a.exact_seeds if (kw and kw.get("likelihood") == "exact") else
                    a.default_seeds if kw is None else a.seeds)
            res, fails = fit_method(y, DT, kw, nmax)
            el = time.time() - t0
            sk = summarise(res[:, 0], res[:, 1], k, cr[0])
            sg = (summarise(res[:, 2], res[:, 3], GAMMA, cr[1])
                  if np.any(np.isfinite(res[:, 2])) else None)
            se2 = (summarise(res[:, 4], res[:, 5], EPS2, cr[2])
                   if kw is None or kw.get("likelihood") == "exact" else None)
            study[k]["rows"][label] = (sk, sg, se2, fails, el)
            study[k]["raw"][label] = res
            print(f"  {label:28s} n={sk['n']:4d} fails={fails} {el:7.1f} s  "
                  f"k bias {sk['bias_pct']:+.3f}% ({sk['bias_z']:+.2f} SE)  "
                  f"SE/SD {sk['se_sd']:.3f}", flush=True)
        # paired differences on identical seeds: exact - default, and default on the subsets
        dflt = study[k]["raw"]["default (Whittle)"]
        ex = study[k]["raw"]["exact likelihood"]
        ne = ex.shape[0]
        pair = {}
        for col, tv in ((0, k), (2, GAMMA), (4, EPS2)):
            dd = 100 * (ex[:, col] - dflt[:ne, col]) / tv
            dd = dd[np.isfinite(dd)]
            sub = 100 * (dflt[:ne, col] - tv) / tv
            sub3 = 100 * (dflt[: a.seeds, col] - tv) / tv
            pair[col] = (dd.mean(), dd.std(ddof=1) / math.sqrt(dd.size), np.abs(dd).max(),
                         sub.mean(), sub.std(ddof=1) / math.sqrt(ne),
                         sub3.mean(), sub3.std(ddof=1) / math.sqrt(sub3.size))
        study[k]["pair"] = pair
        # calibrate_batch == calibrate on a few rows
        b = bt.calibrate_batch(y[:5], frame_interval=DT, exposure=DT)
        diffs = []
        for i in range(5):
            r = bt.calibrate(bt.Recording(y[i], frame_interval=DT, exposure=DT))
            diffs.append(max(abs(b.k[i] / r.k - 1), abs(b.gamma[i] / r.gamma - 1),
                             abs(b.k_err[i] / r.k_err - 1)))
        study[k]["batch_vs_single"] = max(diffs)

    print(f"\n## Main study: bias, spread and error bars (N = {nf}, W = dt = 1/1500 s, "
          "eps = 2 nm)\n")
    print("bias z = bias / (Monte-Carlo SE of the mean); SE/SD = mean reported SE / observed SD "
          "(its own MC uncertainty is about 1/sqrt(2n)); SD/CRB uses the Whittle expected "
          "Fisher CRB.\n")
    print("| k [pN/nm] | method | n fits (fail) | k bias [%] | k bias [MC SE] | k SD [%] | "
          "k SE/SD | k SD/CRB | gamma bias [%] | gamma bias [MC SE] | gamma SD [%] | "
          "gamma SE/SD | gamma SD/CRB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k, d in study.items():
        for label, (sk, sg, se2, fails, el) in d["rows"].items():
            g = sg or {}
            print(f"| {k * 1e3:g} | {label} | {sk['n']} ({fails}) | {sk['bias_pct']:+.3f} | "
                  f"{sk['bias_z']:+.2f} | {sk['sd_pct']:.3f} | {fmt(sk['se_sd'], 3)} | "
                  f"{fmt(sk['sd_crb'], 3)} | "
                  + (f"{g['bias_pct']:+.3f} | {g['bias_z']:+.2f} | {g['sd_pct']:.3f} | "
                     f"{fmt(g['se_sd'], 3)} | {fmt(g['sd_crb'], 3)} |" if g else
                     "— | — | — | — | — |"))
    print("\n## Tracking-error variance eps2 (likelihood methods)\n")
    print("| k [pN/nm] | method | eps2 bias [%] | bias [MC SE] | SD [%] | SE/SD | SD/CRB |")
    print("|---|---|---|---|---|---|---|")
    for k, d in study.items():
        for label, (sk, sg, se2, fails, el) in d["rows"].items():
            if se2:
                print(f"| {k * 1e3:g} | {label} | {se2['bias_pct']:+.2f} | {se2['bias_z']:+.2f} "
                      f"| {se2['sd_pct']:.2f} | {fmt(se2['se_sd'], 3)} | "
                      f"{fmt(se2['sd_crb'], 3)} |")
    print("\n## Paired comparison on identical seeds: exact likelihood - default (Whittle)\n")
    print("| k [pN/nm] | param | seeds | mean diff [% of truth] | SE of diff [%] | max abs diff [%] "
          "| default bias on these seeds [%] | default bias on first --seeds [%] |")
    print("|---|---|---|---|---|---|---|---|")
    for k, d in study.items():
        ne = d["rows"]["exact likelihood"][0]["n"]
        for col, pn in ((0, "k"), (2, "gamma"), (4, "eps2")):
            m, se_, mx, sb, sbe, s3, s3e = d["pair"][col]
            print(f"| {k * 1e3:g} | {pn} | {ne} | {m:+.4f} | {se_:.4f} | {mx:.4f} | "
                  f"{sb:+.3f} +- {sbe:.3f} | {s3:+.3f} +- {s3e:.3f} |")
    print(f"\n## CRB at N = {nf} and wall time of each method's loop\n")
    print("| k [pN/nm] | CRB k [%] | CRB gamma [%] | CRB eps2 [%] | max rel diff batch vs "
          "calibrate (5 rows) |")
    print("|---|---|---|---|---|")
    for k, d in study.items():
        c = d["crb"]
        print(f"| {k * 1e3:g} | {100 * c[0]:.3f} | {100 * c[1]:.3f} | {100 * c[2]:.2f} | "
              f"{d['batch_vs_single']:.2e} |")
    print("\n| k [pN/nm] | method | fits | wall [s] | per fit [ms] |")
    print("|---|---|---|---|---|")
    for k, d in study.items():
        for label, (sk, sg, se2, fails, el) in d["rows"].items():
            nf = sk["n"] + fails
            print(f"| {k * 1e3:g} | {label} | {nf} | {el:.1f} | {1e3 * el / nf:.1f} |")

    # ---- grid of alpha and dt/tau (default method) ------------------------------------------
    print(f"\n## Grid: default method (calibrate_batch, Whittle), {a.grid_seeds} seeds per cell, "
          f"N = {nf}, dt = 1/1500 s, eps = 2 nm\n")
    print("| k [pN/nm] | W/dt | dt/tau | alpha = W/tau | fails | k bias [%] | k bias [MC SE] | "
          "k SD [%] | k CRB [%] | k SD/CRB | k SE/SD (median SE/SD) | gamma bias [%] | "
          "gamma bias [MC SE] | gamma SD [%] | gamma CRB [%] | gamma SD/CRB | gamma SE/SD "
          "(median SE/SD) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    grid = []
    for ik, kpn in enumerate((0.005, 0.02, 0.1)):
        k = kpn * 1e-3
        for iw, wr in enumerate((0.25, 1.0)):
            w = wr * DT
            tau = GAMMA / k
            cr = crb(k, GAMMA, EPS2, w, DT, N_FRAMES)
            y = simulate(k, w, a.grid_seeds, seed=100 + 10 * ik + iw)
            res, fails = fit_method(y, w, None, a.grid_seeds)
            sk = summarise(res[:, 0], res[:, 1], k, cr[0])
            sg = summarise(res[:, 2], res[:, 3], GAMMA, cr[1])
            grid.append((kpn, wr, DT / tau, w / tau, sk, sg))
            print(f"| {kpn:g} | {wr:g} | {DT / tau:.3f} | {w / tau:.3f} | {fails} | "
                  f"{sk['bias_pct']:+.3f} | {sk['bias_z']:+.2f} | {sk['sd_pct']:.3f} | "
                  f"{sk['crb_pct']:.3f} | {sk['sd_crb']:.3f} | {sk['se_sd']:.3f} "
                  f"({sk['se_sd_med']:.3f}) | "
                  f"{sg['bias_pct']:+.3f} | {sg['bias_z']:+.2f} | {sg['sd_pct']:.3f} | "
                  f"{sg['crb_pct']:.3f} | {sg['sd_crb']:.3f} | {sg['se_sd']:.3f} "
                  f"({sg['se_sd_med']:.3f}) |", flush=True)
            del y

    # ---- acceptance ---------------------------------------------------------------------------
    print("\n## Acceptance checks\n")
    print("| check | value | target | met |")
    print("|---|---|---|---|")

    def row(name, val, target, ok):
        print(f"| {name} | {val} | {target} | {'yes' if ok else 'NO'} |")

    for k, d in study.items():
        kk = f"k={k * 1e3:g}"
        for label in ("default (Whittle)", "exact likelihood"):
            sk, sg, *_ = d["rows"][label]
            for pn, s in (("k", sk), ("gamma", sg)):
                row(f"{kk} {label}: {pn} |bias|", f"{s['bias_pct']:+.3f} % "
                    f"({s['bias_z']:+.2f} MC SE)", "<= 2 MC SE and <= 0.5 %",
                    abs(s["bias_z"]) <= 2 and abs(s["bias_pct"]) <= 0.5)
                row(f"{kk} {label}: {pn} SE/SD", f"{s['se_sd']:.3f} "
                    f"(+- {s['se_sd_err']:.3f})", "0.9-1.1", 0.9 <= s["se_sd"] <= 1.1)
                row(f"{kk} {label}: {pn} SD/CRB", f"{s['sd_crb']:.3f} "
                    f"(+- {s['se_sd_err']:.3f})", "<= 1.12 (and >= 0.88)",
                    0.88 <= s["sd_crb"] <= 1.12)
        se = d["rows"]["naive equipartition"][0]
        if k == 5e-5:
            row(f"{kk} naive equipartition k bias", f"{se['bias_pct']:+.2f} %", "+34 % to +43 %",
                34 <= se["bias_pct"] <= 43)
    c = study[5e-5]["crb"]
    row("CRB k, k=0.05", f"{100 * c[0]:.3f} %", "~1.9 % (issue)", abs(100 * c[0] - 1.9) < 0.2)
    row("CRB gamma, k=0.05", f"{100 * c[1]:.3f} %", "~3.9 % (issue)",
        abs(100 * c[1] - 3.9) < 0.4)
    for kpn, wr, r, al, sk, sg in grid:
        row(f"grid k={kpn:g} W/dt={wr:g}: k SD/CRB, gamma SD/CRB",
            f"{sk['sd_crb']:.3f}, {sg['sd_crb']:.3f} (+- {sk['se_sd_err']:.3f})", "within 12 %",
            abs(sk["sd_crb"] - 1) <= 0.12 and abs(sg["sd_crb"] - 1) <= 0.12)

    # ---- figure -----------------------------------------------------------------------------
    try:
        make_figure(study, grid, a.fig)
        print(f"\nfigure: {a.fig}")
    except Exception as exc:  # pragma: no cover
        print(f"\nfigure failed: {exc!r}")
    print(f"\ntotal wall time {time.time() - t_start:.0f} s")


def make_figure(study, grid, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(14, 9.5))
    labels = [m for m, _ in METHODS]
    ks = list(study)
    x = np.arange(len(labels))
    for j, (pn, col) in enumerate((("k", 0), ("gamma", 1))):
        a = ax[0, j]
        for i, k in enumerate(ks):
            b, e = [], []
            for lab in labels:
                s = study[k]["rows"][lab][col]
                b.append(s["bias_pct"] if s else np.nan)
                e.append(2 * s["mcse_pct"] if s else np.nan)
            a.bar(x + (i - 0.5) * 0.38, b, 0.38, yerr=e, capsize=3,
                  label=f"k = {k * 1e3:g} pN/nm")
        a.axhline(0, color="k", lw=0.8)
        a.set_yscale("symlog", linthresh=0.5)
        a.set_xticks(x, [lab.replace(", ", "\n").replace(" (", "\n(").replace(" e", "\ne")
                         for lab in labels], fontsize=7)
        a.set_ylabel(f"bias of {pn} [%] (symlog; bars: 2 MC SE)")
        a.set_title(f"{pn}: bias by method ({N_FRAMES} frames, W = dt = 1/1500 s, eps = 2 nm)",
                    fontsize=9)
        a.legend(fontsize=8)
    a = ax[1, 0]
    z = np.linspace(-4, 4, 200)
    for k in ks:
        res = study[k]["raw"]["default (Whittle)"]
        for col, pn, tv in ((0, "k", k), (2, "gamma", GAMMA)):
            ok = np.isfinite(res[:, col])
            pull = (res[ok, col] - tv) / res[ok, col + 1]
            a.hist(pull, bins=30, range=(-4, 4), density=True, histtype="step",
                   label=f"{pn}, k = {k * 1e3:g} pN/nm (mean {pull.mean():+.2f}, "
                         f"SD {pull.std(ddof=1):.2f})")
    a.plot(z, np.exp(-z * z / 2) / math.sqrt(2 * math.pi), "k--", label="N(0, 1)")
    a.set_xlabel("pull = (estimate - truth) / reported SE, default method")
    a.legend(fontsize=7)
    a = ax[1, 1]
    for wr, mk in ((0.25, "o"), (1.0, "s")):
        sel = [g for g in grid if g[1] == wr]
        a.plot([g[2] for g in sel], [g[4]["sd_crb"] for g in sel], mk + "-",
               label=f"k, W/dt = {wr:g}")
        a.plot([g[2] for g in sel], [g[5]["sd_crb"] for g in sel], mk + "--",
               label=f"gamma, W/dt = {wr:g}")
    a.axhspan(0.88, 1.12, color="0.9")
    a.axhline(1, color="k", lw=0.8)
    a.set_xscale("log")
    xt = sorted({g[2] for g in grid})
    a.set_xticks(xt, [f"{v:.3g}" for v in xt])
    a.minorticks_off()
    a.set_xlabel("dt / tau  (k = 0.005, 0.02, 0.1 pN/nm)")
    a.set_ylabel("observed SD / CRB (default method)")
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
