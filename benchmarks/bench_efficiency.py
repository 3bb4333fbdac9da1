"""Efficiency of blurtrap's estimators against the Cramer-Rao bound over a grid of alpha and dt/tau.

Not a test. Run:  python benchmarks/bench_efficiency.py [--seeds 50] [--frames 32768]
                                                        [--out benchmarks]

Camera-like data (``bt.simulate(method="exact_frames")``): dt = 1/1500 s, eps = 2 nm, gamma =
6 pi (0.00093 Pa s)(1.53 um), T = 295 K; a 3 x 3 grid of dt/tau in {0.1, 0.5, 2} (k = 0.004,
0.02, 0.08 pN/nm) and W/dt in {0.1, 0.5, 1} (alpha = W/tau = (W/dt)(dt/tau) from 0.01 to 2),
``--seeds`` recordings of ``--frames`` frames per cell. Methods per cell (single recording):

- ``likelihood, exact``  -- ``calibrate(method="likelihood", likelihood="exact")``;
- ``likelihood, Whittle`` -- ``calibrate_batch`` (the same fit as ``calibrate(method=
  "likelihood", likelihood="whittle")``, vmapped);
- ``blocked PSD``        -- ``calibrate(method="psd")`` (128 blocks);

and per dt/tau row, on the *exposure series* made of the row's three recordings with the same
seed index (W/dt = 0.1, 0.5, 1):

- ``variance_vs_exposure`` -- ``calibrate(recs, method="variance_vs_exposure")``;
- ``joint likelihood``     -- ``calibrate(recs, method="likelihood", likelihood="whittle")``.

The Cramer-Rao bound (CRB) is the inverse expected Fisher information of (k, gamma, eps^2):
the Whittle expected Fisher of the closed-form aliased blurred spectrum from
``study_calibration.whittle_fisher`` (independent of the fitting code; it matches the exact
dense-Toeplitz Fisher to < 0.5 %, see RESULTS_calibration.md), summed over the three recordings
for the exposure series. SD/CRB = observed SD of the estimates / CRB (1 = efficient; its own
Monte-Carlo uncertainty is ~1/sqrt(2 (n-1))). Writes ``RESULTS_efficiency.md`` and
``efficiency.png`` into ``--out``; ``--raw FILE`` also saves the summaries and ``--replot FILE``
redraws the figure from them. ``--recheck 0.5:1 2:series ... --recheck-seeds 200`` re-measures
chosen cells (dt/tau:W/dt, or dt/tau:series) with the Whittle likelihood on fresh seeds and
appends a table to ``RESULTS_efficiency.md`` (to tell a 2-3 MC SE excursion from a real
inefficiency).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import sys
import time
import warnings

import jax
import numpy as np

import blurtrap as bt

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_peers import machine_info, machine_line  # noqa: E402
from study_calibration import whittle_fisher  # noqa: E402

bt.enable_x64()

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1.0 / 1500.0
EPS2 = (2e-9) ** 2
RATIOS = (0.1, 0.5, 2.0)  # dt/tau
WFRACS = (0.1, 0.5, 1.0)  # W/dt
SINGLE = ("likelihood, exact", "likelihood, Whittle", "blocked PSD")
SERIES = ("variance_vs_exposure", "joint likelihood (3 exposures)")


def summarise(vals, errs, true, crb_rel):
    v = np.asarray(vals, float)
    e = np.asarray(errs, float)
    ok = np.isfinite(v)
    n = int(ok.sum())
    if n < 3:
        return None
    v, e = v[ok], e[ok]
    sd = v.std(ddof=1)
    return dict(n=n, bias=100 * (v.mean() - true) / true,
                bias_z=(v.mean() - true) / (sd / math.sqrt(n)), sd=100 * sd / true,
                crb=100 * crb_rel, sd_crb=(sd / true) / crb_rel,
                se_sd=float(np.mean(e)) / sd if np.all(np.isfinite(e)) else float("nan"),
                se_sd_med=float(np.median(e)) / sd if np.all(np.isfinite(e)) else float("nan"),
                mc=1 / math.sqrt(2 * (n - 1)))


def loop_fit(y, w, kwargs):
    res = np.full((y.shape[0], 4), np.nan)
    fails = 0
    for i, row in enumerate(y):
        try:
            r = bt.calibrate(bt.Recording(row, frame_interval=DT, exposure=w), **kwargs)
            res[i] = [r.k, r.k_err, r.gamma, r.gamma_err]
        except bt.FitError:
            fails += 1
    return res, fails


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--frames", type=int, default=32768)
    ap.add_argument("--exact-seeds", type=int, default=None,
                    help="seeds for the (slow) exact likelihood; default all")
    ap.add_argument("--out", default=str(pathlib.Path(__file__).parent))
    ap.add_argument("--raw", default=None, help="also save the summaries to this JSON file")
    ap.add_argument("--replot", default=None, metavar="RAW_JSON",
                    help="redraw efficiency.png from a --raw file (no fits)")
    ap.add_argument("--recheck", nargs="+", default=None, metavar="DTTAU:WDT",
                    help="only re-measure these cells with the Whittle likelihood and more "
                         "seeds (e.g. 0.5:1 for a single recording, 2:series for the exposure "
                         "series) and append the result to RESULTS_efficiency.md in --out")
    ap.add_argument("--recheck-seeds", type=int, default=200)
    a = ap.parse_args(argv)
    if a.recheck:
        recheck(a)
        return
    if a.replot:
        raw = json.loads(pathlib.Path(a.replot).read_text())
        cells = {(c["r"], c["wf"]): c for c in raw["cells"]}
        series = {c["r"]: c for c in raw["series"]}
        pathlib.Path(a.out).mkdir(parents=True, exist_ok=True)
        make_plot(pathlib.Path(a.out), cells, series)
        return
    n_ex = a.seeds if a.exact_seeds is None else min(a.exact_seeds, a.seeds)
    out_dir = pathlib.Path(a.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore", bt.SubstepBiasWarning)
    mach = machine_info()
    t_start = time.time()
    print(f"# bench_efficiency: seeds={a.seeds} (exact {n_ex}), frames={a.frames}\n"
          f"{machine_line(mach)}", flush=True)
    n = a.frames
    cells = {}
    series_data = {}
    timing = {m: 0.0 for m in SINGLE + SERIES}
    for ir, r in enumerate(RATIOS):
        k = GAMMA * r / DT
        ys = []
        for iw, wf in enumerate(WFRACS):
            w = wf * DT
            y = np.asarray(bt.simulate(k, GAMMA, w, DT, n, key=jax.random.key(700 + 10 * ir + iw),
                                       method="exact_frames", tracking_std=math.sqrt(EPS2),
                                       n_traces=a.seeds), dtype=np.float64)
            ys.append(y)
            fish = whittle_fisher(k, GAMMA, EPS2, w, DT, n)
            crb = np.sqrt(np.diag(np.linalg.inv(fish))) / np.array([k, GAMMA, EPS2])
            res = {}
            t0 = time.time()
            res["likelihood, exact"] = loop_fit(y[:n_ex], w,
                                                dict(method="likelihood", likelihood="exact"))
            timing["likelihood, exact"] += time.time() - t0
            t0 = time.time()
            b = bt.calibrate_batch(y, frame_interval=DT, exposure=w)
            wres = np.stack([b.k, b.k_err, b.gamma, b.gamma_err], 1)
            wres[~b.success] = np.nan
            res["likelihood, Whittle"] = (wres, int((~b.success).sum()))
            timing["likelihood, Whittle"] += time.time() - t0
            t0 = time.time()
            res["blocked PSD"] = loop_fit(y, w, dict(method="psd"))
            timing["blocked PSD"] += time.time() - t0
            cells[(r, wf)] = dict(k=k, w=w, crb=crb, rows={})
            for m, (rr, fails) in res.items():
                sk = summarise(rr[:, 0], rr[:, 1], k, crb[0])
                sg = summarise(rr[:, 2], rr[:, 3], GAMMA, crb[1])
                cells[(r, wf)]["rows"][m] = (sk, sg, fails)
            print(f"dt/tau={r:g} W/dt={wf:g} alpha={wf * r:.3g}: CRB k {100 * crb[0]:.2f} % "
                  f"gamma {100 * crb[1]:.2f} %; " + "; ".join(
                      f"{m}: SD/CRB k {s[0]['sd_crb']:.2f} g {s[1]['sd_crb']:.2f} "
                      f"fails {s[2]}" if s[0] and s[1] else f"{m}: —"
                      for m, s in cells[(r, wf)]["rows"].items()), flush=True)
        # exposure series
        fish = sum(whittle_fisher(k, GAMMA, EPS2, wf * DT, DT, n) for wf in WFRACS)
        crb = np.sqrt(np.diag(np.linalg.inv(fish))) / np.array([k, GAMMA, EPS2])
        sres = {m: (np.full((a.seeds, 4), np.nan), 0) for m in SERIES}
        for m, kw in zip(SERIES, (dict(method="variance_vs_exposure"),
                                  dict(method="likelihood", likelihood="whittle"))):
            arr = sres[m][0]
            fails = 0
            t0 = time.time()
            for i in range(a.seeds):
                recs = [bt.Recording(ys[j][i], frame_interval=DT, exposure=wf * DT)
                        for j, wf in enumerate(WFRACS)]
                try:
                    rr = bt.calibrate(recs, k="shared", **kw)
                    arr[i] = [rr.k, rr.k_err, rr.gamma, rr.gamma_err]
                except bt.FitError:
                    fails += 1
            timing[m] += time.time() - t0
            sres[m] = (arr, fails)
        series_data[r] = dict(k=k, crb=crb, rows={
            m: (summarise(v[:, 0], v[:, 1], k, crb[0]), summarise(v[:, 2], v[:, 3], GAMMA,
                                                                   crb[1]), f)
            for m, (v, f) in sres.items()})
        print(f"dt/tau={r:g} exposure series: CRB k {100 * crb[0]:.2f} % gamma "
              f"{100 * crb[1]:.2f} %; " + "; ".join(
                  f"{m}: SD/CRB k {s[0]['sd_crb']:.2f} g {s[1]['sd_crb']:.2f} fails {s[2]}"
                  if s[0] and s[1] else f"{m}: fails {s[2]}"
                  for m, s in series_data[r]["rows"].items()), flush=True)
    mach["load_end"] = os.getloadavg()
    mach["wall_s"] = time.time() - t_start
    if a.raw:
        pathlib.Path(a.raw).write_text(json.dumps({
            "machine": mach, "timing": timing,
            "cells": [dict(r=r, wf=wf, k=c["k"], crb=list(map(float, c["crb"])), rows=c["rows"])
                      for (r, wf), c in cells.items()],
            "series": [dict(r=r, k=c["k"], crb=list(map(float, c["crb"])), rows=c["rows"])
                       for r, c in series_data.items()]}))
    write_results(out_dir, a, n_ex, mach, cells, series_data, timing)
    try:
        make_plot(out_dir, cells, series_data)
    except Exception as exc:  # pragma: no cover
        print(f"plot failed: {exc!r}")
    print(f"total wall time {mach['wall_s']:.0f} s")


def recheck(a):
    """Re-measure SD/CRB of chosen cells with the Whittle likelihood on fresh seeds."""
    out = pathlib.Path(a.out) / "RESULTS_efficiency.md"
    n, s = a.frames, a.recheck_seeds
    mach = machine_info()
    lines = [f"\n## Re-check with {s} fresh seeds (Whittle likelihood)\n",
             f"`python benchmarks/bench_efficiency.py --frames {n} --recheck "
             f"{' '.join(a.recheck)} --recheck-seeds {s}`; {mach['date']}, commit "
             f"{mach['commit']}, load {mach['load_start'][0]:.1f}. MC uncertainty of SD/CRB "
             f"~{1 / math.sqrt(2 * (s - 1)):.3f}; SE/CRB = mean reported SE / CRB.\n",
             "| dt/tau | W/dt | k SD/CRB | gamma SD/CRB | k SE/CRB | gamma SE/CRB | k bias [%] | "
             "gamma bias [%] |", "|---|---|---|---|---|---|---|---|"]
    for cell in a.recheck:
        r_s, w_s = cell.split(":")
        r = float(r_s)
        wfs = WFRACS if w_s == "series" else (float(w_s),)
        k = GAMMA * r / DT
        ys = [np.asarray(bt.simulate(k, GAMMA, wf * DT, DT, n,
                                     key=jax.random.key(5000 + int(10 * r) + i),
                                     method="exact_frames", tracking_std=math.sqrt(EPS2),
                                     n_traces=s)) for i, wf in enumerate(wfs)]
        fish = sum(whittle_fisher(k, GAMMA, EPS2, wf * DT, DT, n) for wf in wfs)
        crb = np.sqrt(np.diag(np.linalg.inv(fish))) / np.array([k, GAMMA, EPS2])
        est = []
        for i in range(s):
            recs = [bt.Recording(ys[j][i], frame_interval=DT, exposure=wf * DT)
                    for j, wf in enumerate(wfs)]
            try:
                rr = bt.calibrate(recs, method="likelihood", likelihood="whittle")
                est.append((rr.k, rr.gamma, rr.k_err, rr.gamma_err))
            except bt.FitError:
                pass
        e = np.array(est)
        sdk, sdg = e[:, 0].std(ddof=1) / k, e[:, 1].std(ddof=1) / GAMMA
        lines.append(f"| {r:g} | {w_s} | {sdk / crb[0]:.3f} | {sdg / crb[1]:.3f} | "
                     f"{e[:, 2].mean() / k / crb[0]:.3f} | {e[:, 3].mean() / GAMMA / crb[1]:.3f} | "
                     f"{100 * (e[:, 0].mean() / k - 1):+.2f} | "
                     f"{100 * (e[:, 1].mean() / GAMMA - 1):+.2f} |")
        print(lines[-1], flush=True)
    with open(out, "a") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"appended to {out}")


def _fmt(s, key, p=2):
    if s is None:
        return "—"
    v = s[key]
    return "—" if not np.isfinite(v) else f"{v:.{p}f}"


def write_results(out_dir, a, n_ex, mach, cells, series_data, timing):
    L = ["# Efficiency: observed SD against the Cramer-Rao bound\n"]
    L.append(f"Generated by `python benchmarks/bench_efficiency.py --seeds {a.seeds} --frames "
             f"{a.frames}` (exact likelihood on {n_ex} seeds per cell). {machine_line(mach)}; "
             f"load average at end {mach['load_end'][0]:.1f}; wall time {mach['wall_s']:.0f} s."
             "\n")
    L.append(f"Data: camera frames, dt = 1/1500 s, eps = 2 nm, gamma = {GAMMA * 1e6:.5f} pN s/um, "
             f"T = 295 K, {a.frames} frames per recording, exact frame sampler. CRB: inverse "
             "expected Whittle Fisher information of (k, gamma, eps^2) (jax.jacfwd of the "
             "closed-form spectrum, `study_calibration.whittle_fisher`), in % of the truth. "
             "SD/CRB = observed SD / CRB (1 = efficient; Monte-Carlo uncertainty of the ratio "
             f"~{1 / math.sqrt(2 * (a.seeds - 1)):.2f} at {a.seeds} seeds, "
             f"~{1 / math.sqrt(2 * max(n_ex - 1, 1)):.2f} at {n_ex}); bias in % (in MC SE); "
             "SE/SD = mean reported SE / observed SD (median in brackets).\n")
    L.append("## Single recordings: 3 x 3 grid\n")
    L.append("| dt/tau | W/dt | alpha | k [pN/nm] | CRB k [%] | CRB gamma [%] | method | n (fail) | "
             "k SD/CRB | gamma SD/CRB | k bias [%] (MC SE) | gamma bias [%] (MC SE) | k SE/SD | "
             "gamma SE/SD |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (r, wf), c in cells.items():
        for m, (sk, sg, fails) in c["rows"].items():
            nn = sk["n"] if sk else 0
            bk = f"{sk['bias']:+.2f} ({sk['bias_z']:+.1f})" if sk else "—"
            bg = f"{sg['bias']:+.2f} ({sg['bias_z']:+.1f})" if sg else "—"
            star = "*" if c["crb"][1] > 0.25 else ""
            L.append(f"| {r:g} | {wf:g} | {r * wf:.3g}{star} | {c['k'] * 1e3:.3g} | "
                     f"{100 * c['crb'][0]:.2f} | {100 * c['crb'][1]:.2f} | {m} | {nn} ({fails}) "
                     f"| {_fmt(sk, 'sd_crb')} | {_fmt(sg, 'sd_crb')} | {bk} | {bg} | "
                     f"{_fmt(sk, 'se_sd')} ({_fmt(sk, 'se_sd_med')}) | {_fmt(sg, 'se_sd')} "
                     f"({_fmt(sg, 'se_sd_med')}) |")
    L.append("\n\\* CRB of gamma above 25 %: one recording barely identifies gamma (frames "
             "nearly uncorrelated, little blur); the estimator is far from its asymptotic "
             "normal regime (skewed, bounded), so SD/CRB is not an efficiency there and can "
             "fall below 1. The exposure series below is the remedy (paper section 6.2).\n")
    L.append("\n## Exposure series (the row's three recordings, W/dt = 0.1, 0.5, 1, same seed)\n")
    L.append("CRB of the series = inverse of the summed Fisher information of the three "
             "recordings.\n")
    L.append("| dt/tau | k [pN/nm] | CRB k [%] | CRB gamma [%] | method | n (fail) | k SD/CRB | "
             "gamma SD/CRB | k bias [%] (MC SE) | gamma bias [%] (MC SE) | k SE/SD | "
             "gamma SE/SD |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r, c in series_data.items():
        for m, (sk, sg, fails) in c["rows"].items():
            nn = sk["n"] if sk else 0
            bk = f"{sk['bias']:+.2f} ({sk['bias_z']:+.1f})" if sk else "—"
            bg = f"{sg['bias']:+.2f} ({sg['bias_z']:+.1f})" if sg else "—"
            L.append(f"| {r:g} | {c['k'] * 1e3:.3g} | {100 * c['crb'][0]:.2f} | "
                     f"{100 * c['crb'][1]:.2f} | {m} | {nn} ({fails}) | {_fmt(sk, 'sd_crb')} | "
                     f"{_fmt(sg, 'sd_crb')} | {bk} | {bg} | {_fmt(sk, 'se_sd')} | "
                     f"{_fmt(sg, 'se_sd')} |")
    L.append("\n## Wall time by method (all cells)\n")
    L.append("| method | total [s] |")
    L.append("|---|---|")
    for m, t in timing.items():
        L.append(f"| {m} | {t:.1f} |")
    L.append("\nFigure: `efficiency.png` (SD/CRB of k and gamma against dt/tau, one panel per "
             "W/dt, plus the exposure series).\n")
    path = out_dir / "RESULTS_efficiency.md"
    path.write_text("\n".join(L) + "\n")
    print("\n".join(L))
    print(f"\nwrote {path}")


def make_plot(out_dir, cells, series_data):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(17, 8))
    marks = dict(zip(SINGLE + SERIES, "osD^v"))
    cols = dict(zip(SINGLE + SERIES, ("C0", "C1", "C2", "C3", "C4")))
    weak = {key for key, c in cells.items() if c["crb"][1] > 0.25}
    for i, (pn, j) in enumerate((("k", 0), ("gamma", 1))):
        for c, wf in enumerate(WFRACS):
            ax = axes[i, c]
            for m in SINGLE:
                xs, ys, es = [], [], []
                for r in RATIOS:
                    s = cells[(r, wf)]["rows"][m][j]
                    if s:
                        xs.append(r)
                        ys.append(s["sd_crb"])
                        es.append(s["sd_crb"] * s["mc"])
                ax.errorbar(xs, ys, yerr=es, marker=marks[m], capsize=3, label=m,
                            color=cols[m])
                for x_, y_ in zip(xs, ys):
                    if (x_, wf) in weak:
                        ax.plot([x_], [y_], marker=marks[m], ms=13, mfc="none", mec="r")
            ax.set_title(f"{pn}, single recording, W/dt = {wf:g}", fontsize=9)
            ax.set_ylim(0.4, 2.5)
        ax = axes[i, 3]
        for m in SERIES:
            xs, ys, es = [], [], []
            for r in RATIOS:
                s = series_data[r]["rows"][m][j]
                if s:
                    xs.append(r)
                    ys.append(s["sd_crb"])
                    es.append(s["sd_crb"] * s["mc"])
            ax.errorbar(xs, ys, yerr=es, marker=marks[m], capsize=3, label=m,
                        color=cols[m])
        ax.set_title(f"{pn}, exposure series W/dt = 0.1, 0.5, 1", fontsize=9)
        axes[i, 0].plot([], [], "o", ms=11, mfc="none", mec="r",
                        label="CRB(gamma) > 25 %: not asymptotic")
        for ax in axes[i]:
            ax.axhspan(0.9, 1.1, color="0.9")
            ax.axhline(1, color="k", lw=0.8)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xticks(RATIOS, [f"{r:g}" for r in RATIOS])
            ax.minorticks_off()
            if ax is not axes[i, 3]:
                yt = [0.5, 0.7, 1.0, 1.5, 2.0]
                ax.set_yticks(yt, [f"{v:g}" for v in yt])
            ax.set_xlabel("dt / tau")
            ax.legend(fontsize=7)
        axes[i, 0].set_ylabel(f"observed SD / CRB of {pn} (log)")
    fig.tight_layout()
    fig.savefig(out_dir / "efficiency.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
