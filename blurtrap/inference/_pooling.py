"""Which shared parameter the recordings of a joint fit disagree on.

A joint fit shares gamma and eps^2 across its recordings (and k within each group of
``layout.k_index``). When the joint goodness of fit fails, each recording is fitted alone
(the same model and Whittle objective) and, for every shared parameter, the spread of the
recordings' own estimates is tested against their standard errors (Cochran's Q: ``sum
(theta_i - theta_w)^2 / se_i^2`` with ``theta_w`` the inverse-variance mean, chi^2 with
``m - 1`` dof for ``m`` recordings). An independent pass found an exposure series whose
tracking error grew at short exposures (photon-limited: 6.3, 3.7, 2 nm at W = 0.1, 0.3, 1
dt) fitted jointly with k 27 SE and gamma 32 SE off, and the only note blamed "recordings of
different stiffness": the stiffness was the same in all three.
"""

from __future__ import annotations

import math

import numpy as np

from ._fit import chi2_sf, fit_ml
from ._frames import temporal_information
from ._problems import make_layout, spectral_nll
from ._refusals import _unidentified
from ._spectral import _spectral_args
from ._starts import _start_vector

#: a shared parameter the recordings disagree on at Q's p below this is named
POOL_ALPHA = 1e-3

_WHY = {
    "tracking_var": ("the tracking error differs between the recordings (a camera's grows at "
                     "shorter exposures or in dimmer light: photon-limited localisation), but "
                     "the joint fit shares one eps^2. Calibrate each recording alone, or "
                     "pool only recordings of one exposure and illumination"),
    "gamma": ("the friction differs between the recordings (another bead, another height "
              "above the surface, another temperature or viscosity), but the joint fit "
              "shares one gamma. Calibrate each recording alone, or pool only recordings of "
              "one bead at one height"),
    "k": ("the stiffness differs between recordings that share one k (another laser power, "
          "bead or height), but the joint fit shares it. Give each recording's laser_power, "
          "or fit k='per_recording'"),
}
#: effect parameters one recording alone cannot determine (they relate recordings at
#: different powers): models with them get no per-recording fits
_JOINT_ONLY = ("power_offset", "heating")


def alone_estimates(recs, layout, model, f_range=None, excluded=None, fixed=None):
    """Each recording fitted alone: a list of ``{name: (value, se)}`` (names of a single
    recording's layout: ``k``, ``gamma``, ...), ``None`` for a fit that did not converge or
    that ``calibrate`` would refuse (frames without temporal information, k or gamma not
    identified: an independent pass found a note quoting such a recording's eps^2 as
    27.39 +- 0.39 nm^2 against a true 7.84).
    Held parameters stay held (their entries are left out)."""
    from ._ml_fits import _fit_held  # _ml_fits imports this module

    if any(n.startswith(_JOINT_ONLY) for n in layout.extra_names):
        return [None] * len(recs)
    out = []
    for r in recs:
        if not temporal_information(r)[0]:  # calibrate refuses such a recording alone
            out.append(None)
            continue
        lay = make_layout([r], "shared", layout.noise, layout.extra_names)
        args = _spectral_args([r], lay, model, 1, f_range, excluded)
        try:
            res, _ = _fit_held(fit_ml, spectral_nll, _start_vector([r], lay, model.noise),
                               args, lay.names, fixed or {}, False)
        except (ValueError, FloatingPointError):
            out.append(None)
            continue
        # a fit whose errors are conditional on a bound (too small), or that misfits its
        # own recording (a misfit shared by all moves each differently), tests nothing here
        if not bool(res.converged) or res.conditional or _unidentified(res, lay.names) or \
                _own_gof(res.value, args) < POOL_ALPHA:
            out.append(None)
            continue
        val, se = np.asarray(res.value, float), np.sqrt(np.abs(np.diag(np.asarray(res.cov))))
        out.append({n: (float(v), float(s)) for n, v, s in zip(lay.names, val, se)
                    if not (fixed and n in fixed)})
    return out


def _own_gof(p, args) -> float:
    """The goodness-of-fit p of one recording's own fit ``p`` on its ``args``."""
    from ._spectral import _psd_jit, spectral_gof

    psd = _psd_jit(p, args)
    return float(spectral_gof(args.power / psd, args.weight, int(p.shape[0]))["p_value"])


def _cochran(pairs):
    """``(Q, dof, p)`` of the estimates ``[(value, se), ...]`` (finite, se > 0 only), or
    None with fewer than two."""
    pairs = [(v, s) for v, s in pairs if math.isfinite(v) and math.isfinite(s) and s > 0]
    if len(pairs) < 2:
        return None
    v = np.array([p[0] for p in pairs])
    w = 1.0 / np.array([p[1] for p in pairs]) ** 2
    mean = float(np.sum(w * v) / np.sum(w))
    q = float(np.sum(w * (v - mean) ** 2))
    return q, len(pairs) - 1, float(chi2_sf(q, len(pairs) - 1))


def disagreements(layout, alone) -> dict:
    """``{name: (Q, dof, p, [(i, value, se), ...])}`` of the shared parameters whose
    recordings' own estimates disagree (p < :data:`POOL_ALPHA`); ``k`` within each group of
    recordings that share one (not for ``k = c P``)."""
    out = {}
    groups = [] if layout.linear_power else [
        np.flatnonzero(np.asarray(layout.k_index) == g) for g in range(layout.n_k)]
    names = [("k", members) for members in groups if members.size > 1]
    names += [(n, np.arange(len(alone))) for n in ("gamma", "tracking_var")]
    for name, members in names:
        rows = [(int(i), *alone[i][name]) for i in members
                if alone[i] is not None and name in alone[i]]
        test = _cochran([(v, s) for _, v, s in rows])
        if test is not None and test[2] < POOL_ALPHA and (name not in out or
                                                         test[0] > out[name][0]):
            out[name] = (*test, rows)
    return out


def pooling_note(found: dict, k_named: bool, recs) -> str | None:
    """The note naming the shared parameters the recordings ``recs`` disagree on (k only
    unless ``k_named``: :func:`._ml_fits.shared_k_note` named it already), with each
    recording's own estimate (lab units for positions in metres, else SI in the positions'
    unit); None when there is none."""
    from ..effects import QUANTITIES
    from ._refusals import _unit

    metres = _unit(recs) == "m"
    named = [n for n in ("tracking_var", "gamma") + (() if k_named else ("k",)) if n in found]
    if not named:
        return None
    parts = []
    for n in named:
        q, dof, p, rows = found[n]
        f, unit = (QUANTITIES[n].lab_factor, QUANTITIES[n].lab_unit) if metres else \
            (1.0, "SI, in the positions' unit")
        own = ", ".join(f"{i}: {v * f:.4g} +- {s * f:.2g}" for i, v, s in rows)
        parts.append(f"on {n} (each recording alone, {unit}: {own}; heterogeneity "
                     f"chi^2 = {q:.4g}, {dof} dof, p = {p:.2g}): {_WHY[n]}")
    return ("the recordings fitted together disagree " + "; and ".join(parts)
            + ". The joint k, gamma and their errors are biased by the shared value (or a "
            "misfit of the model acts differently on the recordings: check each one's own "
            "fit and diagnose)")
