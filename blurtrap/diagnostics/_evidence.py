"""The evidence behind a candidate effect: residual band ratios in words, the isolated-line
search, the kurtosis test of the frames, physical plausibility of a refit, and the notes on
non-significant effects that still move k or gamma."""

from __future__ import annotations

import math

import numpy as np

from ..inference import CalibrationResult
from ..inference.internal import mean_shift
from ..physics import water_viscosity


def _bands(fit: CalibrationResult):
    f = np.asarray(fit.extras["f"]).ravel()
    ratio = np.asarray(fit.extras["ratio"]).ravel()
    w = np.asarray(fit.extras["weight"]).ravel()
    return f, ratio, w


def _band_ratio(f, ratio, w, lo, hi):
    sel = (f >= lo) & (f <= hi) & (w > 0)
    if not np.any(sel):
        return float("nan"), 0
    return float(np.sum(ratio[sel] * w[sel]) / np.sum(w[sel])), int(np.sum(sel))


def _signature(ratio: float, n: int, excess: bool) -> bool:
    """Does a band's data/model ratio show an excess (or deficit) beyond its noise? Each
    ordinate's ratio has SD ~1 under the model, so a band mean of n ordinates has SD
    ~1/sqrt(n); 2 SD is the bar for naming an effect in words."""
    if not np.isfinite(ratio) or n == 0:
        return False
    dev = ratio - 1.0 if excess else 1.0 - ratio
    return dev > 2.0 / math.sqrt(n)


# effect -> (what its signature is, True for an excess / False for a deficit near Nyquist)
_HIGH_F = {"motion_blur": ("deficit rising toward fs/2 (motion blur)", False),
           "aliasing": ("excess near Nyquist (aliasing)", True),
           "motion_blur+aliasing": ("high-frequency shape of a camera's blur and folding", None),
           "motion_blur+aliasing+tracking_noise": (
               "high-frequency shape of a camera's blur and folding over a tracking-noise "
               "floor", None),
           "tracking_noise": ("flat excess floor (tracking noise)", True),
           "exposure_kernel": ("high-frequency shape unlike sinc^2 (exposure kernel)", None),
           # a filter with an instantaneous part is a shape: the base fit's tracking noise
           # floor lifts the band near Nyquist while the middle falls (0.71 at 0.1-0.25 fs,
           # 1.09 near Nyquist: an independent pass)
           "detector_filter": ("high-frequency shape of a low-pass filter (detector filter)",
                               None),
           "hydrodynamics": ("high-frequency shape of frequency-dependent friction", None)}


