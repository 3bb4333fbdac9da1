"""``blurtrap.calibrate``: every method of the paper plus exact and Whittle likelihoods."""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import warnings
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope, warn_if_float32
from ..physics._constants import BOLTZMANN
from ._allan import fit_allan
from ._fit import chi2_sf, fit_ml, fit_ml_fd_newton, fit_nll_only
from ._fixed import expand as expand_fixed
from ._fixed import propagate as propagate_fixed
from ._fixed import reduce as reduce_fixed
from ._fixed import reduced_objective
from ._instrument import finish_instrument, prepare_instrument
from ._models import TrapModel, get_model
from ._problems import (
    SpectralArgs,
    exact_nll,
    make_exact_args,
    make_layout,
    rec_meta,
    spectral_model_psd,
    spectral_nll,
)
from ._profile import ProfileIntervals
from ._result import LAB as _LAB_UNITS
from ._result import CalibrationResult, FitError
from ._variance import (
    VarianceArgs,
    empirical_variance_se,
    fit_variances,
    profile_intervals,
)

METHODS = ("auto", "likelihood", "psd", "variance_vs_exposure", "variance_vs_power",
           "equipartition", "allan")


def as_recordings(data: Any) -> list:
    """Accept a Recording, a RecordingSet, a sequence of Recordings or a path."""
    if isinstance(data, (str, os.PathLike)):
        from ..data import load

        data = load(data)
    if hasattr(data, "positions") and hasattr(data, "frame_interval"):
        recs = [data]
    elif hasattr(data, "shape") and hasattr(data, "dtype"):
        raise TypeError(
            f"data is a bare array of shape {tuple(data.shape)}: its frame interval and exposure "
            "are unknown. Wrap arrays with blurtrap.from_arrays(positions, frame_interval=..., "
            "exposure=...)."
        )
    elif isinstance(data, dict):
        raise TypeError(
            "data is a dict; expected a Recording, a RecordingSet, a list of Recordings or a "
            "manifest path (load a manifest dict with blurtrap.load or build Recordings with "
            "blurtrap.from_arrays)"
        )
    else:
        try:
            recs = list(data)
        except TypeError:
            raise TypeError(
                "data must be a Recording, a RecordingSet, a list of Recordings or a manifest "
                f"path; got {type(data).__name__}. Wrap arrays with blurtrap.from_arrays(...)."
            ) from None
    if not recs:
        raise ValueError("data holds no recordings")
    for i, r in enumerate(recs):
        if not (hasattr(r, "positions") and hasattr(r, "frame_interval")):
            hint = (" (a bare array: its frame interval and exposure are unknown; wrap arrays "
                    "with blurtrap.from_arrays(positions, frame_interval=..., exposure=...))"
                    if hasattr(r, "shape") else "")
            raise TypeError(f"data[{i}] is a {type(r).__name__}; expected a Recording{hint}")
        warn_if_float32("positions", r.positions)
    return recs


# ------------------------------------------------------------------------------------------
# start values from closed forms (host-side numpy: no JAX dispatch or compilation)
# ------------------------------------------------------------------------------------------
def _np_blur_factor(a: float) -> float:
    if a < 1e-3:
        return 1.0 - a / 3.0 + a * a / 12.0 - a**3 / 60.0
    return 2.0 / a * (1.0 + math.expm1(-a) / a)


def _np_rho_b(a: float, r: float) -> float:
    phi1 = 1.0 - a / 2.0 + a * a / 6.0 if a < 1e-6 else -math.expm1(-a) / a
    return phi1 * phi1 * math.exp(a - r)


