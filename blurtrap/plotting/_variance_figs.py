"""The paper's Figs. 3 and 4: fractional variance vs alpha at several exposures and powers,
and stiffness vs laser power, naive equipartition against the blur-corrected stiffness."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ._blur_figs import _ALPHA_LABEL, _s_curve
from ._common import MS, NM, blur_factor_np, is_result, kT, new_axes, trap_params


def _as_list(recordings):
    if hasattr(recordings, "positions") and hasattr(recordings, "frame_interval"):
        return [recordings]
    recs = list(recordings)
    if not recs:
        raise ValueError("no recordings given")
    return recs


# --------------------------------------------------------------------------------------------
# Figures 3 and 4: variance vs exposure and vs power
# --------------------------------------------------------------------------------------------
def _per_recording_k(params, n):
    if is_result(params):
        ks = np.asarray(params.k_per_recording, dtype=float)
        if ks.size == 1:
            ks = np.full(n, ks[0])
        if ks.size != n:
            raise ValueError(
                f"the CalibrationResult has {ks.size} per-recording stiffnesses but {n} "
                "recordings were given; pass the recordings it was fitted on"
            )
        return ks, float(params.gamma), float(params.tracking_var)
    if isinstance(params, Mapping):
        ks = np.broadcast_to(np.asarray(params["k"], dtype=float), (n,))
        return ks, float(params["gamma"]), float(params.get("tracking_var", 0.0))
    k, g, e2, _ = trap_params(params)
    return np.full(n, k), g, e2


def fig3_fractional_variance(recordings, params, *, ax=None):
    r"""Fig. 3: ``(var(X_m) - eps^2) / (kT/k)`` vs ``alpha = W k / gamma`` for recordings at
    several exposures and laser powers, with $S(\alpha)$.

    - `recordings`: the exposure series (one marker per laser power).
    - `params`: the ``CalibrationResult`` fitted on exactly these recordings (e.g.
      ``calibrate(recs, method="variance_vs_exposure")``; k per power, shared gamma and
      eps^2), or a mapping with ``k`` (scalar or one per recording) [N/m], ``gamma`` [N s/m],
      ``tracking_var`` [m^2].

    Error bars: correlated-sample standard error of each variance (DESIGN item 10).
    **Returns:** Figure with one axes.
    """
    from ..inference import empirical_variance_se

    recs = _as_list(recordings)
    ks, g, e2 = _per_recording_k(params, len(recs))
    groups: dict = {}
    for r, kk in zip(recs, ks, strict=True):
        groups.setdefault(r.laser_power, []).append((r, kk))
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    markers = "os^Dv<>P"
    a_all = []
    for j, (power, items) in enumerate(sorted(groups.items(),
                                              key=lambda it: (it[0] is None, it[0] or 0))):
        al, fr, er = [], [], []
        for r, kk in items:
            v, se = empirical_variance_se(r.positions)
            sigma2 = kT(r.temperature) / kk
            al.append(float(r.exposure) * kk / g)
            fr.append((v - e2) / sigma2)
            er.append(se / sigma2)
        kk = items[0][1]
        lab = (f"P = {power * 1e3:.4g} mW, k = {kk * 1e3:.3g} pN/nm" if power is not None
               else f"k = {kk * 1e3:.3g} pN/nm")
        ax.errorbar(np.asarray(al), np.asarray(fr), yerr=np.asarray(er),
                    fmt=markers[j % len(markers)], ms=5, capsize=2,
                    ls="none", label=lab)
        a_all.extend(al)
    a_all = np.asarray(a_all)
    _s_curve(ax, a_all.min() / 2, a_all.max() * 2)
    ax.set_xscale("log")
    ax.set_xlabel(_ALPHA_LABEL)
    ax.set_ylabel(r"(var$(X_m) - \varepsilon^2$) / ($k_BT/k$) (dimensionless)")
    ax.set_title(f"Fig. 3: fractional variance (gamma = {g * 1e6:.4g} pN s/um, "
                 f"eps = {math.sqrt(max(e2, 0.0)) * NM:.3g} nm)", fontsize=10)
    ax.legend(fontsize=8)
    return fig


def _close(a, b):
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b))


def _corrected_per_power(corrected, recs, powers):
    """The blur-corrected stiffness and its error per power [N/m] and the legend label, from
    a ``CalibrationResult`` (k per recording, averaged per power) or a mapping ``power [W] ->
    k`` or ``-> (k, k_err)``."""
    if is_result(corrected):
        ks = np.asarray(corrected.k_per_recording, dtype=float)
        kerr = np.asarray(corrected.k_per_recording_err, dtype=float)
        if ks.size != len(recs):
            raise ValueError(
                f"corrected has {ks.size} per-recording stiffnesses but {len(recs)} recordings "
                "were given; pass the recordings it was fitted on (or a mapping power -> k)"
            )
        ck, ce = [], []
        for p in powers:
            sel = [i for i, r in enumerate(recs) if _close(float(r.laser_power), p)]
            ck.append(float(np.mean(ks[sel])))
            ce.append(float(np.mean(kerr[sel])))
        return ck, ce, f"blur-corrected ({corrected.method}, {corrected.model})"
    ck, ce = [], []
    for p in powers:
        val = None
        for key, v in dict(corrected).items():
            if _close(float(key), p):
                val = v
        if val is None:
            raise ValueError(f"corrected has no stiffness for laser power {p} W")
        if np.ndim(val):
            ck.append(float(val[0]))
            ce.append(float(val[1]))
        else:
            ck.append(float(val))
            ce.append(0.0)
    return ck, ce, "blur-corrected"


def _naive_at_exposure(ax, recs, w, color, mark):
    """Naive equipartition ``kT/var(X_m)`` of the recordings at exposure ``w``, per power."""
    from ..inference import empirical_variance_se

    sel = [r for r in recs if _close(float(r.exposure), float(w))]
    if not sel:
        raise ValueError(f"no recordings with exposure {float(w) * MS:.4g} ms")
    pw, kn, ke = [], [], []
    for r in sel:
        v, se = empirical_variance_se(r.positions)
        kk = kT(r.temperature) / v
        pw.append(float(r.laser_power) * 1e3)
        kn.append(kk * 1e3)
        ke.append(kk * se / v * 1e3)
    ax.errorbar(pw, kn, yerr=ke, fmt=mark, color=color, ms=6, capsize=2,
                label=f"naive equipartition, W = {float(w) * MS:.3g} ms")


def _power_fit_lines(ax, power_fits, w, pp, color):
    """The ``k = c P`` blur-model fit at exposure ``w`` through the naive points (dashed) and
    its corrected line (dash-dot), when `power_fits` has one."""
    fit = None
    if power_fits:
        for key, res in power_fits.items():
            if _close(float(key), float(w)):
                fit = res
    if fit is not None and "c" in fit.param_names:
        pr = fit.params
        cc, g = pr["c"], pr["gamma"]
        e2 = pr.get("tracking_var", 0.0)
        t = float(fit.temperature)
        kp = cc * pp[1:]
        var = kT(t) / kp * blur_factor_np(float(w) * kp / g) + e2
        ax.plot(pp[1:] * 1e3, kT(t) / var * 1e3, color=color, ls="--", lw=1.2,
                label=f"k = cP blur-model fit at W = {float(w) * MS:.3g} ms")
        ax.plot(pp * 1e3, cc * pp * 1e3, color=color, ls="-.", lw=1.0,
                label=f"  corrected: c = {cc * 1e3:.4g} pN/nm/W")


def fig4_stiffness_vs_power(
    recordings,
    corrected,
    *,
    naive_exposures=None,
    power_fits=None,
    truth_c=None,
    ax=None,
):
    r"""Fig. 4: stiffness vs laser power: naive equipartition ``kT/var(X_m)`` at chosen
    exposures against the blur-corrected stiffness, with ``k = c P`` fits.

    - `recordings`: recordings with ``laser_power`` [W] (all exposures and powers).
    - `corrected`: the blur-corrected stiffness: a ``CalibrationResult`` fitted on
      `recordings` (k per recording, averaged per power), or a mapping
      ``power [W] -> k [N/m]`` or ``-> (k, k_err)``.
    - `naive_exposures`: exposures W [s] at which to show naive equipartition (default: the
      two longest in the data).
    - `power_fits`: mapping ``W [s] -> CalibrationResult`` of
      ``calibrate(recs_at_W, method="variance_vs_power")`` (parameters ``c``, ``gamma``,
      ``tracking_var``). Drawn as the fitted blur model through the naive points (dashed) and
      the corrected line ``k = c P`` (dash-dot), as in the paper.
    - `truth_c`: true ``c`` [N/m/W] for a reference line (simulations).

    **Returns:** Figure with one axes (power in mW, k in pN/nm).
    """
    recs = _as_list(recordings)
    if any(r.laser_power is None for r in recs):
        raise ValueError("fig4_stiffness_vs_power needs laser_power [W] on every recording")
    powers = sorted({float(r.laser_power) for r in recs})
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    pmax = max(powers)
    pp = np.linspace(0.0, 1.1 * pmax, 200)

    # blur-corrected stiffness per power
    ck, ce, clabel = _corrected_per_power(corrected, recs, powers)
    pw_mw = np.asarray(powers) * 1e3
    ax.errorbar(pw_mw, np.asarray(ck) * 1e3, yerr=np.asarray(ce) * 1e3, fmt="o", color="k",
                ms=6, capsize=2, label=clabel, zorder=5)

    # naive equipartition at chosen exposures
    exps = sorted({float(r.exposure) for r in recs})
    if naive_exposures is None:
        naive_exposures = exps[-2:]
    colors = ["C3", "C0", "C2", "C1", "C4"]
    marks = ["^", "s", "v", "D", "P"]
    for j, w in enumerate(naive_exposures):
        c = colors[j % len(colors)]
        _naive_at_exposure(ax, recs, w, c, marks[j % len(marks)])
        _power_fit_lines(ax, power_fits, w, pp, c)
    if truth_c is not None:
        ax.plot(pp * 1e3, float(truth_c) * pp * 1e3, color="0.5", lw=1.0,
                label=f"truth: c = {float(truth_c) * 1e3:.4g} pN/nm/W")
    ax.set_xlim(0, 1.1 * pmax * 1e3)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("laser power P [mW]")
    ax.set_ylabel("stiffness k [pN/nm]")
    ax.set_title("Fig. 4: stiffness vs power, naive vs blur-corrected")
    ax.legend(fontsize=7)
    return fig


__all__ = ["fig3_fractional_variance", "fig4_stiffness_vs_power"]