def _evidence(effect: str, fit: CalibrationResult, recs) -> str:
    """The residual evidence for ``effect`` in words. The effect is named as the cause only
    when the band ratio deviates in its direction by more than 2 SD; otherwise the words say
    that its signature is absent (the likelihood test may still favour it)."""
    f, ratio, w = _bands(fit)
    fs = 1.0 / float(recs[0].frame_interval)
    fmin = float(np.min(f[w > 0])) if np.any(w > 0) else 0.0
    fc = fit.k / (2 * math.pi * fit.gamma) if np.isfinite(fit.gamma) else fs / 10
    if effect == "drift":
        hi = max(5 * fmin, min(0.05 * fc, 0.01 * fs))
        r, n = _band_ratio(f, ratio, w, 0, hi)
        if _signature(r, n, True):
            verdict = "excess at the lowest frequencies: drift"
        else:
            shifts = [t for t in (mean_shift(rec.positions) for rec in recs) if t is not None]
            p = min((t["p"] for t in shifts), default=math.nan)
            verdict = (f"no significant excess in this band, but the means of "
                       f"{shifts[0]['dof'] + 1} segments move beyond their scatter (p = "
                       f"{p:.2g}): drift" if p < 1e-3 else
                       "no significant excess in this band (the likelihood test weighs the "
                       "whole low-frequency spectrum)")
        return f"power below {hi:.3g} Hz is {r:.3g}x the model ({n} ordinates): {verdict}"
    if effect in _HIGH_F:
        r_hi, n_hi = _band_ratio(f, ratio, w, 0.7 * fs / 2, fs / 2)
        r_mid, n_mid = _band_ratio(f, ratio, w, 0.2 * fs / 2, 0.5 * fs / 2)
        what, excess = _HIGH_F[effect]
        if excess is None:  # a shape: any significant high- or mid-band misfit
            seen = (_signature(r_hi, n_hi, True) or _signature(r_hi, n_hi, False)
                    or _signature(r_mid, n_mid, True) or _signature(r_mid, n_mid, False))
        else:
            seen = _signature(r_hi, n_hi, excess)
        verdict = what if seen else f"within noise of the model (no {what.split(' (')[0]})"
        return (f"data/model near Nyquist {r_hi:.3g} ({n_hi} ordinates), at 0.1-0.25 fs "
                f"{r_mid:.3g}: {verdict}")
    if effect == "line_noise":
        j = int(np.argmax(np.where(w > 0, ratio, 0)))
        return f"isolated spike at {f[j]:.4g} Hz, {ratio[j]:.3g}x the model: line noise"
    if effect == "power_offset":
        return "k-vs-power line does not pass through the origin (k = c (P - P0))"
    if effect == "laser_heating":
        return "gamma falls with laser power (viscosity of heated water)"
    return ""


_ADDING = "; adding it: gof p "


def _gof_change(before: dict, after: dict) -> str:
    return f"{_ADDING}{before['p_value']:.2g} -> {after['p_value']:.2g}"


