"""The recordings handed to ``calibrate``: accepting them, and what their metadata say about
the bead (a known radius gives the Stokes friction, against which the fit is checked)."""

from __future__ import annotations

import math
import numbers
import os
from typing import Any

import numpy as np

from .._config import warn_if_float32


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
    xy = [i for i, r in enumerate(recs) if type(r).__name__ == "XYRecording"]
    if xy:
        raise TypeError(
            f"data holds x/y recordings (item(s) {xy}): calibrate fits one axis; use "
            "blurtrap.calibrate_xy(recording) (principal axes, k1, k2, a shared gamma), or "
            "calibrate one axis, e.g. calibrate(xy.x)")
    for i, r in enumerate(recs):
        if not (hasattr(r, "positions") and hasattr(r, "frame_interval")):
            hint = (" (a bare array: its frame interval and exposure are unknown; wrap arrays "
                    "with blurtrap.from_arrays(positions, frame_interval=..., exposure=...))"
                    if hasattr(r, "shape") else "")
            raise TypeError(f"data[{i}] is a {type(r).__name__}; expected a Recording{hint}")
        warn_if_float32("positions", r.positions)
    return recs


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
    from ..physics import water_viscosity

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



#: the position units whose slips the note below can name (the loaders' canonical names)
_UNIT_METRES = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}


def physics_notes(recs, radii, res, plan) -> list:
    """The notes that hold a fitted k and gamma (in SI) against physics: a gamma far from
    Stokes where the bead is known, and k or gamma outside any trapped bead's range. For
    positions in metres and for positions in volts with a stage drive (Rd from the drive:
    a stage in another unit than declared scales k and gamma by 1/s^2, an independent pass
    found k = 112 N/m and gamma 1e6 x Stokes with no note); not for volts through a known
    friction (gamma is the friction given). A friction given beside a drive is not used:
    the note says so and compares it with the fitted gamma."""
    exposure = exposure_notes(res, plan)
    if plan.volts and plan.drive is None:
        return exposure
    if plan.volts and plan.gamma_known is not None:
        out = [_drive_friction_note(res, plan.gamma_known)]
    else:
        out = _stokes_notes(recs, radii, res)
    return out + _plausibility_notes(recs, res, stage=plan.volts) + exposure


def _blur_b(a: float) -> float:
    """B(a) = 2 (cosh a - 1) / a^2 (paper eq. 8): the physics kernel's rho B at rho = 1."""
    from ..physics import rho_b_unchecked

    return float(rho_b_unchecked(np.float64(a), np.float64(0.0)))


#: the exposure note appears when a declared exposure 10 % off would move k by more than
#: this many of its standard errors
_EXPOSURE_SE = 0.5


def exposure_notes(res, plan) -> list:
    """A note when k and gamma rest on the declared exposure more than their errors say.

    With the exposure W and the tracking noise eps^2 both in the model, the frames cannot
    tell W from eps^2: their autocovariance is ``C(0) = kT/k S(a) + eps^2``, ``C(m) = kT/k
    B(a) rho^m`` (``a = W/tau``), so the data fix ``rho`` (hence tau) and ``kT/k B(a)``, and
    any declared W gives the same likelihood with ``k, gamma ~ B(W/tau)`` and eps^2 taking
    the rest. One exposure for every recording, eps^2 not held: when W 10 % longer would
    move k by more than :data:`_EXPOSURE_SE` of its SE, the note says by how much."""
    mdl = plan.model
    names = list(res.param_names)
    w = {float(r.exposure) for r in plan.recordings}
    if not (mdl.blur and mdl.noise) or len(w) != 1 or "tracking_var" in (plan.fixed or {}) \
            or "gamma" not in names:
        return []
    w0 = w.pop()
    k, k_err, tau = float(res.k), float(res.k_err), float(res.gamma) / float(res.k)
    if not (w0 > 0 and tau > 0 and math.isfinite(k_err) and k_err > 0):
        return []
    a = w0 / tau
    shift = _blur_b(1.1 * a) / _blur_b(a) - 1.0
    out = _point_sampling_note(res, plan, w0, a)
    if shift * k < _EXPOSURE_SE * k_err:
        return out
    return out + [f"k and gamma rest on the declared exposure W = {w0 * 1e3:.4g} ms (W/tau = "
            f"{a:.3g}): the frames cannot tell a longer exposure from less tracking noise (the "
            "same likelihood for any W, eps^2 taking the difference), and k, gamma scale as "
            "B(W/tau) = 2 (cosh(W/tau) - 1)/(W/tau)^2: an exposure 10 % longer than declared "
            f"gives k and gamma {shift * 100:.2g} % larger ({shift * k / k_err:.2g} SE). Check "
            "the camera's exposure (integration) time; with several exposures W is identified"]


