"""The calibrations of ``blurtrap demo``: every estimator of the package run on the simulated
experiment, each as one step that appends its table row (:class:`DemoRun` holds what the steps
share), plus a short posterior run and the drift-extrapolation check (appendix B)."""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ._demo_experiment import DemoConfig, add_drift
from ._demo_report import _close, _k_by_power, make_row


@dataclasses.dataclass
class DemoRun:
    """What the demo's steps share: the configuration, the simulated recordings (``None`` if
    their step failed), the table rows and the fits the figures need."""

    cfg: DemoConfig
    recs: Any = None  # RecordingSet of the exposure series
    fig1: Any = None  # (positions, ks, gammas, dt) of the Fig. 1 runs
    rows: list = dataclasses.field(default_factory=list)
    res: dict = dataclasses.field(default_factory=dict)  # fits by key (naive_W, vve_P, ...)
    joint: Any = None  # the joint variance-vs-exposure fit
    psd_fits: dict = dataclasses.field(default_factory=dict)  # model -> fits per power
    drift_info: dict = dataclasses.field(default_factory=dict)
    posterior_samples: Any = None

    @property
    def powers(self) -> list:
        return list(self.cfg.powers)

    def at(self, p, w):
        """The recording at laser power ``p`` and exposure ``w``."""
        return next(r for r in self.recs if _close(r.laser_power, p) and _close(r.exposure, w))


# ------------------------------------------------------------------------------------------
# the estimators, one step each
# ------------------------------------------------------------------------------------------
def naive_equipartition(run: DemoRun) -> bool:
    from . import calibrate

    cfg, powers = run.cfg, run.powers
    out_rows = []
    for w in cfg.naive_exposures:
        sel = [run.at(p, w) for p in powers]
        r = calibrate(sel, method="equipartition")
        run.res[f"naive_{w}"] = r
        ks, es = _k_by_power(r, sel, powers)
        out_rows.append(make_row(f"naive equipartition, W = {w * 1e3:.3g} ms",
                                 "equipartition", "naive", cfg, powers, ks, es,
                                 exposure=w))
    run.rows.extend(out_rows)
    return True


def variance_vs_exposure_each(run: DemoRun) -> bool:
    from . import calibrate

    cfg, powers = run.cfg, run.powers
    ks, es, gs, ges, tvs = [], [], [], [], []
    for p in powers:
        sel = [r for r in run.recs if _close(r.laser_power, p)]
        r = calibrate(sel, method="variance_vs_exposure")
        run.res[f"vve_{p}"] = r
        ks.append(r.k)
        es.append(r.k_err)
        gs.append(r.gamma)
        ges.append(r.gamma_err)
        tvs.append(r.tracking_var)
    run.rows.append(make_row("variance vs exposure, each power", "variance_vs_exposure",
                             "standard", cfg, powers, ks, es, gs, ges, tvs))
    return True


def variance_vs_exposure_joint(run: DemoRun):
    from . import calibrate

    cfg, powers = run.cfg, run.powers
    r = calibrate(list(run.recs), method="variance_vs_exposure")
    run.res["vve_joint"] = r
    ks, es = _k_by_power(r, list(run.recs), powers)
    run.rows.append(make_row("variance vs exposure, joint", "variance_vs_exposure",
                             "standard", cfg, powers, ks, es, r.gamma, r.gamma_err,
                             r.tracking_var))
    return r


def variance_vs_power(run: DemoRun) -> bool:
    from . import calibrate

    cfg, powers = run.cfg, run.powers
    for w in cfg.power_exposures:
        sel = [run.at(p, w) for p in powers]
        r = calibrate(sel, method="variance_vs_power")
        run.res[f"vvp_{w}"] = r
        ks, es = _k_by_power(r, sel, powers)
        run.rows.append(make_row(f"variance vs power (k = cP), W = {w * 1e3:.3g} ms",
                                 "variance_vs_power", "standard", cfg, powers, ks, es,
                                 r.gamma, r.gamma_err, r.tracking_var, exposure=w))
    return True


PSD_LABELS = {"naive": "blocked PSD, naive Lorentzian",
              "naive_aliased": "blocked PSD, naive aliased",
              "standard": "blocked PSD, blur + aliasing + noise"}


def blocked_psd(run: DemoRun, model: str) -> bool:
    """Blocked-PSD fit of ``model`` at each power, W = dt."""
    from . import calibrate

    cfg, powers, dt = run.cfg, run.powers, run.cfg.frame_interval
    ks, es, gs, ges, tvs = [], [], [], [], []
    fits = []
    for p in powers:
        r = calibrate(run.at(p, dt), method="psd", model=model)
        fits.append(r)
        ks.append(r.k)
        es.append(r.k_err)
        gs.append(r.gamma)
        ges.append(r.gamma_err)
        tvs.append(r.tracking_var)
    run.psd_fits[model] = fits
    run.rows.append(make_row(PSD_LABELS[model], "psd", model, cfg, powers, ks, es, gs, ges,
                             tvs if model == "standard" else None, exposure=dt))
    return True


def exact_likelihood(run: DemoRun) -> bool:
    from . import calibrate

    cfg, powers, dt = run.cfg, run.powers, run.cfg.frame_interval
    ks, es, gs, ges, tvs = [], [], [], [], []
    for p in powers:
        r = calibrate(run.at(p, dt), method="likelihood", likelihood="exact")
        run.res[f"exact_{p}"] = r
        ks.append(r.k)
        es.append(r.k_err)
        gs.append(r.gamma)
        ges.append(r.gamma_err)
        tvs.append(r.tracking_var)
    run.rows.append(make_row("exact likelihood (ARMA), standard", "likelihood",
                             "standard", cfg, powers, ks, es, gs, ges, tvs, exposure=dt))
    return True


def posterior(run: DemoRun):
    """A short posterior run at the lowest power, W = dt; its median row if k and gamma were
    sampled. Returns the samples (``{}`` when none)."""
    cfg, dt = run.cfg, run.cfg.frame_interval
    p0 = run.powers[0]
    samples, _ = run_posterior(run.at(p0, dt), cfg)
    if samples and "k" in samples and "gamma" in samples:
        k, g = samples["k"], samples["gamma"]
        run.rows.append(make_row("posterior median (emcee), standard", "posterior",
                                 "standard", cfg, [p0], [float(np.median(k))],
                                 [float(np.std(k))], float(np.median(g)),
                                 float(np.std(g)), exposure=dt))
    return samples or {}


def drift(run: DemoRun) -> bool:
    """High-pass extrapolation (appendix B) of the lowest-power recording with added drift."""
    from .inference import drift_extrapolation

    cfg, dt = run.cfg, run.cfg.frame_interval
    p0 = run.powers[0]
    rec = add_drift(run.at(p0, dt), cfg.seed + 7)
    k0 = cfg.c * p0
    fc = k0 / (2 * math.pi * cfg.gamma)
    v0, slope, _, _ = drift_extrapolation(rec.positions, rec.frame_interval,
                                          corner_frequency=fc)
    from .physics import measured_variance

    v_true = float(measured_variance(k0, cfg.gamma, dt, cfg.temperature,
                                     cfg.tracking_std**2))
    run.drift_info.update(recording=rec, fc=fc, v0_nm2=v0 * 1e18,
                          unfiltered_nm2=float(np.var(rec.positions)) * 1e18,
                          expected_nm2=v_true * 1e18)
    return True


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