def _line_candidate(fit: CalibrationResult, half_window: int = 500, guard: int = 2,
                    lowest: int = 10):
    """Most significant isolated spike: periodogram/model ratio divided by its local mean
    over +-``half_window`` ordinates (excluding +-``guard`` around the candidate), so broadband
    misfit (drift, blur) is not mistaken for a line. The ``lowest`` Fourier frequencies
    (f < 10/T) are not searched: a "line" there cannot be told from drift. Under the model each
    ratio is Exp(1); the p-value accounts for the search over all M ordinates:
    1 - (1 - e^-r)^M."""
    f, ratio, w = _bands(fit)
    keep = w > 0
    f, q = f[keep], ratio[keep]
    if q.size > 4 * lowest:
        f, q = f[lowest:], q[lowest:]
    m = q.size
    hw = min(half_window, max(m // 4, 1))
    c = np.concatenate([[0.0], np.cumsum(np.pad(q, hw, mode="reflect"))])
    idx = np.arange(m) + hw
    total = c[idx + hw + 1] - c[idx - hw]
    inner = c[idx + guard + 1] - c[idx - guard]
    local = (total - inner) / (2 * hw - 2 * guard)
    r = q / local
    j = int(np.argmax(r))
    p = float(-np.expm1(m * np.log1p(-math.exp(-min(float(r[j]), 700.0)))))
    return float(f[j]), p, float(r[j])


def _kurtosis_test(recs, fit: CalibrationResult):
    zs = []
    for r in recs:
        y = np.asarray(r.positions, dtype=float)
        y = y - y.mean()
        m2 = float(np.mean(y * y))
        g2 = float(np.mean(y**4)) / m2**2 - 3.0
        # correlated frames: var(g2) ~ (24/N) sum_n r(n)^4 with the empirical autocorrelation
        n = y.size
        spec = np.fft.rfft(y, 2 * n)
        ac = np.fft.irfft(np.abs(spec) ** 2)[: min(n, 2000)] / n / m2
        stop = int(np.argmax(ac <= 0)) if np.any(ac <= 0) else len(ac)
        s4 = 1.0 + 2.0 * float(np.sum(ac[1:max(stop, 1)] ** 4))
        zs.append(g2 / math.sqrt(24.0 * s4 / n))
    z = float(np.sum(zs) / math.sqrt(len(zs)))
    p = float(math.erfc(abs(z) / math.sqrt(2.0)))
    return z, p


# Largest fitted hydrodynamic radius accepted, relative to the Stokes radius gamma/(6 pi eta):
# Faxen's law only raises gamma above 6 pi eta R, so R <= gamma/(6 pi eta); the margin covers
# the scatter of R in a weakly informative fit.
HYDRO_RADIUS_MARGIN = 1.5
DIODE_ALPHA_MAX = 1.05


def _plausible(name: str, params: dict, recs) -> tuple[bool, str]:
    """Physical consistency of a candidate's refit. ``hydrodynamics``: the fitted radius must
    not exceed the Stokes radius implied by the fitted gamma (near a wall gamma only grows,
    Faxen), else the high-frequency shape it absorbs is something else (on photodiode-filter
    data the hydrodynamic fit wants R ~ 3 x the Stokes radius). ``detector_filter``: the
    instantaneous fraction alpha cannot exceed 1 (no gain above the DC response)."""
    if name == "hydrodynamics":
        temp = float(np.median([float(r.temperature) for r in recs]))
        r_stokes = params["gamma"] / (6.0 * math.pi * float(water_viscosity(temp)))
        r_fit = params["hydro_radius"]
        if r_fit > HYDRO_RADIUS_MARGIN * r_stokes:
            return False, (f"fitted radius {r_fit * 1e6:.3g} um exceeds the Stokes radius "
                           f"{r_stokes * 1e6:.3g} um implied by gamma (gamma >= 6 pi eta R)")
    if name == "detector_filter" and params["diode_alpha"] > DIODE_ALPHA_MAX:
        return False, f"instantaneous fraction alpha = {params['diode_alpha']:.3g} > 1"
    return True, ""


#: A candidate that is not significant but moves k or gamma by more than this many of the base
#: fit's standard errors makes the base fit's errors dishonest: the data cannot tell the two
#: models apart, yet the answer depends on the choice (e.g. tracking noise on a W = dt camera
#: recording: blur + aliasing without noise fits as well, with k 14 SE low).
SENSITIVITY_SE = 2.0


def moved_by(base: CalibrationResult, before: dict, after: dict) -> dict:
    """k (or each k[i]) and gamma that differ between two optima by more than
    :data:`SENSITIVITY_SE` of the base fit's errors: name -> shift in those SEs."""
    errs = dict(zip(base.param_names, base.errors))
    out = {}
    for name in base.params:
        if not (name == "gamma" or name == "k" or name.startswith("k[")) \
                or name not in before or name not in after:
            continue
        e = errs[name]
        if np.isfinite(e) and e > 0 and abs(after[name] - before[name]) > SENSITIVITY_SE * e:
            out[name] = (after[name] - before[name]) / e
    return out


#: a candidate whose fit is worse than the base by more than this (chi^2_1 at 95 %, halved)
#: is one the data tell apart and reject: no "cannot tell the two apart" note for it
_WORSE_DLOGL = 1.92


def _sensitivity_notes(base: CalibrationResult, ranked, screened) -> list[str]:
    out = []
    for c in ranked:
        params = screened.get(c.effect)
        if c.significant or c.required or params is None or not c.plausible:
            continue
        if c.delta_loglik is not None and c.delta_loglik < -_WORSE_DLOGL:
            continue  # the data reject it (e.g. folding a photodiode's anti-aliased spectrum)
        shifts = [f"{n} by {z:+.1f} SE" for n, z in moved_by(base, base.params, params).items()]
        if shifts:
            out.append(f"{c.effect} is not significant, but adding it moves {', '.join(shifts)}: "
                       "the data cannot tell the two models apart and the result depends on the "
                       f"choice; prefer the physically complete model (add {c.effect} if the "
                       "instrument has it) and quote its larger errors")
    return out
