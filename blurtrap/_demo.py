"""``blurtrap demo``: simulate the experiment of Wong & Halvorsen (2006) and calibrate it every
way the package knows, then write figures, a Markdown report and a table against the truth.

The embedded default (paper section 4): a 3.063 um polystyrene bead (radius 1.53 um) in water
at 295 K (viscosity 0.95 mPa s, gamma = 6 pi eta r), held at 4 laser powers with k = c P
(k = 0.01 ... 0.04 pN/nm), filmed by a ~1500 fps camera with a series of exposure times and
2 nm tracking error. Exposures longer than the 1/1500 s frame interval are filmed at a
frame interval equal to the exposure (the paper's 1 ms and 2 ms runs need a slower frame rate).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import sys
import time
import traceback
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

BOLTZMANN = 1.380649e-23


@dataclasses.dataclass(frozen=True)
class DemoConfig:
    """Settings of the simulated experiment (SI units)."""

    radius: float = 1.53e-6  # m
    viscosity: float = 0.00095  # Pa s
    temperature: float = 295.0  # K
    powers: tuple = (0.1, 0.2, 0.3, 0.4)  # W
    c: float = 1e-4  # N/m/W  (k = c P: 0.01 ... 0.04 pN/nm)
    fps: float = 1500.0  # Hz
    exposures: tuple = (1.0e-4, 2.0e-4, 4.0e-4, 1 / 1500, 1.0e-3, 2.0e-3, 4.0e-3)  # s
    tracking_std: float = 2e-9  # m
    n_frames: int = 32768
    naive_exposures: tuple = (1.0e-3, 2.0e-3)  # s, as in the paper's Fig. 4
    power_exposures: tuple = (1.0e-3, 2.0e-3)  # s, variance-vs-power fits
    # Fig. 1 (caption): (k [N/m], tau [s]) of the three simulation settings
    fig1_settings: tuple = ((5e-5, 0.537e-3), (5e-5, 0.134e-3), (1.25e-5, 2.148e-3))
    fig1_windows: tuple = (2e-5, 5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 4e-3, 8e-3, 16e-3)
    fig1_frames: int = 20000
    posterior_steps: int = 200
    psd_models: tuple = ("naive", "naive_aliased", "standard")
    per_power_variance: bool = True  # variance vs exposure at each power (besides joint)
    exact_likelihood: bool = True
    posterior: bool = True
    seed: int = 0

    @property
    def gamma(self) -> float:
        return 6 * math.pi * self.viscosity * self.radius

    @property
    def ks(self) -> np.ndarray:
        return self.c * np.asarray(self.powers, dtype=float)

    @property
    def frame_interval(self) -> float:
        return 1.0 / self.fps

    def frame_intervals(self) -> np.ndarray:
        return np.maximum(np.asarray(self.exposures, dtype=float), self.frame_interval)


def quick_config(seed: int = 0) -> DemoConfig:
    """Small sizes for a fast check (tests, CI): fewer frames; no exact likelihood, posterior,
    per-power variance-vs-exposure or naive PSD fits (the naive equipartition rows show the
    blur bias), one variance-vs-power fit. A short run is dominated by first-call
    compilation, one per estimator and data shape."""
    return DemoConfig(n_frames=16384, fig1_frames=4000, exact_likelihood=False,
                      posterior=False, power_exposures=(2.0e-3,), psd_models=("standard",),
                      per_power_variance=False, seed=seed)


# ------------------------------------------------------------------------------------------
# small utilities
# ------------------------------------------------------------------------------------------
class _Log:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def _close(a, b) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b))


def _pct(est, true):
    if est is None or true is None or not np.isfinite(est) or not np.isfinite(true):
        return None
    return 100.0 * (est - true) / true


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


# ------------------------------------------------------------------------------------------
# simulation
# ------------------------------------------------------------------------------------------
def simulate_experiment(cfg: DemoConfig):
    """Exposure series at every power: ``{(power, exposure): Recording}`` in a RecordingSet
    ordered power-major. One ``simulate`` call (method ``exact_frames``)."""
    import jax

    from .data import Recording, RecordingSet
    from .simulate import simulate

    ws = np.asarray(cfg.exposures, dtype=float)
    dts = cfg.frame_intervals()
    # one independent stream per recording (a single key would give every grid point the
    # same random numbers: common random numbers, correlated recordings)
    keys = jax.random.split(jax.random.key(cfg.seed), len(cfg.powers) * len(ws))
    keys = keys.reshape(len(cfg.powers), len(ws))
    x = simulate(cfg.ks[:, None], cfg.gamma, ws[None, :], dts[None, :], cfg.n_frames,
                 key=keys, temperature=cfg.temperature,
                 method="exact_frames", tracking_std=cfg.tracking_std)
    x = np.asarray(x, dtype=float)  # (powers, exposures, 1, frames)
    recs = []
    for i, p in enumerate(cfg.powers):
        for j, w in enumerate(ws):
            recs.append(Recording(
                x[i, j, 0], frame_interval=float(dts[j]), exposure=float(w),
                temperature=cfg.temperature, laser_power=float(p),
                name=f"P{p * 1e3:.0f}mW_W{w * 1e3:.3f}ms",
                metadata={"simulated": True, "k_true_N_per_m": float(cfg.ks[i]),
                          "gamma_true_N_s_per_m": cfg.gamma},
            ))
    return RecordingSet(recs)


def simulate_fig1(cfg: DemoConfig):
    """The three settings of the paper's Fig. 1, all exposure windows from one trajectory
    each (``ExposureWindows``). Returns (positions (3, n_win, 1, N), ks, gammas, dt)."""
    import jax

    from .simulate import ExposureWindows, simulate

    ks = np.array([s[0] for s in cfg.fig1_settings])
    gammas = np.array([s[0] * s[1] for s in cfg.fig1_settings])
    dt = max(cfg.fig1_windows)
    keys = jax.random.split(jax.random.key(cfg.seed + 1), len(ks))
    x = simulate(ks, gammas, ExposureWindows(cfg.fig1_windows), dt, cfg.fig1_frames,
                 key=keys, temperature=cfg.temperature,
                 method="exact_frames")
    return np.asarray(x, dtype=float), ks, gammas, dt


def add_drift(rec, seed: int):
    """A copy of ``rec`` with slow stage drift (two sinusoids below 0.5 Hz, ~7 nm rms)."""
    from .data import Recording

    rng = np.random.default_rng(seed)
    t = np.arange(rec.n_frames) * rec.frame_interval
    ph = rng.uniform(0, 2 * np.pi, 2)
    drift = (8e-9 * np.sin(2 * np.pi * 0.13 * t + ph[0])
             + 5e-9 * np.sin(2 * np.pi * 0.41 * t + ph[1]))
    return Recording(np.asarray(rec.positions) + drift, frame_interval=rec.frame_interval,
                     exposure=rec.exposure, temperature=rec.temperature,
                     laser_power=rec.laser_power, name=f"{rec.name}+drift")


def naive_error_grid(cfg: DemoConfig, k_grid=None, w_grid=None):
    """Analytic relative error of naive equipartition, ``kT/var(X_m)/k - 1``, with
    ``var(X_m) = kT/k S(W k/gamma) + eps^2`` for the demo bead, over a k x W grid."""
    from .plotting._common import blur_factor_np

    k_grid = np.geomspace(5e-6, 2e-4, 40) if k_grid is None else np.asarray(k_grid, float)
    w_grid = np.geomspace(5e-5, 5e-3, 48) if w_grid is None else np.asarray(w_grid, float)
    kt = BOLTZMANN * cfg.temperature
    kk, ww = np.meshgrid(k_grid, w_grid, indexing="ij")
    var = kt / kk * blur_factor_np(ww * kk / cfg.gamma) + cfg.tracking_std**2
    return k_grid, w_grid, kt / var / kk - 1.0


# ------------------------------------------------------------------------------------------
# turning results into table rows (lab units)
# ------------------------------------------------------------------------------------------
def _k_by_power(result, recs, powers):
    ks = np.asarray(result.k_per_recording, dtype=float)
    es = np.asarray(result.k_per_recording_err, dtype=float)
    if ks.size == 1 and len(recs) > 1:
        ks, es = np.full(len(recs), ks[0]), np.full(len(recs), es[0])
    out_k, out_e = [], []
    for p in powers:
        sel = [i for i, r in enumerate(recs) if r.laser_power is not None
               and _close(r.laser_power, p)]
        if sel:
            out_k.append(float(np.mean(ks[sel])))
            out_e.append(float(np.mean(es[sel])))
        else:
            out_k.append(None)
            out_e.append(None)
    return out_k, out_e


def make_row(label, method, model, cfg, powers, ks, kerrs, gamma=None, gamma_err=None,
             tracking_var=None, exposure=None, note=None):
    """One table row in lab units, with the truth and the % errors."""
    truth_k = {float(p): float(cfg.c * p) for p in cfg.powers}
    row = {
        "label": label,
        "method": method,
        "model": model,
        "exposure_ms": None if exposure is None else float(exposure) * 1e3,
        "power_mW": [float(p) * 1e3 for p in powers],
        "k_pN_per_nm": [None if k is None else k * 1e3 for k in ks],
        "k_err_pN_per_nm": [None if e is None else _f(e * 1e3) for e in kerrs],
        "k_true_pN_per_nm": [truth_k[float(p)] * 1e3 for p in powers],
        "k_error_pct": [_pct(k, truth_k[float(p)]) for k, p in zip(ks, powers, strict=True)],
    }
    g_true = cfg.gamma
    if gamma is None:
        row.update(gamma_pN_s_per_um=None, gamma_err_pN_s_per_um=None, gamma_error_pct=None)
    elif np.ndim(gamma):
        row["gamma_pN_s_per_um"] = [_f(g * 1e6) for g in gamma]
        row["gamma_err_pN_s_per_um"] = [_f(e * 1e6) for e in gamma_err]  # pyright: ignore
        row["gamma_error_pct"] = [_pct(g, g_true) for g in gamma]
    else:
        row["gamma_pN_s_per_um"] = _f(gamma * 1e6)
        row["gamma_err_pN_s_per_um"] = _f(gamma_err * 1e6) if gamma_err is not None else None
        row["gamma_error_pct"] = _pct(gamma, g_true)
    row["gamma_true_pN_s_per_um"] = g_true * 1e6
    if tracking_var is not None:
        tv = np.atleast_1d(np.asarray(tracking_var, dtype=float)) * 1e18
        row["tracking_var_nm2"] = [float(v) for v in tv] if tv.size > 1 else float(tv[0])
    if note:
        row["note"] = note
    return row


def _fmt_k(k, pct):
    if k is None:
        return "-"
    return f"{k:.4f} ({pct:+.1f}%)" if pct is not None else f"{k:.4f}"


def _gamma_cell(row):
    g = row["gamma_pN_s_per_um"]
    if g is None:
        return "-"
    if isinstance(g, list):
        vals = [v for v in g if v is not None]
        if not vals:
            return "-"
        m = float(np.mean(vals))
        pct = _pct(m, row["gamma_true_pN_s_per_um"])
        return f"{m:.4f} ({pct:+.1f}%) *"
    return f"{g:.4f} ({row['gamma_error_pct']:+.1f}%)"


def format_table(rows, cfg: DemoConfig) -> str:
    """The console table: k per power [pN/nm] and gamma [pN s/um], with % error vs truth."""
    powers = [p * 1e3 for p in cfg.powers]
    head = ["method"] + [f"k @ {p:.0f} mW [pN/nm]" for p in powers] + ["gamma [pN s/um]"]
    truth = ["truth"] + [f"{k * 1e3:.4f}" for k in cfg.ks] + [f"{cfg.gamma * 1e6:.4f}"]
    body = [head, truth]
    for r in rows:
        cells = [r["label"]]
        pairs = zip(r["k_pN_per_nm"], r["k_error_pct"], strict=True)
        by_p = dict(zip(r["power_mW"], pairs, strict=True))
        for p in powers:
            k, pct = by_p.get(p, (None, None))
            cells.append(_fmt_k(k, pct))
        cells.append(_gamma_cell(r))
        body.append(cells)
    widths = [max(len(row[i]) for row in body) for i in range(len(head))]
    lines = []
    for n, row in enumerate(body):
        lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths, strict=True))))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    lines.append("(% = error vs truth; * = mean of per-power fits)")
    return "\n".join(lines)


def markdown_table(rows, cfg: DemoConfig) -> str:
    powers = [p * 1e3 for p in cfg.powers]
    head = (["method"] + [f"k @ {p:.0f} mW [pN/nm]" for p in powers]
            + ["gamma [pN s/um]", "eps^2 [nm^2]"])
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out.append("| **truth** | " + " | ".join(f"{k * 1e3:.4f}" for k in cfg.ks)
               + f" | {cfg.gamma * 1e6:.4f} | {cfg.tracking_std**2 * 1e18:.3g} |")
    for r in rows:
        pairs = zip(r["k_pN_per_nm"], r["k_error_pct"], strict=True)
        by_p = dict(zip(r["power_mW"], pairs, strict=True))
        cells = [r["label"]]
        for p in powers:
            k, pct = by_p.get(p, (None, None))
            cells.append(_fmt_k(k, pct))
        cells.append(_gamma_cell(r))
        tv = r.get("tracking_var_nm2")
        if tv is None:
            cells.append("-")
        elif isinstance(tv, list):
            cells.append(f"{np.mean(tv):.3g} *")
        else:
            cells.append(f"{tv:.3g}")
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


# ------------------------------------------------------------------------------------------
# posterior (optional: only if this version of blurtrap has it)
# ------------------------------------------------------------------------------------------
def _posterior_samples(post):
    """Best effort: a mapping name -> 1-D samples from whatever sample_posterior returns."""
    if isinstance(post, Mapping):
        return {str(k): np.asarray(v, dtype=float).ravel() for k, v in post.items()
                if np.ndim(v) >= 1}
    samples = getattr(post, "samples", None)
    if callable(samples):
        samples = samples()
    if isinstance(samples, Mapping):
        return {str(k): np.asarray(v, dtype=float).ravel() for k, v in samples.items()}
    names = getattr(post, "param_names", None)
    for attr in ("flat_samples", "chain", "flatchain"):
        arr = getattr(post, attr, None)
        if callable(arr):
            arr = arr()
        if arr is not None and names is not None:
            a = np.asarray(arr, dtype=float).reshape(-1, len(names))
            return {str(n): a[:, i] for i, n in enumerate(names)}
    getter = getattr(post, "get_chain", None)
    if callable(getter) and names is not None:
        a = np.asarray(getter(flat=True), dtype=float).reshape(-1, len(names))
        return {str(n): a[:, i] for i, n in enumerate(names)}
    return None


def run_posterior(rec, cfg: DemoConfig):
    """Call ``blurtrap.inference.sample_posterior`` with a small number of steps, passing only
    the keywords its signature accepts. Returns (samples or None, raw result)."""
    import jax

    from . import inference

    fn = inference.sample_posterior
    params = inspect.signature(fn).parameters
    kw = {}
    for name, val in (("n_steps", cfg.posterior_steps), ("n_walkers", 16), ("nwalkers", 16),
                      ("seed", cfg.seed), ("progress", False)):
        if name in params:
            kw[name] = val
    if "key" in params:
        kw["key"] = jax.random.key(cfg.seed)
    import warnings

    with warnings.catch_warnings():  # a deliberately short chain: expected warnings
        warnings.simplefilter("ignore")
        post = fn(rec, **kw)
    return _posterior_samples(post), post


# ------------------------------------------------------------------------------------------
# the demo
# ------------------------------------------------------------------------------------------
class _Steps:
    def __init__(self, log):
        self.log = log
        self.records = []

    def run(self, name, fn, *, needs=()) -> Any:  # the step's value; None if it failed
        missing = [n for n in needs if n is None]
        if missing:
            self.records.append({"step": name, "status": "skipped",
                                 "reason": "an earlier step it needs failed", "seconds": 0.0})
            self.log(f"{name}: skipped (an earlier step it needs failed)")
            return None
        self.log(f"{name} ...")
        t = time.perf_counter()
        try:
            out = fn()
        except Exception as exc:  # record, go on with the other steps
            dt = time.perf_counter() - t
            msg = f"{type(exc).__name__}: {exc}".strip().splitlines()[0]
            self.records.append({"step": name, "status": "failed", "error": msg,
                                 "seconds": dt, "traceback": traceback.format_exc()})
            self.log(f"{name}: FAILED ({msg})")
            return None
        dt = time.perf_counter() - t
        self.records.append({"step": name, "status": "ok", "seconds": dt})
        self.log(f"{name}: done ({dt:.1f} s)")
        return out

    def skip(self, name, reason):
        self.records.append({"step": name, "status": "skipped", "reason": reason,
                             "seconds": 0.0})
        self.log(f"{name}: skipped ({reason})")

    @property
    def failed(self):
        return [r for r in self.records if r["status"] == "failed"]


def demo(out="blurtrap-demo", *, quick=False, quiet=False, seed=0, config=None):
    """Run the demo; returns the JSON-able summary dict (see ``blurtrap demo --json``).

    Writes ``report.md``, ``results.json`` and PNG figures into `out`."""
    from . import calibrate, inference

    cfg = config or (quick_config(seed) if quick else DemoConfig(seed=seed))
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    log = _Log(quiet)
    steps = _Steps(log)
    t_start = time.perf_counter()
    powers = list(cfg.powers)
    ws = list(cfg.exposures)
    dt = cfg.frame_interval
    log(f"blurtrap demo: bead radius {cfg.radius * 1e6:.3g} um, gamma = "
        f"{cfg.gamma * 1e6:.4g} pN s/um, k = {', '.join(f'{k * 1e3:.3g}' for k in cfg.ks)} "
        f"pN/nm, {len(ws)} exposures x {cfg.n_frames} frames at {cfg.fps:g} fps"
        + (" (quick)" if quick else ""))

    recs = steps.run(
        f"simulate exposure series ({len(powers)} powers x {len(ws)} exposures x "
        f"{cfg.n_frames} frames)", lambda: simulate_experiment(cfg))
    fig1 = steps.run("simulate Fig. 1 runs (3 settings, ExposureWindows)",
                     lambda: simulate_fig1(cfg))

    def at(p, w):
        return next(r for r in recs if _close(r.laser_power, p) and _close(r.exposure, w))

    rows = []
    res = {}

    # ---- naive equipartition ---------------------------------------------------------
    def naive():
        out_rows = []
        for w in cfg.naive_exposures:
            sel = [at(p, w) for p in powers]
            r = calibrate(sel, method="equipartition")
            res[f"naive_{w}"] = r
            ks, es = _k_by_power(r, sel, powers)
            out_rows.append(make_row(f"naive equipartition, W = {w * 1e3:.3g} ms",
                                     "equipartition", "naive", cfg, powers, ks, es,
                                     exposure=w))
        rows.extend(out_rows)
        return True

    steps.run("naive equipartition", naive, needs=(recs,))

    # ---- variance vs exposure ----------------------------------------------------------
    def vve_each():
        ks, es, gs, ges, tvs = [], [], [], [], []
        for p in powers:
            sel = [r for r in recs if _close(r.laser_power, p)]
            r = calibrate(sel, method="variance_vs_exposure")
            res[f"vve_{p}"] = r
            ks.append(r.k)
            es.append(r.k_err)
            gs.append(r.gamma)
            ges.append(r.gamma_err)
            tvs.append(r.tracking_var)
        rows.append(make_row("variance vs exposure, each power", "variance_vs_exposure",
                             "standard", cfg, powers, ks, es, gs, ges, tvs))
        return True

    if cfg.per_power_variance:
        steps.run("variance vs exposure (each power)", vve_each, needs=(recs,))
    else:
        steps.skip("variance vs exposure (each power)", "--quick")

    def vve_joint():
        r = calibrate(list(recs), method="variance_vs_exposure")
        res["vve_joint"] = r
        ks, es = _k_by_power(r, list(recs), powers)
        rows.append(make_row("variance vs exposure, joint", "variance_vs_exposure",
                             "standard", cfg, powers, ks, es, r.gamma, r.gamma_err,
                             r.tracking_var))
        return r

    joint = steps.run("variance vs exposure (joint: k per power, shared gamma, eps^2)",
                      vve_joint, needs=(recs,))

    # ---- variance vs power ------------------------------------------------------------
    def vvp():
        for w in cfg.power_exposures:
            sel = [at(p, w) for p in powers]
            r = calibrate(sel, method="variance_vs_power")
            res[f"vvp_{w}"] = r
            ks, es = _k_by_power(r, sel, powers)
            rows.append(make_row(f"variance vs power (k = cP), W = {w * 1e3:.3g} ms",
                                 "variance_vs_power", "standard", cfg, powers, ks, es,
                                 r.gamma, r.gamma_err, r.tracking_var, exposure=w))
        return True

    steps.run("variance vs power (k = c P)", vvp, needs=(recs,))

    # ---- blocked PSD and exact likelihood at W = dt -------------------------------------
    psd_fits = {}
    labels = {"naive": "blocked PSD, naive Lorentzian",
              "naive_aliased": "blocked PSD, naive aliased",
              "standard": "blocked PSD, blur + aliasing + noise"}
    for model in cfg.psd_models:
        def psd(model=model):
            ks, es, gs, ges, tvs = [], [], [], [], []
            fits = []
            for p in powers:
                r = calibrate(at(p, dt), method="psd", model=model)
                fits.append(r)
                ks.append(r.k)
                es.append(r.k_err)
                gs.append(r.gamma)
                ges.append(r.gamma_err)
                tvs.append(r.tracking_var)
            psd_fits[model] = fits
            rows.append(make_row(labels[model], "psd", model, cfg, powers, ks, es, gs, ges,
                                 tvs if model == "standard" else None, exposure=dt))
            return True

        steps.run(f"blocked PSD fit, model {model}", psd, needs=(recs,))

    if cfg.exact_likelihood:
        def exact():
            ks, es, gs, ges, tvs = [], [], [], [], []
            for p in powers:
                r = calibrate(at(p, dt), method="likelihood", likelihood="exact")
                res[f"exact_{p}"] = r
                ks.append(r.k)
                es.append(r.k_err)
                gs.append(r.gamma)
                ges.append(r.gamma_err)
                tvs.append(r.tracking_var)
            rows.append(make_row("exact likelihood (ARMA), standard", "likelihood",
                                 "standard", cfg, powers, ks, es, gs, ges, tvs, exposure=dt))
            return True

        steps.run("exact likelihood", exact, needs=(recs,))
    else:
        steps.skip("exact likelihood", "--quick")

    # ---- posterior ------------------------------------------------------------------
    posterior_samples = None
    posterior_note = None
    if not hasattr(inference, "sample_posterior"):
        posterior_note = "posterior: not available in this version"
        log(posterior_note)
        steps.skip("posterior", "not available in this version")
    elif not cfg.posterior:
        posterior_note = "posterior: skipped (--quick)"
        steps.skip("posterior", "--quick")
    else:
        def post():
            p0 = powers[0]
            samples, _ = run_posterior(at(p0, dt), cfg)
            if samples and "k" in samples and "gamma" in samples:
                k, g = samples["k"], samples["gamma"]
                rows.append(make_row("posterior median (emcee), standard", "posterior",
                                     "standard", cfg, [p0], [float(np.median(k))],
                                     [float(np.std(k))], float(np.median(g)),
                                     float(np.std(g)), exposure=dt))
            return samples or {}

        posterior_samples = steps.run("posterior (short run)", post, needs=(recs,))

    # ---- drift (appendix B) ---------------------------------------------------------
    drift_info = {}

    def drift():
        from .inference import drift_extrapolation

        p0 = powers[0]
        rec = add_drift(at(p0, dt), cfg.seed + 7)
        k0 = cfg.c * p0
        fc = k0 / (2 * math.pi * cfg.gamma)
        v0, slope, _, _ = drift_extrapolation(rec.positions, rec.frame_interval,
                                              corner_frequency=fc)
        from .physics import measured_variance

        v_true = float(measured_variance(k0, cfg.gamma, dt, cfg.temperature,
                                         cfg.tracking_std**2))
        drift_info.update(recording=rec, fc=fc, v0_nm2=v0 * 1e18,
                          unfiltered_nm2=float(np.var(rec.positions)) * 1e18,
                          expected_nm2=v_true * 1e18)
        return True

    steps.run("drift: high-pass extrapolation (appendix B)", drift, needs=(recs,))

    # ---- figures ----------------------------------------------------------------------
    figures = []

    def save(fig, name, caption):
        from .plotting import save as save_figure  # saves, then closes the pyplot figure

        path = outdir / f"{name}.png"
        save_figure(fig, path, dpi=110)
        figures.append({"file": path.name, "caption": caption})

    def figs():
        from . import plotting as bp

        truth = {"k": cfg.ks[0], "gamma": cfg.gamma, "tracking_var": cfg.tracking_std**2,
                 "temperature": cfg.temperature}
        errors = []

        def attempt(name, make, caption):
            try:
                save(make(), name, caption)
            except Exception as exc:
                errors.append(f"{name}: {type(exc).__name__}: {exc}")
                log(f"figure {name}: FAILED ({exc})")

        if fig1 is not None:
            x1, k1, g1, dt1 = fig1
            attempt("fig1a_universal_curve",
                    lambda: bp.fig1a_universal_curve(x1, cfg.fig1_windows, k1, g1,
                                                     temperature=cfg.temperature,
                                                     frame_interval=dt1),
                    "Fig. 1a: simulated fractional variance vs alpha = W/tau for the paper's "
                    "three settings, collapsing on S(alpha).")

            def f1b():
                from .data import Recording

                j = list(cfg.fig1_windows).index(4e-3) if 4e-3 in cfg.fig1_windows else -1
                rec = Recording(x1[2, j, 0], frame_interval=dt1, exposure=cfg.fig1_windows[j],
                                temperature=cfg.temperature)
                return bp.fig1b_histogram(rec, {"k": k1[2], "gamma": g1[2],
                                                "temperature": cfg.temperature})

            attempt("fig1b_histogram", f1b,
                    "Fig. 1b: histogram of blurred frames (setting iii, W = 4 ms) with the "
                    "predicted blurred normal (solid) and the blur-free normal (dotted).")
        if joint is not None:
            attempt("fig3_fractional_variance",
                    lambda: bp.fig3_fractional_variance(list(recs), joint),
                    "Fig. 3: (var - eps^2)/(kT/k) vs alpha at 4 powers, rescaled with the "
                    "joint variance-vs-exposure fit, on S(alpha).")
        if recs is not None:
            corr = {}
            for p in powers:
                r = res.get(f"vve_{p}")
                if r is not None:
                    corr[p] = (r.k, r.k_err)
            if len(corr) < len(powers) and joint is not None:  # --quick: the joint fit
                kj, ej = _k_by_power(joint, list(recs), powers)
                corr = {p: (kk, ee) for p, kk, ee in zip(powers, kj, ej, strict=True)}
            if len(corr) == len(powers):
                pfits = {w: res[f"vvp_{w}"] for w in cfg.power_exposures if f"vvp_{w}" in res}
                attempt("fig4_stiffness_vs_power",
                        lambda: bp.fig4_stiffness_vs_power(
                            list(recs), corr, naive_exposures=cfg.naive_exposures,
                            power_fits=pfits, truth_c=cfg.c),
                        "Fig. 4: naive equipartition k at W = 1 and 2 ms vs the blur-corrected "
                        "k (variance vs exposure); dashed: k = cP blur-model fits.")
        if "recording" in drift_info:
            attempt("fig5_highpass",
                    lambda: bp.fig5_highpass(drift_info["recording"], drift_info["fc"],
                                             params=truth),
                    "Fig. 5: variance vs high-pass cut-off of a drifting recording "
                    "(lowest power), linear fit extrapolated to 0 Hz.")
        if "standard" in psd_fits:
            rec0 = at(powers[0], dt)
            fits0 = [psd_fits[m][0] for m in ("standard", "naive", "naive_aliased")
                     if m in psd_fits]
            attempt("fig6_psd", lambda: bp.fig6_psd(rec0, fits0),
                    "Fig. 6: blocked PSD (lowest power, W = dt) with the blur-corrected aliased "
                    "fit (solid), naive (dashed) and naive aliased (dotted).")
            attempt("fig7_deviation", lambda: bp.fig7_deviation(rec0, psd_fits["standard"][0]),
                    "Fig. 7: data/model of the blur-corrected PSD fit with the 1/sqrt(n_b) "
                    "band; histogram with the normal and Gamma(n_b) laws.")
        if "standard" in psd_fits and "naive" in psd_fits:
            attempt("residuals_before_after",
                    lambda: bp.residuals_before_after(psd_fits["naive"][0],
                                                      psd_fits["standard"][0], rec0,
                                                      labels=("before (naive)",
                                                              "after (standard)")),
                    "PSD residuals before (naive model) and after adding motion blur, "
                    "aliasing and tracking noise (standard model).")
        kg, wg, err = naive_error_grid(cfg)
        attempt("naive_error_map",
                lambda: bp.naive_error_map(kg, wg, err,
                                           title=f"naive equipartition error, R = "
                                                 f"{cfg.radius * 1e6:.3g} um, eps = "
                                                 f"{cfg.tracking_std * 1e9:.2g} nm"),
                "Relative error of naive equipartition k over stiffness x exposure for this "
                "bead (analytic, var = kT/k S(alpha) + eps^2).")
        if posterior_samples:
            keep = {k: v for k, v in posterior_samples.items()
                    if k in ("k", "gamma", "tracking_var")} or posterior_samples
            attempt("corner", lambda: bp.corner(keep, truths=truth),
                    "Posterior of the lowest-power recording (short emcee run).")
        if errors:
            raise RuntimeError("; ".join(errors))
        return True

    steps.run("figures", figs)

    # ---- outputs ----------------------------------------------------------------------
    runtime = time.perf_counter() - t_start
    settings = {
        "bead_radius_um": cfg.radius * 1e6,
        "viscosity_mPa_s": cfg.viscosity * 1e3,
        "temperature_K": cfg.temperature,
        "gamma_true_pN_s_per_um": cfg.gamma * 1e6,
        "laser_power_mW": [p * 1e3 for p in cfg.powers],
        "k_true_pN_per_nm": [k * 1e3 for k in cfg.ks],
        "c_true_pN_per_nm_per_W": cfg.c * 1e3,
        "exposures_ms": [w * 1e3 for w in cfg.exposures],
        "frame_intervals_ms": [d * 1e3 for d in cfg.frame_intervals()],
        "camera_fps": cfg.fps,
        "tracking_nm": cfg.tracking_std * 1e9,
        "n_frames": cfg.n_frames,
        "seed": cfg.seed,
        "quick": bool(quick),
    }
    summary = {
        "ok": not steps.failed,
        "out": str(outdir),
        "settings": settings,
        "results": rows,
        "drift": {k: v for k, v in drift_info.items() if k != "recording"},
        "posterior": posterior_note or ("ok" if posterior_samples else "no samples"),
        "steps": [{k: v for k, v in s.items() if k != "traceback"} for s in steps.records],
        "figures": [f["file"] for f in figures],
        "report": str(outdir / "report.md"),
        "runtime_s": runtime,
        "units": "lab (pN/nm, pN s/um, nm^2, ms, mW, Hz)",
    }
    try:
        (outdir / "report.md").write_text(
            _report(summary, rows, cfg, figures, steps.records, drift_info, posterior_note),
            encoding="utf-8")
        (outdir / "results.json").write_text(json.dumps(summary, indent=1), encoding="utf-8")
    except Exception as exc:  # pragma: no cover - disk errors
        summary["ok"] = False
        summary["steps"].append({"step": "report", "status": "failed", "error": str(exc)})
    summary["table"] = format_table(rows, cfg)
    return summary


def _report(summary, rows, cfg, figures, step_records, drift_info, posterior_note) -> str:
    from . import __version__

    s = summary["settings"]
    lines = [
        "# blurtrap demo: calibrating a blurred, aliased optical trap",
        "",
        f"blurtrap {__version__}. Simulated experiment after Wong & Halvorsen, Opt. Express 14, "
        "12517 (2006), section 4; all numbers in lab units.",
        "",
        "## Setup",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| bead radius | {s['bead_radius_um']:.3g} um (polystyrene, 3.063 um diameter) |",
        f"| viscosity, temperature | {s['viscosity_mPa_s']:.3g} mPa s, {s['temperature_K']:g} K |",
        f"| friction gamma = 6 pi eta r (truth) | {s['gamma_true_pN_s_per_um']:.4f} pN s/um |",
        f"| laser powers | {', '.join(f'{p:g}' for p in s['laser_power_mW'])} mW |",
        f"| stiffness k = c P (truth) | "
        f"{', '.join(f'{k:.3g}' for k in s['k_true_pN_per_nm'])} pN/nm "
        f"(c = {s['c_true_pN_per_nm_per_W']:.3g} pN/nm/W) |",
        f"| exposures W | {', '.join(f'{w:.3g}' for w in s['exposures_ms'])} ms |",
        f"| frame intervals | {', '.join(f'{d:.3g}' for d in s['frame_intervals_ms'])} ms "
        f"(camera {s['camera_fps']:g} fps; longer exposures at frame interval = W) |",
        f"| tracking error | {s['tracking_nm']:g} nm rms |",
        f"| frames per recording | {s['n_frames']} (simulate, method exact_frames) |",
        "",
        "## Results",
        "",
        "Stiffness per laser power and friction, estimate (error vs truth). `*`: mean of "
        "per-power fits. PSD and likelihood fits use the recordings at W = dt = "
        f"{cfg.frame_interval * 1e3:.3g} ms.",
        "",
        markdown_table(rows, cfg),
        "",
        "Naive equipartition ignores motion blur: blur lowers the measured variance by "
        "S(alpha), so kT/var over-estimates k, the more so the longer the exposure and the "
        "stiffer the trap. The blur-corrected methods agree with the truth to within a few "
        "standard errors (all standard errors are in `results.json`). The naive PSD fits "
        "look acceptable but return biased k and gamma (paper appendix C).",
        "",
    ]
    if drift_info:
        lines += [
            "### Drift (appendix B)",
            "",
            f"Lowest power with added slow drift: unfiltered variance "
            f"{drift_info['unfiltered_nm2']:.4g} nm^2, extrapolated drift-free variance "
            f"{drift_info['v0_nm2']:.4g} nm^2, model (no drift) "
            f"{drift_info['expected_nm2']:.4g} nm^2.",
            "",
        ]
    if posterior_note:
        lines += [posterior_note, ""]
    lines += ["## Figures", ""]
    for f in figures:
        lines += [f"![{f['file']}]({f['file']})", "", f"*{f['caption']}*", ""]
    lines += ["## Steps", "", "| step | status | time [s] |", "|---|---|---|"]
    for r in step_records:
        st = r["status"] + (f": {r['error']}" if r.get("error") else "") + (
            f" ({r['reason']})" if r.get("reason") else "")
        lines.append(f"| {r['step']} | {st} | {r['seconds']:.1f} |")
    lines += ["", f"Total runtime: {summary['runtime_s']:.1f} s.", "",
              "Reproduce with `blurtrap demo" + (" --quick" if s["quick"] else "")
              + f" --seed {s['seed']}`.", ""]
    return "\n".join(lines)


def run_demo(args) -> int:
    """Entry point of ``blurtrap demo`` (argparse namespace with out, json, quick, seed)."""
    summary = demo(args.out, quick=bool(getattr(args, "quick", False)),
                   quiet=bool(getattr(args, "json", False)), seed=int(getattr(args, "seed", 0)))
    if getattr(args, "json", False):
        out = {k: v for k, v in summary.items() if k != "table"}
        print(json.dumps(out))
    else:
        print(summary["table"])
        if summary["posterior"] == "posterior: not available in this version":
            print(summary["posterior"])
        print(f"report: {summary['report']}  ({len(summary['figures'])} figures, "
              f"{summary['runtime_s']:.1f} s)")
    failed = [s for s in summary["steps"] if s["status"] == "failed"]
    if failed:
        names = ", ".join(s["step"] for s in failed)
        print(f"blurtrap demo: error: {len(failed)} step(s) failed: {names} "
              f"(see {summary['report']})", file=sys.stderr)
        return 1
    return 0