def _np_periodogram(y, dt, n_blocks=1):
    y = np.asarray(y, dtype=float)
    m = y.size // n_blocks
    if m < 4:
        raise ValueError(
            f"n_blocks = {n_blocks} leaves {m} frames per block for a record of {y.size} "
            "frames; need at least 4 frames per block"
        )
    blocks = y[: m * n_blocks].reshape(n_blocks, m)
    blocks = blocks - blocks.mean(axis=1, keepdims=True)
    spec = np.fft.rfft(blocks, axis=1)[:, 1:]
    p = (spec.real**2 + spec.imag**2).mean(axis=0) * dt / m
    f = np.arange(1, m // 2 + 1) / (m * dt)
    return f, p, m


def moment_start(rec):
    """Closed-form moment estimate of (k, gamma, eps2) from lags 0, 1, 2.

    In the model ``C(2)/C(1) = rho`` exactly (blur and noise cancel), ``C(1) = sigma2 B rho``
    and ``C(0) = sigma2 S + eps2``; the estimate is clipped into the physical range and falls
    back to ``tau = dt`` when lag correlations are not resolved (dt >> tau).
    Returns ``(k, gamma, eps2, rho_hat)``.
    """
    y = np.asarray(rec.positions, dtype=float)
    y = y - y.mean()
    n = y.size
    c0 = float(np.mean(y * y))
    c1 = float(np.mean(y[1:] * y[:-1])) if n > 2 else 0.0
    c2 = float(np.mean(y[2:] * y[:-2])) if n > 3 else 0.0
    dt, w, t = float(rec.frame_interval), float(rec.exposure), float(rec.temperature)
    kt = BOLTZMANN * t
    rho = c2 / c1 if c1 > 0 else 0.0
    if not (0.02 < rho < 0.99999) or c1 <= 0:
        rho_used = min(max(rho, 0.05), 0.99999) if c1 > 0 else math.exp(-1.0)
    else:
        rho_used = rho
    tau = -dt / math.log(rho_used)
    a, r = w / tau, dt / tau
    sigma2 = c1 / _np_rho_b(a, r) if c1 > 0 else c0
    s = _np_blur_factor(a)
    sigma2 = min(max(sigma2, 0.3 * c0 / s), 3.0 * c0 / s)
    eps2 = c0 - sigma2 * s
    eps2 = max(eps2, 0.02 * c0)
    k = kt / sigma2
    return k, k * tau, eps2, rho


def temporal_information(rec, z_min=5.0):
    """Whether frames carry information on the relaxation time: the lag-1 autocorrelation
    is significantly positive, ``r1 sqrt(N) > z_min`` (under white frames r1 sqrt(N) is
    standard normal). Frames lose it when dt >> tau (and W << dt), or when the tracking noise
    swamps the motion. Returns ``(informative, z)``."""
    y = np.asarray(rec.positions, dtype=float)
    y = y - y.mean()
    n = y.size
    if n < 8:
        return False, 0.0
    c0 = float(np.mean(y * y))
    c1 = float(np.mean(y[1:] * y[:-1]))
    z = c1 / c0 * math.sqrt(n) if c0 > 0 else 0.0
    return bool(z > z_min), z


#: a frame this many robust SDs (1.4826 x median absolute deviation) from the median is an
#: outlier (a Gaussian trace of 1e7 frames reaches ~5.5)
_OUTLIER_Z = 8.0


def _outliers(rec):
    """``(count, index, value, robust SDs)`` of frames more than ``_OUTLIER_Z`` robust SDs
    from the median (count 0 when there are none)."""
    y = np.asarray(rec.positions, dtype=float)
    med = float(np.median(y))
    mad = 1.4826 * float(np.median(np.abs(y - med)))
    if not mad > 0:
        return 0, 0, float(y[0]), 0.0
    dev = np.abs(y - med) / mad
    j = int(np.argmax(dev))
    return int(np.sum(dev > _OUTLIER_Z)), j, float(y[j]), float(dev[j])


def _robust_temporal_z(rec) -> float:
    """The lag-1 statistic of :func:`temporal_information` with the frames clipped to the
    median +- ``_OUTLIER_Z`` robust SDs: a few outliers dominate the variance and hide the
    correlation of all other frames (identical to the plain statistic without outliers)."""
    y = np.asarray(rec.positions, dtype=float)
    med = float(np.median(y))
    mad = 1.4826 * float(np.median(np.abs(y - med)))
    if mad > 0:
        y = np.clip(y, med - _OUTLIER_Z * mad, med + _OUTLIER_Z * mad)
    y = y - y.mean()
    if y.size < 8:
        return 0.0
    c0 = float(np.mean(y * y))
    return float(np.mean(y[1:] * y[:-1])) / c0 * math.sqrt(y.size) if c0 > 0 else 0.0


def _outlier_sentence(recs, z_min=5.0) -> str:
    """A sentence on outliers that hide the lag correlation ('' when there are none)."""
    for i, r in enumerate(recs):
        n_out, j, val, dev = _outliers(r)
        if n_out:
            zr = _robust_temporal_z(r)
            hides = (f"with them clipped the lag-1 correlation is {zr:.1f} standard errors "
                     "above 0, so the frames do resolve the relaxation: remove the outliers "
                     "(or the stretch around them) and fit again" if zr > z_min else
                     "remove them (or the stretch around them)")
            return (f"outliers: recording {i} has {n_out} frame(s) more than {_OUTLIER_Z:g} "
                    f"robust SDs from its median (frame {j}: {val:.4g} m, {dev:.3g} SDs); "
                    + hides)
    return ""


def _start_vector(recs, layout, noise, start=None):
    if start:
        missing = [n for n in layout.names if n not in start]
        if not missing:
            return jnp.asarray(np.array([float(start[n]) for n in layout.names]))
        base = _start_vector(recs, layout, noise)
        return jnp.asarray(np.array([float(start.get(n, base[i]))
                                     for i, n in enumerate(layout.names)]))
    starts = np.array([moment_start(r)[:3] for r in recs])
    ks = starts[:, 0]
    if layout.linear_power:
        kvec = [np.median(ks / np.asarray(layout.power))]
    else:
        idx = np.asarray(layout.k_index)
        kvec = [np.median(ks[idx == j]) for j in range(layout.n_k)]
    vec: list = list(kvec) + [np.median(starts[:, 1])]
    if noise:
        vec.append(np.median(starts[:, 2]))
    for name in getattr(layout, "extra_names", ()):
        vec.append(effect_start(name, recs, float(np.median(starts[:, 1]))))
    return jnp.asarray(np.array(vec, dtype=float))


def effect_start(name: str, recs, gamma: float) -> float:
    """Rough, positive start values for effect parameters (refined by the fit)."""
    c0 = float(np.median([np.var(np.asarray(r.positions)) for r in recs]))
    dur = float(np.median([r.n_frames * float(r.frame_interval) for r in recs]))
    fs = float(np.median([1.0 / float(r.frame_interval) for r in recs]))
    powers = [float(r.laser_power) for r in recs if r.laser_power is not None]
    temp = float(np.median([float(r.temperature) for r in recs]))
    from ..physics import water_viscosity
    table = {
        "drift_diffusion": 0.01 * c0 / dur,
        "line_amplitude": 0.1 * math.sqrt(c0),
        "rise_fraction": 0.1,
        "f3db": min(0.25 * fs, 8000.0),
        "diode_alpha": 0.3,
        "hydro_radius": gamma / (6 * math.pi * float(water_viscosity(np.clip(temp, 274, 373)))),
        "power_offset": 0.05 * min(powers) if powers else 1e-3,
        "heating": 10.0,
    }
    if name not in table:
        raise ValueError(f"no start value rule for effect parameter {name!r}")
    return table[name]


# ------------------------------------------------------------------------------------------
# goodness of fit
# ------------------------------------------------------------------------------------------
def spectral_gof(ratio, weight, n_params, min_dof=64):
    """Binned test of periodogram/model ratios (each has mean 1, variance 1/n_blocks).

    ``ratio`` and ``weight`` have shape (R, M) (weight 0 on padding). Consecutive ordinates
    of each recording are pooled into bins worth >= ``min_dof`` exponential degrees of
    freedom, so each bin mean is close to normal with variance 1/(bin weight);
    ``T = sum_b W_b (mean_b - 1)^2 ~ chi^2(n_bins - n_params)``.
    """
    ratio, weight = np.asarray(ratio), np.asarray(weight)
    stat, nb = 0.0, 0
    for q, wt in zip(ratio, weight):
        keep = wt > 0
        q, wt = q[keep], wt[keep]
        if q.size == 0:
            continue
        per = max(1, int(math.ceil(min_dof / float(np.median(wt)))))
        nbin = len(q) // per
        if nbin == 0:
            continue
        qb = q[: nbin * per].reshape(nbin, per)
        wb = wt[: nbin * per].reshape(nbin, per)
        means = np.sum(qb * wb, axis=1) / np.sum(wb, axis=1)
        stat += float(np.sum(np.sum(wb, axis=1) * (means - 1.0) ** 2))
        nb += nbin
    dof = max(nb - n_params, 1)
    p = float(chi2_sf(stat, dof))
    return {"test": "binned spectral chi2", "statistic": stat, "dof": dof, "p_value": p}


# ------------------------------------------------------------------------------------------
# spectral (Whittle / blocked) and exact likelihood fits
# ------------------------------------------------------------------------------------------
def _spectral_args(recs, layout, model, n_blocks, f_range, excluded=None):
    """Periodogram ordinates of all recordings. Whenever the model has the closed form, its
    expectation is the exact expected periodogram of a block of M frames (the Fejer-kernel
    leakage of the finite block included, same cost as P_d): for blocked spectra and for the
    full-record Whittle likelihood alike, so that records that are not long compared with
    tau are not biased. Models with extra effects use P_d(f) (leakage O(tau/T); measured for a
    photodiode filter at 100 kHz: the expected periodogram exceeds P_d by ~1.5 % near Nyquist
    at 2^14 samples, 6 % at 2^12. Adding the closed-form trap's leakage fixed that but made
    the autodiff fits of these models ~2x slower to compile; not yet done)."""
    fs, ps, ws, ms = [], [], [], []
    for r in recs:
        nb = max(int(n_blocks), 1)
        f, p, m = _np_periodogram(r.positions, float(r.frame_interval), nb)
        ms.append(m)
        wt = np.full(f.shape, float(nb))
        if m % 2 == 0:
            wt[-1] *= 0.5  # Nyquist ordinate is chi^2_1
        if f_range is not None:
            sel = (f >= f_range[0]) & (f <= f_range[1])
            f, p, wt = f[sel], p[sel], wt[sel]
        for a, b in excluded or ():
            wt = np.where((f >= a) & (f <= b), 0.0, wt)  # excluded ordinates: no weight
        fs.append(f)
        ps.append(p)
        ws.append(wt)
    m_max = max(len(f) for f in fs)
    if m_max == 0:
        raise ValueError(f"f_range = {f_range} Hz leaves no frequencies to fit")
    ref = float(np.mean(np.concatenate(ps)))

    def pad(arrs, fill):
        return np.stack([np.concatenate([a, np.full(m_max - len(a), fill)]) for a in arrs])

    dts = np.array([float(r.frame_interval) for r in recs])
    f2 = pad([f for f in fs], 0.0)
    f2 = np.where(f2 == 0.0, 0.25 / dts[:, None], f2)  # harmless value on padding
    return SpectralArgs(
        layout=layout,
        model=model,
        meta=rec_meta(recs),
        f=jnp.asarray(f2),
        s2=jnp.asarray(np.sin(np.pi * f2 * dts[:, None]) ** 2),
        power=jnp.asarray(pad(ps, ref)),
        weight=jnp.asarray(pad(ws, 0.0)),
        log_ref=jnp.asarray(np.log(ref)),
        block_len=(jnp.asarray(np.array(ms, dtype=float))
                   if model.alias and model.closed_form else None),
    )


_psd_jit = eqx.filter_jit(spectral_model_psd)


def _slow_relaxation_hint(recs, values, names):
    """A sentence when the fitted tau is not short compared with the record (else '')."""
    if "gamma" not in names or "k" not in names:
        return ""
    tau = float(values[names.index("gamma")]) / float(values[names.index("k")])
    dur = min(r.n_frames * float(r.frame_interval) for r in recs)
    if math.isfinite(tau) and tau > dur / 30.0:
        info = [temporal_information(r) for r in recs]
        if all(z < 0.5 * math.sqrt(r.n_frames) for r, (_, z) in zip(recs, info)):
            return f" The fit ran tau = gamma/k to {tau:.3g} s, but " + \
                _no_temporal_information_message(recs, info)
        return (f" The fitted relaxation time tau = gamma/k = {tau:.3g} s is not short compared "
                f"with the record ({dur:.3g} s): the bead diffuses almost freely, so k is not "
                "identified; record longer or use a stiffer trap.")
    return ""


def _check_relaxation_resolved(res, recs, method, block_frames=None):
    """Refuse a fit whose relaxation time is longer than a third of the record (or block):
    the bead then diffuses almost freely, the likelihood runs k towards 0, and the observed
    Fisher information at that edge gives a meaningless, tiny error on k. gamma (D) is still
    identified and is quoted in the message."""
    g, ge = res.gamma, res.gamma_err
    if not math.isfinite(g):
        return res
    for i, (r, kk) in enumerate(zip(recs, res.k_per_recording)):
        n = r.n_frames if block_frames is None else min(block_frames, r.n_frames)
        dur = n * float(r.frame_interval)
        tau = g / float(kk)
        if not (tau < dur / 3.0):
            informative, z = temporal_information(r)
            if z < 0.5 * math.sqrt(r.n_frames):  # a freely diffusing bead has r1 ~ 1
                raise FitError(f"{method} fit ran k to {float(kk):.3g} N/m, but the frames are "
                               "far less correlated than a freely diffusing bead's: "
                               + _no_temporal_information_message([r], [(informative, z)]))
            what = "record" if block_frames is None else f"block ({n} frames)"
            d = BOLTZMANN * float(r.temperature) / g
            raise FitError(
                f"{method} fit: the relaxation time tau = gamma/k = {tau:.3g} s of recording {i} "
                f"is longer than a third of the {what} ({dur:.3g} s): the bead diffuses almost "
                f"freely and k is not identified (the fit ran it to {float(kk):.3g} N/m). gamma "
                f"= {g:.4g} +- {ge:.2g} N s/m (D = {d * 1e12:.4g} um^2/s) is still determined. "
                "Record longer than ~10 tau, use a stiffer trap"
                + (", or fewer, longer blocks (n_blocks)" if block_frames else "") + "."
            )
    return res


#: a blocked-PSD fit needs blocks at least this many relaxation times long, and a leakage
#: index sqrt(M) tau/T_block (see `_leakage_index`) of at most this: a 65 536-frame record
#: fitted in one block at index 7.1 (k = 1e-5 pN/nm, dt = W = 1/1500 s, T = 32 tau) put
#: gamma 5.6 SE low, while the photodiode peer set (index 1.5, 8 blocks) is honest
_PSD_MIN_BLOCK_TAU = 20.0
_PSD_LEAKAGE_MAX = 3.0


def _check_psd_blocks(res, recs, n_blocks, explicit):
    """Blocks shorter than ~20 tau leave few, strongly correlated ordinates below the corner
    frequency; the Gamma likelihood of the block averages then treats them as independent
    and reports errors that are far too small (measured: 2048-frame records with tau = T/10
    in one block gave gamma 6-9 SE low, benchmarks/study_robustness.py), and so do long
    records in one block when the leakage index is large. With the default
    block count this is an error (the record itself is too short for a PSD fit); with a
    user's `n_blocks` a note."""
    g = res.gamma
    if not math.isfinite(g):
        return res
    for r, kk in zip(recs, res.k_per_recording):
        m = r.n_frames // n_blocks
        ratio = m * float(r.frame_interval) / (g / float(kk))
        leak = math.sqrt(m) / ratio
        if ratio >= _PSD_MIN_BLOCK_TAU and leak <= _PSD_LEAKAGE_MAX:
            continue
        msg = (f"psd: blocks of {m} frames are only {ratio:.3g} relaxation times "
               f"(tau = gamma/k = {g / float(kk):.3g} s) long (leakage index sqrt(M) tau/T = "
               f"{leak:.2g}; needed: >= {_PSD_MIN_BLOCK_TAU:g} tau and index <= "
               f"{_PSD_LEAKAGE_MAX:g}): neighbouring ordinates are correlated and the "
               "blocked-PSD estimates and errors cannot be trusted")
        if explicit:
            return dataclasses.replace(res, notes=res.notes + (
                msg + "; use fewer blocks (n_blocks) or method='likelihood'",))
        raise FitError(msg + ". The record is too short for a blocked PSD fit: use "
                       "method='likelihood' (exact for any record length).")
    return res


def _singular_fisher_causes(recs, values, names) -> str:
    """What the data say about why a fit failed: dt >> tau only when the frames (outliers
    clipped) really carry no temporal information; otherwise the outliers, steps or record
    length seen in the data, or a neutral list of possible causes."""
    if not recs:
        return ("possible causes: outliers or steps in the trace, a parameter at its bound, "
                "a wrong exposure or frame interval, or too short a record")
    causes = []
    zr = max(_robust_temporal_z(r) for r in recs)
    dt = min(float(r.frame_interval) for r in recs)
    tau = math.nan
    if "gamma" in names and "k" in names:
        tau = float(values[names.index("gamma")]) / float(values[names.index("k")])
    if zr < 5.0:
        causes.append(f"dt >> tau: the lag-1 correlation of the frames is only {zr:.1f} "
                      "standard errors above 0" + (f" (the fit ran tau = gamma/k to {tau:.3g} "
                      f"s; dt = {dt:.3g} s)" if math.isfinite(tau) else "")
                      + ", so there is little temporal information (use recordings at "
                      "several exposures or powers)")
    elif math.isfinite(tau) and tau < dt / 3.0:
        causes.append(f"dt >> tau: the fit puts the relaxation time tau = gamma/k at {tau:.3g} s, "
                      f"shorter than the frame interval {dt:.3g} s, where one recording carries "
                      "too little temporal information for gamma; give the friction "
                      "(friction='stokes' with the bead radius, or fixed={'gamma': ...}) or "
                      "record at several exposures")
    out = _outlier_sentence(recs)
    if out:
        causes.append(out)
    for i, r in enumerate(recs):
        seg = np.array_split(np.asarray(r.positions, dtype=float), 8)
        if len(seg[-1]) < 8:
            continue
        meds = np.array([np.median(v) for v in seg])
        # spread within the segments: a step does not inflate it
        mad = 1.4826 * float(np.median([np.median(np.abs(v - m)) for v, m in zip(seg, meds)]))
        jump = float(meds.max() - meds.min())
        if mad > 0 and jump > 4.0 * mad:
            causes.append(f"a step or drift: the median position of recording {i} moves by "
                          f"{jump:.3g} m ({jump / mad:.2g} robust SDs) across the record")
    n = min(r.n_frames for r in recs)
    if n < 1000:
        causes.append(f"a short record ({n} frames)")
    if not causes:
        return ("nothing in the frames points to one cause; possible causes: outliers or "
                "steps in the trace, a parameter at its bound (e.g. eps^2 -> 0), a wrong "
                "exposure or frame interval, or too short a record")
    return "what the frames show: " + "; ".join(causes)


def _check_fit(out, names, method, strict=True, notes=None, recs=None):
    hint = _slow_relaxation_hint(recs, np.asarray(out.value), names) if recs else ""
    if not bool(out.converged):
        seen = _outlier_sentence(recs) if recs else ""
        raise FitError(
            f"{method} fit did not converge after {int(out.n_steps)} steps "
            f"(max |grad| = {float(out.grad_norm):.3g}); parameters {names}. "
            + (f"The frames show {seen}." if seen else
               "Try another method or check the data (outliers, drift, wrong exposure/frame "
               "interval).")
            + hint
        )
    if not bool(out.hessian_pd):
        if not strict:
            if notes is not None:
                notes.append(f"{method}: the Fisher information is singular (a parameter at "
                             "its bound or unidentifiable): standard errors are NaN" + hint)
            return
        why = _singular_fisher_causes(recs, np.asarray(out.value), names)
        raise FitError(
            f"{method} fit: the Fisher information is singular - the parameters {names} are "
            f"not all identifiable from these data; {why}." + hint
        )
    lost = _unidentified(out, names)
    if lost and strict:
        # with a nuisance parameter at its bound the information of the others is finite,
        # but an SE above the value itself carries no information (white frames, dt >> tau:
        # k 4.4 +- 86 pN/nm): refuse as for a singular information, naming the cause
        why = _singular_fisher_causes(recs, np.asarray(out.value), names)
        raise FitError(
            f"{method} fit: the Fisher information is singular in effect - {lost} have "
            f"standard errors above their values and are not identifiable from these data; "
            f"{why}." + hint
        )


#: k (or c) or gamma with a relative SE above this is not identified by the data
MAX_RELATIVE_SE = 1.0


def _unidentified(out, names) -> list[str]:
    value = np.asarray(out.value, dtype=float)
    se = np.sqrt(np.abs(np.diag(np.asarray(out.cov, dtype=float))))
    core = [i for i, n in enumerate(names) if n in ("k", "c", "gamma") or n.startswith("k[")]
    return [names[i] for i in core
            if np.isfinite(se[i]) and se[i] > MAX_RELATIVE_SE * abs(value[i])]


def _assemble(recs, layout, model, method, values, cov, gof, notes=(), extras=None,
              at_bound=None, interval_source=None):
    """The result of a fit. ``at_bound``: the fit's bound flags (``FitOutput.at_bound``, the
    one rule :func:`blurtrap.inference._fit.at_lower_bound`); those parameters get a NaN error
    (the fit already made their variance NaN and the others' conditional on the bound).
    ``interval_source``: where the result's profile intervals come from
    (:class:`blurtrap.inference._profile.ProfileIntervals`; default: Wald intervals only)."""
    values = np.asarray(values, dtype=float)
    cov = np.asarray(cov, dtype=float)
    names = layout.names
    nk = 1 if layout.linear_power else layout.n_k
    if layout.linear_power:
        powers = np.asarray(layout.power)
        k_rec = values[0] * powers
        k_err = np.sqrt(cov[0, 0]) * powers
    else:
        idx = np.asarray(layout.k_index)
        k_rec = values[:nk][idx]
        k_err = np.sqrt(np.clip(np.diag(cov)[:nk], 0, None))[idx]
    if "power_offset" in names:
        p0 = values[names.index("power_offset")]
        k_rec = k_rec * (1.0 - p0 / np.asarray(layout.power))
    bound = np.zeros(len(names), bool) if at_bound is None else np.asarray(at_bound, bool)
    at_bounds = [n for n, b in zip(names, bound) if b]
    if bound.any():  # NaN error, whatever the caller's covariance says
        cov = cov.copy()
        cov[bound, :] = 0.0
        cov[:, bound] = 0.0
        cov[bound, bound] = np.nan  # (as the fit's own covariance: decoupled, NaN variance)
        notes = tuple(notes) + (
            f"{', '.join(at_bounds)} at the lower bound 0: NaN error there, and the other "
            "errors are conditional on the bound (smaller than the spread of the estimates "
            "when the bound is only nearly reached); result.intervals gives profile-likelihood "
            "intervals that account for it",)
    temps = {float(r.temperature) for r in recs}
    if "drift_diffusion" in names:
        notes = tuple(notes) + (
            "drift_diffusion: its standard error is ~3x too small (half the drift power is the "
            "record's one end-to-end ramp, so the periodogram ordinates are not independent; "
            "the docstring of blurtrap.inference.EFFECTS['drift']); treat it as an order of "
            "magnitude. The errors of k, gamma and eps^2 stay calibrated.",)
    return CalibrationResult(
        method=method,
        model=model.name,
        param_names=tuple(names),
        values=values,
        covariance=cov,
        temperature=float(recs[0].temperature) if len(temps) == 1 else float(np.mean(list(temps))),
        k_per_recording=np.asarray(k_rec, dtype=float),
        k_per_recording_err=np.asarray(k_err, dtype=float),
        gof=gof,
        n_recordings=len(recs),
        n_frames=int(sum(r.n_frames for r in recs)),
        converged=True,
        at_bounds=tuple(at_bounds),
        notes=tuple(notes),
        extras=extras or {},
        interval_source=interval_source,
    )


def _fit_spectral(recs, layout, model, n_blocks, f_range, method_name, notes, start=None,
                  strict=True, fixed=None, excluded=None, robust=False):
    args = _spectral_args(recs, layout, model, n_blocks, f_range, excluded)
    scale = _start_vector(recs, layout, model.noise, start)
    out, held = _fit_held(fit_ml, spectral_nll, scale, args, layout.names, fixed)
    _check_fit(out, layout.names, method_name, strict, notes, recs)
    if robust:
        out, held, args = _robust_refit(out, held, args, scale, layout, fixed, notes,
                                        method_name, strict, recs)
    psd = _psd_jit(out.value, args)
    gof = spectral_gof(args.power / psd, args.weight, len(layout.names))
    extras = {"n_blocks": n_blocks, "nll": float(out.nll), "k_mode": _k_mode_of(layout),
              "f": np.asarray(args.f), "ratio": np.asarray(args.power / psd),
              "weight": np.asarray(args.weight)}
    res = _assemble(recs, layout, model, method_name, out.value, out.cov, gof, notes, extras,
                    at_bound=out.at_bound,
                    interval_source=_interval_source(spectral_nll, args, scale, out, held))
    block = None if n_blocks <= 1 else min(r.n_frames for r in recs) // n_blocks
    return _check_relaxation_resolved(res, recs, method_name, block)


#: robust spectral fit: an ordinate whose Gamma upper tail probability under the fit is below
#: this (Bonferroni over the ordinates) is a spike and gets no weight
ROBUST_ALPHA = 1e-3


def _robust_refit(out, held, args, scale, layout, fixed, notes, method, strict, recs):
    """Drop ordinates far above the fitted spectrum (spikes, lines) and refit, up to 3
    times; the count and the frequencies go into the notes."""
    from jax.scipy.special import gammaincc

    dropped = np.zeros(np.shape(args.weight), bool)
    for _ in range(3):
        w = np.asarray(args.weight)
        ratio = np.asarray(args.power / _psd_jit(out.value, args))
        n_eff = np.where(w > 0, w, 1.0)
        tail = np.asarray(gammaincc(n_eff, n_eff * ratio))
        spikes = (w > 0) & (tail < ROBUST_ALPHA / max(int(np.sum(w > 0)), 1))
        if not spikes.any():
            break
        dropped |= spikes
        args = eqx.tree_at(lambda a: a.weight, args, jnp.asarray(np.where(spikes, 0.0, w)))
        out, held = _fit_held(fit_ml, spectral_nll, scale, args, layout.names, fixed)
        _check_fit(out, layout.names, method, strict, notes, recs)
    if dropped.any():
        fr = np.asarray(args.f)[dropped]
        shown = ", ".join(f"{v:.5g}" for v in fr[:8]) + (" ..." if fr.size > 8 else "")
        notes.append(f"robust: {int(dropped.sum())} ordinate(s) far above the fitted spectrum "
                     f"(Gamma tail p < {ROBUST_ALPHA:g}/M) left out: {shown} Hz")
    else:
        notes.append("robust: no ordinate far above the fitted spectrum")
    return out, held, args


@float64_scope
def screen_model(recs, model, k, start=None):
    """Whittle fit of ``model`` without standard errors: ``(params dict, nll, gof, ok)``.
    Same ordinates and objective as ``calibrate(method='likelihood', likelihood='whittle')``
    so that log-likelihoods of nested models are comparable."""
    mdl = get_model(model)
    layout = make_layout(recs, k, mdl.noise, tuple(p.name for p in mdl.extra_params))
    args = _spectral_args(recs, layout, mdl, 1, None)
    scale = _start_vector(recs, layout, mdl.noise, start)
    p, nll, ok = fit_nll_only(spectral_nll, scale, args)
    psd = _psd_jit(jnp.asarray(p), args)
    gof = spectral_gof(args.power / psd, args.weight, len(layout.names))
    return dict(zip(layout.names, map(float, p))), nll, gof, ok


def _fit_held(fit, nll, scale, args, names, fixed):
    """``fit(nll, scale, args)`` with the parameters in ``fixed`` ({name: (value, se)}) held:
    ``(FitOutput on all parameters, held)``, the input errors propagated into the covariance
    (:mod:`._fixed`); ``held`` is None without fixed parameters, else what the intervals need
    (reduced objective, its start scale, args and output)."""
    if not fixed:
        return fit(nll, scale, args), None
    free, fscale, fargs = reduce_fixed(names, scale, args, fixed)
    red = reduced_objective(nll)
    out = fit(red, fscale, fargs)
    full = expand_fixed(out, free, len(names), fargs.full)
    cov = propagate_fixed(nll, args, full.value, full.cov, names, fixed)
    full = eqx.tree_at(lambda o: o.cov, full, jnp.asarray(cov))
    return full, (red, fscale, fargs, out, free, any(se > 0 for _, se in fixed.values()))


def _interval_source(nll, args, scale, out, held, hessian="auto"):
    """Profile intervals of the fit (of its free parameters when some are held; none when
    a held input has an error: its Wald errors include the propagated input error, which a
    profile with the input held would leave out)."""
    if held is None:
        return ProfileIntervals(nll, args, scale, out.value, out.cov, out.at_bound, hessian)
    red, fscale, fargs, rout, free, has_error = held
    if has_error:
        return None
    src = ProfileIntervals(red, fargs, fscale, rout.value, rout.cov, rout.at_bound, hessian)
    return lambda result: float64_scope(src._compute)(
        tuple(result.param_names[i] for i in free))


def _k_mode_of(layout):
    if layout.linear_power:
        return "linear_power"
    return "shared" if layout.n_k == 1 else "per_group"


def _fit_exact(recs, layout, model, notes, fixed=None):
    args = make_exact_args(recs, layout, model)
    # start from the (cheap, asymptotically equivalent) Whittle estimate
    sargs = _spectral_args(recs, layout, model, 1, None)
    moment = _start_vector(recs, layout, model.noise)
    wout, _ = _fit_held(fit_ml, spectral_nll, moment, sargs, layout.names, fixed)
    starts = [wout.value] if bool(wout.success) else []
    names = layout.names
    if not starts or ("k" in names and _leakage_index(
            recs, float(wout.value[0]), float(wout.value[names.index("gamma")]))
            > _LEAKAGE_INDEX_MAX):
        # where Whittle is unreliable (tau not << T) also start from the closed forms and
        # keep the better optimum: the exact likelihood can have a second local optimum there
        starts.append(moment)
    out = s_out = held = None
    for s0 in starts:
        cand, h0 = _fit_held(fit_ml_fd_newton, exact_nll, s0, args, names, fixed)
        if out is None or (bool(cand.converged) and (not bool(out.converged)
                                                      or float(cand.nll) < float(out.nll))):
            out, s_out, held = cand, s0, h0
    assert out is not None  # starts is never empty
    _check_fit(out, layout.names, "likelihood (exact)", recs=recs)
    # goodness of fit on the periodogram against this fit's own spectrum
    psd = _psd_jit(out.value, sargs)
    gof = spectral_gof(sargs.power / psd, sargs.weight, len(layout.names))
    extras = {"loglik": -float(out.nll)}
    res = _assemble(recs, layout, model, "likelihood", out.value, out.cov, gof, notes, extras,
                    at_bound=out.at_bound,
                    interval_source=_interval_source(exact_nll, args, s_out, out, held,
                                                     hessian="fd"))
    return _check_relaxation_resolved(res, recs, "likelihood (exact)")


#: Switch from Whittle to the exact likelihood above this leakage index (see below).
_LEAKAGE_INDEX_MAX = 1.0


def _leakage_index(recs, k_values, gamma):
    """``max_r sqrt(N_r) tau_r / T_r``: the Whittle likelihood's finite-record bias in units of
    the standard error scales like this. Measured (benchmarks/study_whittle_leakage.py, results
    in benchmarks/RESULTS_calibration.md; 8 seeds x 65 536 frames, W = dt, same data for both
    likelihoods): the mean Whittle-minus-exact shift of gamma is +0.35, +0.61, +0.14, +0.01 SE
    at index 8.5, 2.6, 0.85, 0.26 (with P_d instead of the exact expected periodogram it was
    -2.0, -0.7, -0.2, -0.08 SE). Above 1.0 auto uses the exact likelihood (below it the
    shift is < ~0.15 SE and Whittle is up to ~250x cheaper on long photodiode records)."""
    idx = 0.0
    for r, kk in zip(recs, np.broadcast_to(np.asarray(k_values, dtype=float), (len(recs),))):
        tau = gamma / kk
        idx = max(idx, math.sqrt(r.n_frames) * tau / (r.n_frames * float(r.frame_interval)))
    return idx


def _default_k_mode(recs):
    powers = [r.laser_power for r in recs]
    if all(p is not None for p in powers) and len({float(p) for p in powers}) > 1:
        return "per_power"
    return "shared"


def _joint_likelihood_se(recs, layout, model, p):
    """Standard errors the joint (Whittle) likelihood of the same recordings would give at
    ``p``: the expected Fisher information of the periodogram ordinates,
    ``sum_f w(f) grad log P(f) grad log P(f)^T``, with the package's spectral model
    (central differences of the compiled model spectrum that the likelihood fits use)."""
    sargs = _spectral_args(recs, layout, model, 1, None)
    p = np.asarray(p, dtype=float)
    floor = 1e-6 * float(np.median([np.var(np.asarray(r.positions)) for r in recs]))
    cols = []
    for i in range(p.size):
        h = 1e-5 * max(abs(p[i]), floor)
        up, dn = p.copy(), p.copy()
        up[i] += h
        dn[i] = max(dn[i] - h, 0.0)
        lp = [np.log(np.asarray(_psd_jit(jnp.asarray(q), sargs))) for q in (up, dn)]
        cols.append((lp[0] - lp[1]) / (up[i] - dn[i]))
    jac = np.stack(cols, axis=-1)  # (R, M, P)
    fisher = np.einsum("rmi,rmj->ij", jac * np.asarray(sargs.weight)[..., None], jac)
    try:
        return np.sqrt(np.clip(np.diag(np.linalg.inv(fisher)), 0, None))
    except np.linalg.LinAlgError:
        return np.full(p.size, np.nan)


def _fit_variance(recs, layout, model, method_name, notes):
    if len(recs) < len(layout.names):
        raise ValueError(
            f"{method_name} needs at least {len(layout.names)} recordings to fit "
            f"{layout.names}; got {len(recs)}"
        )
    v = np.array([np.var(np.asarray(r.positions, dtype=float)) for r in recs])
    n = np.array([float(r.n_frames) for r in recs])
    args = VarianceArgs(layout=layout, model=model, meta=rec_meta(recs), v=jnp.asarray(v),
                        n=jnp.asarray(n), se=jnp.asarray(v * np.sqrt(2.0 / n)))
    scale = _start_vector(recs, layout, model.noise)
    p, cov, chi2, ok, pd, fitted = fit_variances(args, scale)
    if not bool(ok):
        raise FitError(f"{method_name}: least squares did not converge; parameters {layout.names}")
    if not bool(pd):
        raise FitError(
            f"{method_name}: parameters {layout.names} are not identifiable from these "
            "variances (need exposures spanning alpha ~ 0.3-10, or several powers)"
        )
    dof = max(len(recs) - len(layout.names), 0)
    gof = {"test": "weighted chi2 of variances", "statistic": float(chi2), "dof": dof,
           "p_value": float(chi2_sf(float(chi2), dof)) if dof > 0 else float("nan")}
    notes = list(notes)
    names = layout.names
    # 95 % profile-likelihood intervals: the Wald interval (value +- 1.96 SE) is not honest
    # here (k = kT/sigma^2 with sigma^2 and eps^2 separated only by the curvature of
    # S(alpha), and eps^2 >= 0: skewed, bounded estimates; benchmarks/RESULTS_variance_methods.md)
    prof = profile_intervals(fitted, p, chi2)
    intervals = {names[i]: prof[i] for i in range(len(names))}
    wald = np.sqrt(np.clip(np.diag(cov), 0, None))
    txt = []
    for i, name in enumerate(names):
        lo, hi = intervals[name]
        fac, unit = _LAB_UNITS.get(name.split("[")[0], (1.0, "SI"))
        txt.append(f"{name} [{lo * fac:.4g}, {hi * fac:.4g}] {unit}")
    notes.append("95 % profile-likelihood intervals (chi^2 profile, eps^2 >= 0; in "
                 "result.intervals, SI): " + "; ".join(txt) + ". Use them rather "
                 "than value +- 1.96 SE: the variance methods' estimates are skewed and the "
                 "Wald interval under- or over-covers")
    unbounded = [nm for nm, (lo, hi) in intervals.items()
                 if not np.isfinite(hi) or (lo == 0.0 and nm != "tracking_var")]
    if unbounded:
        notes.append(f"{method_name}: the data do not bound {unbounded} within a factor 1000 "
                     "(weakly identified: exposures or powers too close, or alpha << 1)")
    extras: dict[str, Any] = {"intervals": intervals}
    try:
        jse = _joint_likelihood_se(recs, layout, model, p)
        nk = 1 if layout.linear_power else layout.n_k
        # this method's effective SE: the 95 % profile interval's half width / 1.96 (the
        # Wald SE is inflated where eps^2 sits on its bound)
        eff = np.array([(hi - lo) / (2 * 1.959964) if np.isfinite(hi - lo) else w
                        for (lo, hi), w in zip(prof.values(), wald)])
        ratio = float(np.median(eff[:nk] / jse[:nk]))
        g_ratio = float(eff[nk] / jse[nk])
        if np.isfinite(ratio):
            extras["joint_se_ratio"] = ratio
            notes.append(f"the joint likelihood on these recordings gives ~{ratio:.2g}x smaller "
                         f"SE of k (and ~{g_ratio:.2g}x of gamma) than this method's 95 % intervals "
                         "imply: predicted from its Fisher information at this estimate; "
                         "calibrate(..., method='likelihood')")
    except Exception:  # noqa: BLE001 - an advisory note only
        pass
    return _assemble(recs, layout, model, method_name, p, cov, gof, notes, extras,
                     interval_source=_given_intervals(intervals))


def _given_intervals(intervals):
    """An ``interval_source`` for intervals already computed (all profile intervals)."""
    table = {n: (float(lo), float(hi)) for n, (lo, hi) in intervals.items()}
    return lambda result: (table, {n: "profile" for n in table})


def _fit_allan(recs, layout, model, notes):
    """k, gamma, eps^2 from the overlapping Allan variance (exact expectation and covariance,
    iterated GLS); errors from the GLS information, goodness of fit from its chi^2."""
    if model.extra or not model.alias:
        raise ValueError("method 'allan' fits the closed-form frame model (naive, blur or "
                         f"standard); got model {model.name!r}")
    scale = _start_vector(recs, layout, model.noise)
    p, cov, chi2, dof, ok, pd, est = fit_allan(recs, layout, rec_meta(recs), model.blur, scale)
    if not bool(ok):
        raise FitError(f"allan: the fit did not converge; parameters {layout.names}")
    if not bool(pd):
        raise FitError(f"allan: parameters {layout.names} are not identifiable from these "
                       "Allan variances (dt >> tau leaves no temporal information)")
    gof = {"test": "chi2 of Allan variances (exact covariance)", "statistic": float(chi2),
           "dof": dof, "p_value": float(chi2_sf(float(chi2), dof)) if dof > 0 else float("nan")}
    notes = list(notes) + [f"allan: overlapping Allan variance at {len(e.m)} octave cluster "
                           f"sizes (1..{int(e.m[-1])} frames) of {e.n_frames} frames" for e in est]
    return _assemble(recs, layout, model, "allan", p, cov, gof, notes,
                     extras={"allan": [e.to_dict() for e in est]})


def _equipartition(recs, diffusion, pade):
    ks, kerr = [], []
    notes = []
    for r in recs:
        v, se = empirical_variance_se(r.positions)
        kt = BOLTZMANN * float(r.temperature)
        if diffusion is None:
            k = kt / v
            ks.append(k)
            kerr.append(k * se / v)
        else:
            from ..physics._blur import stiffness_from_variance

            meth = "pade" if pade else "exact"
            k = float(stiffness_from_variance(v, diffusion, float(r.exposure), float(r.temperature),
                                              method=meth))
            h = v * 1e-6
            dk = (float(stiffness_from_variance(v + h, diffusion, float(r.exposure),
                                                float(r.temperature), method=meth)) - k) / h
            ks.append(k)
            kerr.append(abs(dk) * se)
    if diffusion is None:
        notes.append("naive equipartition k = kT/var(X_m): biased high by motion blur "
                     "(var is reduced by S(alpha)) and low by tracking noise (var is raised)")
        gamma, gerr = math.nan, math.nan
    else:
        notes.append(f"blur-corrected equipartition with given D = {diffusion:.4g} m^2/s "
                     f"({'Pade' if pade else 'exact'} inversion)")
        gamma = BOLTZMANN * float(recs[0].temperature) / diffusion
        gerr = 0.0
    names = tuple(f"k[{i}]" for i in range(len(recs))) if len(recs) > 1 else ("k",)
    values = np.array(ks + ([gamma] if diffusion is not None else []))
    errs = np.array(kerr + ([gerr] if diffusion is not None else []))
    names = names + (("gamma",) if diffusion is not None else ())
    return CalibrationResult(
        method="equipartition",
        model="naive" if diffusion is None else "blur",
        param_names=names,
        values=values,
        covariance=np.diag(errs**2),
        temperature=float(recs[0].temperature),
        k_per_recording=np.array(ks),
        k_per_recording_err=np.array(kerr),
        gof={},
        n_recordings=len(recs),
        n_frames=int(sum(r.n_frames for r in recs)),
        notes=tuple(notes),
    )


_K_MODES = (None, "shared", "per_recording", "per_power", "linear_power")
#: D of a 1 nm sphere in water is ~2e-10 m^2/s: anything above this is a unit slip.
_MAX_PLAUSIBLE_DIFFUSION = 1e-8


def _check_options(recs, method, likelihood, k, n_blocks, f_range, diffusion, pade, start,
                   strict):
    """Validate calibrate's options; nothing given is ignored silently."""
    if k not in _K_MODES:
        raise ValueError(f"k must be one of {_K_MODES[1:]} (or None for the default); "
                         f"got k = {k!r}")
    if not isinstance(strict, (bool, np.bool_)):
        raise ValueError(f"strict must be True or False; got strict = {strict!r}")
    if not isinstance(pade, (bool, np.bool_)):
        raise ValueError(f"pade must be True or False; got pade = {pade!r}")
    if n_blocks is not None:
        if method != "psd":
            raise ValueError(f"n_blocks = {n_blocks!r} applies only to method='psd'; got "
                             f"method = {method!r}")
        if isinstance(n_blocks, bool) or not isinstance(n_blocks, numbers.Integral) \
                or n_blocks < 1:
            raise ValueError(f"n_blocks must be an integer >= 1 (number of non-overlapping "
                             f"blocks); got n_blocks = {n_blocks!r}")
        n_blocks = int(n_blocks)
    if f_range is not None:
        if method in ("equipartition", "variance_vs_exposure", "variance_vs_power") or \
                (method in ("auto", "likelihood") and likelihood == "exact"):
            raise ValueError(f"f_range = {f_range!r} applies only to the spectral methods "
                             "(method='psd', or the Whittle likelihood); got method = "
                             f"{method!r}, likelihood = {likelihood!r}")
        try:
            lo, hi = (float(v) for v in f_range)
        except (TypeError, ValueError):
            raise ValueError(f"f_range must be two numbers (f_min, f_max) in Hz; got "
                             f"f_range = {f_range!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
            raise ValueError(f"f_range must satisfy 0 <= f_min < f_max (finite, Hz); got "
                             f"f_range = ({lo!r}, {hi!r})")
        nyq = max(0.5 / float(r.frame_interval) for r in recs)
        if lo >= nyq:
            raise ValueError(f"f_range = ({lo:g}, {hi:g}) Hz starts above the Nyquist "
                             f"frequency {nyq:g} Hz of the recordings (f_range is in Hz, not kHz)")
        if hi > nyq * (1.0 + 1e-9):
            raise ValueError(f"f_range = ({lo:g}, {hi:g}) Hz: f_max = {hi:g} Hz is above the "
                             f"Nyquist frequency fs/2 = {nyq:g} Hz of the recordings, where "
                             "there are no ordinates; expected f_max <= fs/2 (f_range is in "
                             "Hz, not kHz)")
        f_range = (lo, hi)
    if diffusion is not None:
        if method not in ("equipartition", "auto"):
            raise ValueError(f"diffusion = {diffusion!r} is used only by method='equipartition' "
                             f"(and by 'auto' when frames carry no temporal information); got "
                             f"method = {method!r}")
        d = float(diffusion) if isinstance(diffusion, numbers.Real) and not isinstance(
            diffusion, bool) else math.nan
        if not (math.isfinite(d) and d > 0):
            raise ValueError(f"diffusion (diffusion coefficient D) must be finite and > 0 "
                             f"m^2/s; got diffusion = {diffusion!r}")
        if d > _MAX_PLAUSIBLE_DIFFUSION:
            raise ValueError(
                f"diffusion = {d:g} m^2/s is implausibly large (a 1 nm sphere in water has "
                f"D ~ 2e-10 m^2/s): it looks like um^2/s. D is in SI units: 1 um^2/s = 1e-12 m^2/s"
            )
    elif pade:
        raise ValueError("pade=True selects the Pade inversion of blur-corrected equipartition "
                         "and needs diffusion=D; got diffusion=None")
    if start is not None:
        if not isinstance(start, dict):
            raise ValueError(f"start must be a dict of start values by parameter name; got "
                             f"{type(start).__name__}")
        for name, v in start.items():
            ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v) \
                and v > 0  # pyright: ignore[reportOperatorIssue]  # numbers.Real orders
            if not ok:
                raise ValueError(f"start[{name!r}] must be a finite number > 0 (SI units); got "
                                 f"{v!r}")
    return n_blocks, f_range


#: saturation: a pile-up of at least this many frames at exactly the minimum or maximum value
#: that holds more than twice as many frames as the next value inwards (an unclipped tail
#: thins out towards the extreme: a continuous trace has each value once, a quantised one
#: fewer frames on its outermost level than on the next)
_SAT_MIN_FRAMES = 3
#: refuse above this fraction of saturated frames, or when the clipped tails lower the
#: variance by more than _SAT_MAX_BIAS_SE standard errors of the frame variance
_SAT_MAX_FRACTION = 0.005
_SAT_MAX_BIAS_SE = 0.5
#: quantisation: note a step above std/4 (it adds step^2/12 > 0.5 % of the variance); refuse a
#: step above the std. Below one std the rounding error is white noise of variance step^2/12,
#: uncorrelated with the motion to exp(-2 pi^2 std^2/step^2) (Sheppard; < 3e-9 at step = std),
#: which eps^2 absorbs: measured with the exact likelihood on 8192-frame AR(1) traces rounded
#: to steps of 0.25, 0.5 and 1 std, k and gamma moved by < 0.4 SE. At 1.5 and 2 std they were
#: 1.5 and 3-8 SE off (tau = 8 dt: the rounding error of neighbouring frames correlates).
_QUANT_NOTE_STEP = 0.25
_QUANT_MAX_STEP = 1.0


def _clipped_variance_deficit(p: float) -> float:
    """Relative variance lost when a Gaussian's tail beyond its upper p-quantile is moved onto
    the quantile: ``E[(Z - z)^2; Z > z] = (1 + z^2) Q(z) - z phi(z)``."""
    from statistics import NormalDist

    p = min(max(p, 1e-300), 0.5)
    z = NormalDist().inv_cdf(1.0 - p)
    phi = math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
    return max((1.0 + z * z) * p - z * phi, 0.0)


def _quantisation_step(values: np.ndarray, n: int) -> float:
    """The grid step of a trace whose values lie on a regular grid (else 0)."""
    if values.size < 2 or values.size > n // 2:
        return 0.0
    d = np.diff(values)
    q = float(d.min())
    if not q > 0:
        return 0.0
    m = d / q
    return q if bool(np.all(np.abs(m - np.round(m)) < 1e-3)) else 0.0


def _inspect_frames(recs, strict: bool) -> list:
    """Saturation (frames piled up at exactly the extreme values) and coarse quantisation.

    Clipping removes the tails of the position distribution and flattens the trace while the
    detector is saturated: k comes out high and the spectrum distorted, with no sign in the
    goodness of fit. Refused (``ValueError``) above ``_SAT_MAX_FRACTION`` of the frames or
    when the variance deficit it implies is not small compared with the variance's standard
    error; smaller pile-ups get a note. Quantisation adds white noise of variance step^2/12,
    which the tracking-noise term absorbs: a note above a step of std/4, refused above one
    std, where the rounding error is neither white nor independent of the motion. With
    ``strict=False`` the refusals become notes and the fit goes on.
    """
    notes, errors = [], []
    for i, r in enumerate(recs):
        y = np.asarray(r.positions, dtype=float)
        n = y.size
        u, counts = np.unique(y, return_counts=True)
        if u.size < 2:
            continue
        sd = float(np.std(y))
        where = f"recording {i}" + (f" ({r.name})" if getattr(r, "name", None) else "")
        piles = []
        for side, j, jn in (("minimum", 0, 1), ("maximum", -1, -2)):
            c, cn = int(counts[j]), int(counts[jn])
            if c >= _SAT_MIN_FRAMES and c >= 2 * cn + 1:
                piles.append((side, c, float(u[j])))
        if piles:
            frac = sum(c for _, c, _ in piles) / n
            deficit = sum(_clipped_variance_deficit(c / n) for _, c, _ in piles)
            v, se = empirical_variance_se(y)
            rel_se = se / v if v > 0 else math.inf
            what = " and ".join(f"{c} frames ({100.0 * c / n:.2g} %) at exactly the {side} "
                                f"{val:.6g} m" for side, c, val in piles)
            msg = (f"{where} ({n} frames): {what}: the detector saturated (clipped). "
                   "Clipping cuts the tails of the position distribution and flattens the "
                   "trace while saturated, so k comes out too high (a Gaussian clipped there "
                   f"loses ~{100.0 * deficit:.2g} % of its variance; the variance's standard "
                   f"error is {100.0 * rel_se:.2g} %) and the spectrum is distorted")
            if frac > _SAT_MAX_FRACTION or deficit > _SAT_MAX_BIAS_SE * rel_se:
                errors.append(msg)
            else:
                notes.append(msg + " - here too few frames to matter (fit kept)")
        q = _quantisation_step(u, n)
        if q > 0 and sd > 0 and q > _QUANT_NOTE_STEP * sd:
            added = q * q / 12.0
            msg = (f"{where}: positions are quantised in steps of {q:.4g} m ({q / sd:.2g} x "
                   f"their standard deviation {sd:.4g} m; {u.size} distinct values). Rounding "
                   f"adds white noise of variance step^2/12 = {added:.3g} m^2 "
                   f"({100.0 * added / sd**2:.2g} % of the frame variance)")
            if q > _QUANT_MAX_STEP * sd:
                errors.append(msg + f"; with a step above {_QUANT_MAX_STEP:g} standard "
                              "deviation the rounding error is neither white nor independent "
                              "of the motion, and k and gamma are biased (by several SE at "
                              "1.5-2 std). Record with a finer position resolution")
            else:
                notes.append(msg + ", which the tracking-noise term eps^2 absorbs (its "
                             "fitted value includes it); models without tracking noise "
                             "(naive, blur) would put k that much too low")
    if errors:
        if strict:
            raise ValueError("; ".join(errors) + ". Crop the saturated stretches or fix the "
                             "detector range/resolution; strict=False fits anyway (with a "
                             "note; the result is then biased).")
        notes = [f"NOT TRUSTWORTHY (strict=False): {e}" for e in errors] + notes
    return notes


def _no_temporal_information_message(recs, info):
    best = max(z for _, z in info)
    v, se = empirical_variance_se(recs[0].positions)
    n = min(r.n_frames for r in recs)
    out = _outlier_sentence(recs)
    why = (out if out else f"only {n} frames" if n < 200 else
           "dt >> tau (the bead relaxes between frames), or tracking noise dominates the motion")
    return (
        f"these recordings cannot identify gamma: the lag-1 correlation of the frames is only "
        f"{best:.1f} standard errors above 0 ({why}) and there are fewer than 3 exposures or "
        f"laser powers. What they do determine is the frame variance var(X_m) = "
        f"{v * 1e18:.4g} +- {se * 1e18:.2g} nm^2 (recording 0). Give the diffusion coefficient "
        "(diffusion=D with method='auto' or 'equipartition': blur-corrected equipartition), or "
        "record an exposure series or a power series."
    )


def _flag(name, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False; got {name} = {value!r}")
    return bool(value)


@float64_scope
def calibrate(
    data,
    *,
    method: str = "auto",
    model=None,
    k: str | None = None,
    likelihood: str = "auto",
    n_blocks: int | None = None,
    f_range=None,
    diffusion: float | None = None,
    pade: bool = False,
    start: dict | None = None,
    strict: bool = True,
    fixed: dict | None = None,
    friction: str | None = None,
    detector: str | None = None,
    anti_aliasing: bool | None = None,
    excluded_ranges=None,
    lines: str = "auto",
    robust: bool = False,
) -> CalibrationResult:
    """Calibrate k, gamma (D) and eps^2 with standard errors from one or more recordings.

    **Arguments:**

    - `data`: a ``Recording``, ``RecordingSet``, list of recordings or a manifest path.
    - `method`: ``"auto"`` (the most informative method the data allow; the choice is in
      ``result.notes``), ``"likelihood"`` (joint exact or Whittle likelihood), ``"psd"``
      (blocked power spectrum, Gamma maximum likelihood, appendix C), ``"variance_vs_exposure"``
      (section 6.2), ``"variance_vs_power"`` (section 6.3, k = c P), ``"equipartition"``
      (naive, or blur-corrected when ``diffusion`` is given).
    - `model`: ``"standard"`` (default: blur + aliasing + tracking noise), ``"blur"``,
      ``"naive"``, ``"naive_aliased"``, or a ``TrapModel``.
    - `k`: how stiffness is shared across recordings: ``"shared"``, ``"per_recording"``,
      ``"per_power"``, ``"linear_power"`` (default: per power when powers differ).
    - `likelihood`: ``"exact"`` (O(N) time-domain, REML mean), ``"whittle"`` or ``"auto"``
      (Whittle above 2^14 frames per recording, where the two agree to well within errors).
    - `n_blocks`: blocks for ``method="psd"`` (default: 128 blocks, at least 64 frames each).
    - `f_range`: ``(f_min, f_max)`` [Hz] fitted in the spectral methods.
    - `diffusion`, `pade`: for blur-corrected equipartition.
    - `start`: optional start values by parameter name (SI), e.g. from a previous fit
      (``result.params``); missing names use the closed-form starts.
    - `strict`: raise ``FitError`` when the Fisher information is singular (default); with
      ``strict=False`` (spectral methods) the fit is returned with NaN errors and a note.
      Saturated frames (a pile-up at exactly the minimum or maximum value) and positions
      quantised in steps above their standard deviation raise ``ValueError``; with
      ``strict=False`` they give a note instead. Milder quantisation (steps above std/4)
      and a few saturated frames are noted in ``result.notes``.
    - `fixed`: parameters held at known values, ``{"gamma": 9.1e-9}`` or with a standard
      error ``{"gamma": (9.1e-9, 0.3e-9)}`` (SI), which is propagated into the others' errors.
    - `friction`: ``"stokes"`` holds gamma at ``6 pi eta R`` of the bead (the recordings'
      ``bead_radius_m``, ``viscosity_Pa_s`` or water at their temperature, Faxen's factor at
      ``distance_to_surface_m``; ``bead_radius_err_m``, ``viscosity_err_Pa_s``,
      ``temperature_err_K`` propagated); ``"free"`` fits it (default: the recordings'
      ``friction`` setting, else free).
    - `detector`, `anti_aliasing`: ``"camera"`` or ``"photodiode"`` (default: the
      recordings' settings). They choose the model when `model` is not given: exposure
      average and folding for a camera or an integrating photodiode, neither for a
      photodiode with anti-aliasing (fitted below 0.4 fs unless `f_range` says otherwise);
      a ``diode_filter`` setting adds the photodiode filter (fitted, or held at given values).
    - `excluded_ranges`: ``[(f_low, f_high), ...]`` [Hz] left out of the spectral fits.
    - `lines`: ``"auto"`` (default) finds strong narrow lines (a drive, mains pick-up) and
      subtracts them before the fit, naming them in the notes; ``"keep"`` fits the trace as
      it is.
    - `robust`: spectral fits leave out ordinates far above the fitted spectrum (spikes).

    Positions in volts (``position_unit="V"``) give the displacement sensitivity Rd [m/V] and
    force sensitivity Rf = k Rd [N/V] as parameters ``displacement_sensitivity`` and
    ``force_sensitivity``, from the known friction or from a stage drive (active calibration:
    a ``drive`` setting with the recorded stage positions); k, gamma, eps^2 are then in SI.

    **Returns:** :class:`CalibrationResult` (SI units).

    **Raises:** ``FitError`` when a fit does not converge or is not identifiable;
    ``ValueError`` for bad arguments and for saturated or coarsely quantised frames.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got method = {method!r}")
    if likelihood not in ("auto", "exact", "whittle"):
        raise ValueError(f"likelihood must be 'auto', 'exact' or 'whittle'; got {likelihood!r}")
    recs = as_recordings(data)
    mdl: TrapModel = get_model(model)
    n_blocks, f_range = _check_options(recs, method, likelihood, k, n_blocks, f_range,
                                       diffusion, pade, start, strict)
    radii = _bead_radii(recs)
    data_notes = tuple(_inspect_frames(recs, bool(strict)))
    plan = prepare_instrument(recs, mdl, model is not None, method, fixed=fixed,
                              friction=friction, detector=detector,
                              anti_aliasing=anti_aliasing, excluded_ranges=excluded_ranges,
                              lines=lines, f_range=f_range)
    res = _calibrate(plan.recordings, method, plan.model, k, likelihood, n_blocks,
                     plan.f_range, diffusion, pade, start, strict, plan.fixed, plan.excluded,
                     _flag("robust", robust))
    res = finish_instrument(res, plan).with_inputs(plan.recordings, plan.model,
                                                   plan.f_range, plan.excluded)
    if not plan.volts:
        data_notes += tuple(_stokes_notes(recs, radii, res))
    notes = tuple(plan.notes) + data_notes
    if notes:
        res = dataclasses.replace(res, notes=tuple(res.notes) + notes)
    return res


#: a fitted gamma outside [1/3, 3] x the Stokes friction of the known bead is flagged
_STOKES_MAX_RATIO = 3.0


def _bead_radii(recs) -> list:
    """``metadata['bead_radius_m']`` (and optional ``'viscosity_Pa_s'``) per recording, as
    ``(radius, viscosity or None)`` or ``None``; a value that is not a plausible radius in
    metres is a ValueError."""
    out = []
    for i, r in enumerate(recs):
        meta = getattr(r, "metadata", None) or {}
        rad = meta.get("bead_radius_m")
        if rad is None:
            out.append(None)
            continue
        ok = isinstance(rad, numbers.Real) and not isinstance(rad, bool) and \
            math.isfinite(float(rad)) and float(rad) > 0
        if not ok:
            raise ValueError(f"recording {i}: metadata['bead_radius_m'] must be a bead radius "
                             f"in m (> 0, finite); got {rad!r}")
        if float(rad) > 1e-3:
            raise ValueError(f"recording {i}: metadata['bead_radius_m'] = {rad!r} m is "
                             f"implausibly large: it looks like um or nm (1 um = 1e-6 m)")
        eta = meta.get("viscosity_Pa_s")
        if eta is not None and not (isinstance(eta, numbers.Real) and not isinstance(eta, bool)
                                    and math.isfinite(float(eta)) and float(eta) > 0):
            raise ValueError(f"recording {i}: metadata['viscosity_Pa_s'] must be > 0 (Pa s); "
                             f"got {eta!r}")
        out.append((float(rad), None if eta is None else float(eta)))
    return out


def _stokes_notes(recs, radii, res) -> list:
    """A note when the fitted gamma is far from Stokes' 6 pi eta r of the known bead."""
    from ..physics._effects import water_viscosity

    g = float(res.gamma)
    if not (math.isfinite(g) and g > 0) or res.method == "equipartition":
        return []
    for i, (r, ri) in enumerate(zip(recs, radii)):
        if ri is None:
            continue
        rad, eta = ri
        t = float(r.temperature)
        which = "metadata viscosity_Pa_s" if eta is not None else f"water at {t:g} K"
        eta = eta if eta is not None else float(water_viscosity(t))
        g0 = 6.0 * math.pi * eta * rad
        ratio = g / g0
        if 1.0 / _STOKES_MAX_RATIO <= ratio <= _STOKES_MAX_RATIO:
            return []
        return [f"gamma = {g:.4g} N s/m is {ratio:.3g} x the Stokes friction 6 pi eta r = "
                f"{g0:.4g} N s/m of the bead (r = {rad:.4g} m from recording {i}'s metadata "
                f"bead_radius_m, eta = {eta:.4g} Pa s, {which}); expected within "
                f"{1 / _STOKES_MAX_RATIO:.2g}-{_STOKES_MAX_RATIO:g} x (a nearby surface raises "
                "it by Faxen's factor, < 3 x above ~1.1 radii). Check the position "
                "calibration (units), the exposure and frame interval, the bead radius and "
                "the temperature"]
    return []


def _calibrate(recs, method, mdl, k, likelihood, n_blocks, f_range, diffusion, pade, start,
               strict, fixed=None, excluded=None, robust=False):
    notes: list[str] = []
    if robust and method not in ("auto", "likelihood", "psd"):
        raise ValueError(f"robust=True applies to the spectral methods (Whittle likelihood, "
                         f"psd); got method = {method!r}")
    fixed = fixed or {}
    if fixed and method not in ("auto", "likelihood", "psd"):
        raise ValueError(f"fixed = {sorted(fixed)} applies to the likelihood and psd methods; "
                         f"got method = {method!r}")
    if excluded and method not in ("auto", "likelihood", "psd"):
        raise ValueError(f"excluded ranges apply to the spectral methods (Whittle likelihood, "
                         f"psd); got method = {method!r}")

    if method == "equipartition":
        return _equipartition(recs, diffusion, pade)

    if method == "auto":
        # The joint likelihood of all frames contains the variance-vs-exposure and
        # variance-vs-power information too, so it is the most informative choice whenever
        # the parameters are identifiable at all.
        info = [temporal_information(r) for r in recs]
        n_exp = len({float(r.exposure) for r in recs})
        powers = {float(r.laser_power) for r in recs if r.laser_power is not None}
        if any(ok for ok, _ in info):
            best = max(z for _, z in info)
            notes.append("auto: frames resolve the trap relaxation (lag-1 correlation "
                         f"{best:.1f} standard errors above 0); joint likelihood")
        elif "gamma" in fixed:
            best = max(z for _, z in info)
            if mdl.noise and "tracking_var" not in fixed:
                raise FitError(
                    f"the frames carry no temporal information (lag-1 correlation only "
                    f"{best:.1f} standard errors above 0: dt >> tau, W < dt): with gamma known, "
                    "k follows from the blurred variance var = kT/k S(W k/gamma) + eps^2 alone, "
                    "which cannot separate k from the tracking-error variance eps^2. Give it: "
                    "fixed={'tracking_var': eps2} in m^2 (0 when the tracking error is "
                    "negligible; CLI --fix tracking_var=NM2), or record at several exposures")
            notes.append(f"auto: frames carry little temporal information (lag-1 correlation "
                         f"{best:.1f} standard errors above 0: dt >> tau); gamma is held at the "
                         "given friction, so the joint likelihood gives k from the "
                         "blur-corrected variance")
        elif n_exp >= 3:
            notes.append(f"auto: frames are nearly independent (dt >> tau); gamma is "
                         f"identified by the {n_exp} exposures (variance-vs-exposure "
                         "information) in the joint likelihood")
        elif len(powers) >= 3 and all(r.laser_power is not None for r in recs):
            notes.append("auto: dt >> tau; k = c P across the laser powers (variance-vs-power "
                         "information) in the joint likelihood")
            if k is None:
                k = "linear_power"
        elif diffusion is not None:
            best = max(z for _, z in info)
            res = _equipartition(recs, diffusion, pade)
            return dataclasses.replace(res, notes=(
                f"auto: frames carry no temporal information (lag-1 correlation only {best:.1f} "
                "standard errors above 0: dt >> tau, or tracking noise dominates) and there are "
                "fewer than 3 exposures or powers; k from blur-corrected equipartition with the "
                "given D, assuming eps^2 = 0 (any tracking noise biases k low)",) + res.notes)
        else:
            raise FitError(_no_temporal_information_message(recs, info))
        method = "likelihood"

    if k is None:
        k = "linear_power" if method == "variance_vs_power" else _default_k_mode(recs)
    if mdl.has("power_offset") and k != "linear_power":
        raise ValueError("the power_offset effect needs k='linear_power' (k = c (P - P0))")
    layout = make_layout(recs, k, mdl.noise, tuple(p.name for p in mdl.extra_params))
    unknown = sorted(set(fixed) - set(layout.names))
    if unknown:
        raise ValueError(f"fixed names {unknown}, which this model does not have; its "
                         f"parameters are {list(layout.names)}")
    if len(fixed) == len(layout.names):
        raise ValueError(f"fixed holds every parameter {list(layout.names)}: nothing to fit")
    if start:
        unknown = sorted(set(start) - set(layout.names))
        if unknown:
            raise ValueError(f"start has parameter names {unknown} that this model does not "
                             f"have; its parameters are {list(layout.names)}")

    if mdl.extra and method in ("variance_vs_exposure", "variance_vs_power"):
        raise ValueError(f"method {method!r} fits only the core model; effects "
                         f"{[e.name for e in mdl.extra]} need method='likelihood' or 'psd'")
    if method == "likelihood":
        use = likelihood
        if use == "auto":
            use = "whittle" if min(r.n_frames for r in recs) > 2**14 else "exact"
            if (f_range is not None or excluded or robust) and use == "exact":
                use = "whittle"
                notes.append(("f_range" if f_range is not None else "excluded ranges"
                              if excluded else "robust") + " given: the Whittle likelihood over that band (the exact "
                             "likelihood uses every frequency)")
        if use == "exact" and not mdl.alias:
            if likelihood == "exact":
                raise ValueError(f"model {mdl.name!r} is not aliased (an anti-aliased "
                                 "photodiode): its frames are not the sampled trap process of "
                                 "the exact likelihood; use likelihood='whittle'")
            use = "whittle"
        if use == "exact" and mdl.extra:
            if likelihood == "exact":
                raise ValueError("the exact time-domain likelihood covers the closed-form "
                                 "model only; use likelihood='whittle' with effects "
                                 f"{[e.name for e in mdl.extra]}")
            use = "whittle"
        exact_ok = (not mdl.extra and f_range is None and not excluded and not robust
                    and mdl.alias and mdl.closed_form)
        if use == "whittle" and likelihood == "auto" and exact_ok:
            ks, gs = zip(*[moment_start(r)[:2] for r in recs])
            if _leakage_index(recs, ks, float(np.median(gs))) > _LEAKAGE_INDEX_MAX:
                use = "exact"
                notes.append("likelihood: exact (the relaxation time is not short compared with "
                             "the record, where the Whittle approximation is biased)")
        if use == "exact":
            if not notes or not notes[-1].startswith("likelihood: exact"):
                notes.append("likelihood: exact")
            return _fit_exact(recs, layout, mdl, notes, fixed)
        res = _fit_spectral(recs, layout, mdl, 1, f_range, "likelihood", list(notes), start,
                            strict, fixed, excluded, robust)
        p = res.params
        if "gamma" in p and "c" not in p:
            kvals = res.k_per_recording
            leak = _leakage_index(recs, kvals, p["gamma"])
            if leak > _LEAKAGE_INDEX_MAX:
                if likelihood == "auto" and exact_ok:
                    notes.append("likelihood: exact (the fitted relaxation time is not short "
                                 "compared with the record, where the Whittle approximation "
                                 "is biased)")
                    return _fit_exact(recs, layout, mdl, notes, fixed)
                res = dataclasses.replace(res, notes=res.notes + (
                    f"Whittle leakage index sqrt(N) tau/T = {leak:.2g} > {_LEAKAGE_INDEX_MAX}: "
                    "the relaxation time is not short compared with the record and the "
                    "Whittle approximation may bias gamma by a fraction of its SE or more; "
                    "likelihood='exact' is exact",))
        return dataclasses.replace(res, notes=(*notes, "likelihood: whittle",
                                               *res.notes[len(notes):]))
    if method == "psd":
        nb = n_blocks
        if nb is None:
            # blocks long compared with tau (>= 100 tau from the closed-form start): shorter
            # blocks correlate neighbouring ordinates and the Gamma likelihood then
            # understates the errors (SE/SD 0.33 measured with 7-tau blocks)
            taus = [st[1] / st[0] for st in (moment_start(r) for r in recs)]
            n_min = min(r.n_frames for r in recs)
            t_min = min(r.n_frames * float(r.frame_interval) for r in recs)
            nb = max(1, min(128, n_min // 64, int(t_min / (100.0 * max(taus)))))
            # a power of two: the block length (an array shape) then takes few values across
            # records, so new recordings rarely recompile the fit
            nb = 1 << (nb.bit_length() - 1)
            notes.append(f"psd: {nb} blocks of {n_min // nb} frames (>= 100 tau each where "
                         "the record allows)")
        res = _fit_spectral(recs, layout, mdl, int(nb), f_range, "psd", notes, start, strict,
                            fixed, excluded, robust)
        return _check_psd_blocks(res, recs, int(nb), explicit=n_blocks is not None)
    if method == "allan":
        return _fit_allan(recs, layout, mdl, notes)
    if method in ("variance_vs_exposure", "variance_vs_power"):
        if method == "variance_vs_power" and k != "linear_power":
            warnings.warn("variance_vs_power is usually run with k='linear_power'", stacklevel=2)
        return _fit_variance(recs, layout, mdl, method, notes)
    raise AssertionError(method)  # pragma: no cover