def _point_sampling_note(res, plan, w0: float, a: float) -> list:
    """A photodiode declared to integrate over W whose fitted eps^2 rests on it: a
    point-sampling ADC (W' = 0) explains the same frames with less tracking noise. The
    frames fix ``C(0) = kT/k S(a) + eps^2`` and ``kT/k B(a)``, so eps^2 at another exposure
    W' is ``C(0) - kT/k B(a) S(a')/B(a')`` and k is ``k B(a')/B(a)``; the note gives both
    at W' = 0, or at the W' where eps^2 = 0. An independent pass: point samples declared
    W = dt gave eps^2 = (1.7 nm)^2, 58 SE above its true 0, and k 2 SE off at dt = tau/2,
    with no note."""
    from ..physics import BOLTZMANN, blur_factor_unchecked

    names = list(res.param_names)
    if plan.detector != "photodiode" or plan.volts or "tracking_var" not in names:
        return []
    i = names.index("tracking_var")
    eps2, eps2_err = float(res.values[i]), math.sqrt(abs(float(res.covariance[i, i])))
    if not (math.isfinite(eps2_err) and eps2 > 3.0 * eps2_err):
        return []
    k = float(res.k)
    var = BOLTZMANN * float(res.temperature) / k  # kT/k at the declared exposure
    c0, big_a = eps2 + var * float(blur_factor_unchecked(np.float64(a))), var * _blur_b(a)
    eps2_point = c0 - big_a  # eps^2 of point samples (W' = 0)
    if eps2 - eps2_point < 3.0 * eps2_err:  # the declared exposure hardly matters to eps^2
        return []
    w_at = 0.0  # the exposure of the reading given: point samples, or eps^2 = 0 at W' in (0, W)
    if eps2_point < 0:
        lo, hi = 0.0, a  # S/B falls from 1 at 0: the W' where eps^2 = 0, by bisection
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            s_b = float(blur_factor_unchecked(np.float64(mid))) / _blur_b(mid)
            lo, hi = (mid, hi) if s_b > c0 / big_a else (lo, mid)
        w_at = hi
    k_at = k * (_blur_b(w_at) if w_at > 0 else 1.0) / _blur_b(a)  # the same kT/k B
    if eps2_point > 3.0 * eps2_err and abs(k_at - k) < 0.5 * float(res.k_err):
        return []  # real tracking noise either way, and k hardly moves: the declaration stands
    alt = (f"by point samples (W -> 0) with eps^2 = {eps2_point * 1e18:.3g} nm^2" if w_at == 0 else
           f"by an exposure of {w_at / a * w0 * 1e3:.3g} ms and no tracking noise")
    return [f"eps^2 = {eps2 * 1e18:.3g} nm^2 ({eps2 / eps2_err:.2g} SE above 0) rests on the photodiode "
            f"integrating over the declared exposure W = {w0 * 1e3:.4g} ms: the same frames are described "
            f"as well {alt} (k = {k_at * 1e3:.4g} pN/nm, {(k_at / k - 1) * 100:+.2g} %, "
            f"{(k_at - k) / float(res.k_err):+.2g} SE): the frames cannot tell a shorter exposure from "
            "more tracking noise. An ADC that samples points does not integrate over the frame interval: "
            "declare the time it averages over (e.g. 1 % of the frame interval for a sample-and-hold)"]


def _drive_friction_note(res, gamma_known) -> str:
    g0, s0 = gamma_known
    g, sg = float(res.gamma), float(res.gamma_err)
    z = (g - g0) / math.sqrt(sg ** 2 + s0 ** 2) if math.isfinite(sg) and sg + s0 > 0 else math.nan
    verdict = (f"they disagree (z = {z:.2g}): check the bead radius, its distance to the "
               "surface, the viscosity and the stage's calibration and unit"
               if abs(z) > 3 else f"consistent (z = {z:.2g})")
    return (f"the friction given ({g0 * 1e6:.5g} pN s/um, friction='stokes' or fixed gamma) is "
            "not used: with a stage drive the displacement sensitivity comes from the drive "
            f"and gamma is fitted, {g * 1e6:.5g} +- {sg * 1e6:.2g} pN s/um, {g / g0:.3g} x the "
            f"friction given: {verdict}. Without the drive (no stage column) the friction "
            "given would set Rd")


def _plausibility_notes(recs, res, stage=False) -> list:
    """A note when a fitted stiffness or friction lies outside its physically plausible
    range (``Param.bounds``, the support of the default priors): almost always positions in
    another unit than declared. k and gamma scale as 1/s^2 when the positions are s x too
    large, so the note names the unit that brings them into range (positions in metres);
    ``stage``: positions in volts scaled by a stage drive (Rd), whose stage positions (in
    metres) then carry the slip: the note names the factor."""
    from ..effects import UNIT_SLIP_QUANTITIES, implausible

    bad = [(n, v, q) for n, v in zip(res.param_names, np.asarray(res.values, dtype=float))
           if n.split("[")[0] in UNIT_SLIP_QUANTITIES and (q := implausible(n, v)) is not None]
    if not bad:
        return []
    shown = "; ".join(f"{n} = {v:.3g} {q.unit} ({v * q.lab_factor:.3g} {q.lab_unit}), "
                      f"expected {q.range_text(lab=False)}" for n, v, q in bad)
    meta = getattr(recs[0], "metadata", None) or {}
    declared = "m" if stage else (str(meta.get("position_unit", "m")) if hasattr(meta, "get")
                                  else "m")
    hint = ""
    if stage:
        fits = [s for s in (1e-9, 1e-6, 1e-3, 1e3, 1e6, 1e9)
                if not any(q.outside(v / s**2) for _, v, q in bad)]
        if fits:
            hint = (f"; with the stage positions {fits[0]:g} x what was given they would be "
                    "in range: check the stage's unit (Recording(stage=...) is in metres; "
                    "a stage_nm / stage_um column, um read as nm or the reverse)")
        else:
            hint = ": check the stage's unit and the drive amplitude"
    elif declared in _UNIT_METRES:
        best = None
        for unit, metres in _UNIT_METRES.items():
            s = metres / _UNIT_METRES[declared]  # positions were s x what was declared
            ok = not any(q.outside(v / s**2) for _, v, q in bad)
            # the likeliest: closest to the middle (log scale) of the plausible ranges
            dist = sum(abs(math.log(v / s**2 / math.sqrt(math.prod(q.bounds or (1.0, 1.0)))))
                       for _, v, q in bad)
            if unit != declared and ok and (best is None or dist < best[1]):
                best = (unit, dist)
        if best is not None:
            hint = (f"; positions declared in {declared!r} give these values, in "
                    f"{best[0]!r} they would be in range: check the position unit")
    return [f"implausible: {shown} (a trapped bead in a liquid lies within these "
            f"ranges){hint or ': check the position unit and scale'}"]


#: a calibration whose goodness of fit has p below this gets a note saying so (when no
#: other note quotes the goodness of fit): a fit of a model the data contradict gives k,
#: gamma and errors that may be far off (an independent pass found p = 0 with k 13-43 SE
#: off and no note: an undeclared diode filter, a wrong exposure, repeated frames)
MISFIT_ALPHA = 1e-3


def misfit_note(res, notes) -> list:
    """``[note]`` when ``res``' goodness of fit fails (p < :data:`MISFIT_ALPHA`) and none of
    ``notes`` (all the result's notes) quotes the goodness of fit, else ``[]``."""
    p = (res.gof or {}).get("p_value")
    if not (isinstance(p, (float, int)) and p < MISFIT_ALPHA):
        return []
    if any("goodness of fit" in n for n in notes):
        return []
    pv = f"p = {p:.2g}" if p > 0 else "p < 1e-300"
    return [f"the model does not fit the data (goodness of fit {pv}{_misfit_band(res)}): "
            "k, gamma and their errors may be biased by an effect the model lacks (another "
            "note may name it). bt.diagnose(data) ranks the effects that could explain the "
            "misfit, and calibrate(..., model='standard+<effect>') adds one"]


def _misfit_band(res) -> str:
    """Where the data/model ratio of a spectral fit departs most from 1 (of 20 bands with
    equal numbers of fitted ordinates), or '' without the ratio and its weights."""
    ex = res.extras or {}
    if not all(name in ex for name in ("f", "ratio", "weight")):
        return ""
    f, q, w = (np.ravel(np.asarray(ex[name], dtype=float)) for name in ("f", "ratio", "weight"))
    if not f.shape == q.shape == w.shape:
        return ""
    # fitted ordinates only: padding, excluded ranges and left-out spikes have weight 0
    ok = (w > 0) & (f > 0) & (q > 0) & np.isfinite(q)
    if np.count_nonzero(ok) < 40:
        return ""
    order = np.argsort(f[ok])
    f, q = f[ok][order], q[ok][order]
    groups = np.array_split(np.arange(f.size), 20)
    g = max(groups, key=lambda idx: idx.size * (float(np.mean(q[idx])) - 1.0) ** 2)
    m = float(np.mean(q[g]))
    return (f"; the largest misfit: the data {'above' if m > 1 else 'below'} the model by "
            f"{abs(m - 1) * 100:.2g} % at {f[g[0]]:.4g}-{f[g[-1]]:.4g} Hz")
