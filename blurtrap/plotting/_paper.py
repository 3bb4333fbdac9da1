"""The seven figures of Wong & Halvorsen, Opt. Express 14, 12517 (2006), from blurtrap objects.

Every function returns a matplotlib ``Figure`` (drawn in lab units, labelled; a new pyplot
figure unless ``ax=``/``fig=`` says where to draw) and computes no fits: pass it recordings
and ``CalibrationResult`` objects (SI units) made with ``blurtrap.calibrate``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ._common import (
    FIT_STYLE,
    MS,
    NM,
    NM2,
    blocked_psd,
    blur_factor_np,
    fit_n_blocks,
    gamma_pdf,
    is_result,
    kT,
    model_name,
    model_psd,
    new_axes,
    new_figure,
    normal_pdf,
    sample_variance_se_np,
    trap_params,
)

_ALPHA_LABEL = r"dimensionless exposure $\alpha = W/\tau$ (dimensionless)"
_FRAC_LABEL = r"fractional variance var$(X_m)$ / ($k_BT/k$) (dimensionless)"


def _as_list(recordings):
    if hasattr(recordings, "positions") and hasattr(recordings, "frame_interval"):
        return [recordings]
    recs = list(recordings)
    if not recs:
        raise ValueError("no recordings given")
    return recs


def _s_curve(ax, lo, hi, **kw):
    a = np.logspace(math.log10(lo), math.log10(hi), 300)
    style = dict(color="k", lw=1.5, label=r"$S(\alpha)$, eq. (8)")
    style.update(kw)
    ax.plot(a, blur_factor_np(a), **style)


# --------------------------------------------------------------------------------------------
# Figure 1
# --------------------------------------------------------------------------------------------
def fig1a_universal_curve(
    positions,
    exposures,
    k,
    gamma,
    *,
    temperature=295.0,
    frame_interval=None,
    tracking_var=0.0,
    labels=None,
    ax=None,
):
    r"""Fig. 1(a): simulated fractional variance vs $\alpha$ collapsing on $S(\alpha)$.

    **Arguments:**

    - `positions`: frames [m] from ``simulate(k, gamma, ExposureWindows(exposures), ...)``:
      shape ``(S, n_windows, n_traces, n_frames)`` for S settings (``(S, n_windows,
      n_frames)`` and ``(n_windows, [n_traces,] n_frames)`` for one setting work too).
    - `exposures`: the window durations W [s], in the order of the windows axis.
    - `k` [N/m], `gamma` [N s/m]: one value per setting (broadcast).
    - `temperature` [K]; `tracking_var` [m^2] subtracted before rescaling.
    - `frame_interval` [s]: if given, error bars use the correlated-sample standard error
      (DESIGN item 10); otherwise the paper's ``sqrt(2/N)``.
    - `labels`: one legend label per setting.

    **Returns:** Figure with one axes (log alpha axis).
    """
    p = np.asarray(positions, dtype=float)
    w = np.atleast_1d(np.asarray(exposures, dtype=float))
    k_, g_ = np.broadcast_arrays(np.atleast_1d(np.asarray(k, float)),
                                 np.atleast_1d(np.asarray(gamma, float)))
    n_set = k_.size
    if p.ndim == 2:
        p = p[None, :, None, :]
    elif p.ndim == 3:
        if n_set > 1 or p.shape[0] != w.size:
            p = p[:, :, None, :]
        else:
            p = p[None]
    if p.ndim != 4 or p.shape[1] != w.size or p.shape[0] != n_set:
        raise ValueError(
            f"positions of shape {np.shape(positions)} do not match {n_set} setting(s) x "
            f"{w.size} exposure window(s); expected (settings, windows, [traces,] frames)"
        )
    n_tr, n = p.shape[2], p.shape[3]
    v = np.var(p, axis=-1).mean(axis=-1)  # (S, n_win)
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    markers = "osD^vP*X"
    a_all = []
    for i in range(n_set):
        kt = kT(temperature)
        sigma2 = kt / k_[i]
        tau = g_[i] / k_[i]
        alpha = w / tau
        frac = (v[i] - tracking_var) / sigma2
        if frame_interval is not None:
            se = sample_variance_se_np(n, k_[i], g_[i], w, float(frame_interval),
                                       float(temperature), float(tracking_var))
            err = se / math.sqrt(n_tr) / sigma2
        else:
            err = frac * math.sqrt(2.0 / (n * n_tr))
        lab = (labels[i] if labels is not None else
               f"k = {k_[i] * 1e3:.3g} pN/nm, tau = {tau * MS:.3g} ms")
        ax.errorbar(alpha, frac, yerr=err, fmt=markers[i % len(markers)], ms=5, capsize=2,
                    ls="none", label=lab)
        a_all.append(alpha)
    a_all = np.concatenate(a_all)
    _s_curve(ax, a_all.min() / 2, a_all.max() * 2)
    ax.set_xscale("log")
    ax.set_xlabel(_ALPHA_LABEL)
    ax.set_ylabel(_FRAC_LABEL)
    ax.set_title("Fig. 1a: simulated variance vs exposure collapses on S(alpha)")
    ax.legend(fontsize=8)
    return fig


def fig1b_histogram(recording, params, *, bins=60, ax=None):
    r"""Fig. 1(b): histogram of measured frame positions with the predicted blurred normal
    (variance ``kT/k S(alpha) + eps^2``, solid) and the blur-free normal (``kT/k + eps^2``,
    dotted).

    - `recording`: a ``Recording`` (its exposure and temperature are used).
    - `params`: ``CalibrationResult``, mapping ``{"k", "gamma"[, "tracking_var"]}`` [SI] or
      tuple — the true or fitted trap.

    **Returns:** Figure with one axes (position in nm).
    """
    k, g, e2, _ = trap_params(params)
    t = float(recording.temperature)
    x = (np.asarray(recording.positions) - np.mean(recording.positions)) * NM
    sigma2 = kT(t) / k
    alpha = float(recording.exposure) * k / g
    var_blur = (sigma2 * float(blur_factor_np(alpha)) + e2) * NM2
    var_free = (sigma2 + e2) * NM2
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    ax.hist(x, bins=bins, density=True, color="0.75", edgecolor="0.5",
            label=f"frames (N = {x.size}), var = {np.var(x):.4g} nm$^2$")
    lim = 4.5 * math.sqrt(var_free)
    xs = np.linspace(-lim, lim, 400)
    ax.plot(xs, normal_pdf(xs, 0.0, math.sqrt(var_blur)), color="C3", lw=1.8,
            label=f"predicted, blurred: var = {var_blur:.4g} nm$^2$")
    ax.plot(xs, normal_pdf(xs, 0.0, math.sqrt(var_free)), color="k", ls=":", lw=1.8,
            label=f"blur-free: var = {var_free:.4g} nm$^2$")
    ax.set_xlabel("position - mean [nm]")
    ax.set_ylabel("probability density [1/nm]")
    ax.set_title(f"Fig. 1b: frame histogram, W = {float(recording.exposure) * MS:.3g} ms, "
                 f"alpha = {alpha:.3g}")
    ax.legend(fontsize=8)
    return fig


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
    from ..inference import empirical_variance_se

    recs = _as_list(recordings)
    if any(r.laser_power is None for r in recs):
        raise ValueError("fig4_stiffness_vs_power needs laser_power [W] on every recording")
    powers = sorted({float(r.laser_power) for r in recs})
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    pmax = max(powers)
    pp = np.linspace(0.0, 1.1 * pmax, 200)

    # blur-corrected stiffness per power
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
        clabel = f"blur-corrected ({corrected.method}, {corrected.model})"
    else:
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
        clabel = "blur-corrected"
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
        c = colors[j % len(colors)]
        ax.errorbar(pw, kn, yerr=ke, fmt=marks[j % len(marks)], color=c, ms=6, capsize=2,
                    label=f"naive equipartition, W = {float(w) * MS:.3g} ms")
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
            ax.plot(pp[1:] * 1e3, kT(t) / var * 1e3, color=c, ls="--", lw=1.2,
                    label=f"k = cP blur-model fit at W = {float(w) * MS:.3g} ms")
            ax.plot(pp * 1e3, cc * pp * 1e3, color=c, ls="-.", lw=1.0,
                    label=f"  corrected: c = {cc * 1e3:.4g} pN/nm/W")
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


# --------------------------------------------------------------------------------------------
# Figure 5: drift (appendix B)
# --------------------------------------------------------------------------------------------
def fig5_highpass(
    recording,
    corner_frequency=None,
    *,
    params=None,
    fraction=(0.1, 0.5),
    n_cut=20,
    f_max=None,
    ax=None,
):
    r"""Fig. 5: variance vs high-pass cut-off and its linear extrapolation to 0 Hz (appendix
    B; :func:`blurtrap.inference.drift_extrapolation`).

    - `recording`: a ``Recording`` (possibly with drift).
    - `corner_frequency` f_c [Hz]; default ``k/(2 pi gamma)`` from `params`.
    - `params`: optional true/fitted trap (``CalibrationResult``, mapping or tuple); when
      given, the expected curve ``C(0) - 2 int_0^f1 P_d(f) df`` of the drift-free model is
      drawn (its slope at 0 is ``-2 P_d(0)``, DESIGN item 8).
    - `fraction`: the fitted range of cut-offs as fractions of f_c.
    - `f_max` [Hz]: largest cut-off shown (default ``min(1.2 f_c, Nyquist)``).

    **Returns:** Figure with one axes (cut-off in Hz, variance in nm^2).
    """
    from ..inference import drift_extrapolation, highpass_variance_curve

    dt = float(recording.frame_interval)
    if corner_frequency is None:
        if params is None:
            raise ValueError("give corner_frequency [Hz] or params (k, gamma) to set it")
        k, g, _, _ = trap_params(params)
        corner_frequency = k / (2 * math.pi * g)
    fc = float(corner_frequency)
    y = np.asarray(recording.positions)
    v0, slope, cut, v = drift_extrapolation(y, dt, corner_frequency=fc, fraction=fraction,
                                            n_cut=n_cut)
    nyq = 0.5 / dt
    fm = float(f_max) if f_max is not None else min(1.2 * fc, nyq)
    grid = np.linspace(0.0, fm, 300)
    vg = highpass_variance_curve(y, dt, grid)
    v_unf = float(np.var(y))
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    ax.plot(grid, vg * NM2, color="0.55", lw=1.0, label="variance after ideal high-pass")
    ax.plot(cut, v * NM2, "o", color="C0", ms=4, label="fitted cut-offs")
    fl = np.linspace(0.0, cut.max(), 50)
    ax.plot(fl, (v0 + slope * fl) * NM2, color="C3", ls="--", lw=1.5,
            label=f"linear fit, slope {slope * NM2:.3g} nm$^2$/Hz")
    ax.plot([0.0], [v0 * NM2], "*", color="C3", ms=14,
            label=f"extrapolated to 0 Hz: {v0 * NM2:.4g} nm$^2$")
    ax.plot([0.0], [v_unf * NM2], "x", color="k", ms=10, mew=2,
            label=f"unfiltered: {v_unf * NM2:.4g} nm$^2$")
    if params is not None:
        k, g, e2, t = trap_params(params)
        fine = np.linspace(0.0, fm, 2000)
        fine[0] = 1e-9 * fm
        pd = model_psd(params, recording, fine, model="standard")
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (pd[1:] + pd[:-1]) * np.diff(fine))])
        c0 = kT(t) / k * float(blur_factor_np(float(recording.exposure) * k / g)) + e2
        ax.plot(fine, (c0 - 2.0 * cum) * NM2, color="k", ls=":", lw=1.2,
                label=f"drift-free model (C(0) = {c0 * NM2:.4g} nm$^2$)")
    ax.axvline(fc, color="0.7", lw=0.8, ls="-")
    ax.text(fc, ax.get_ylim()[1], " f_c", va="top", fontsize=8, color="0.4")
    ax.set_xlim(left=-0.02 * fm)
    ax.set_xlabel("high-pass cut-off frequency [Hz]")
    ax.set_ylabel("variance [nm$^2$]")
    ax.set_title(f"Fig. 5: drift removal by extrapolation (f_c = {fc:.4g} Hz)")
    ax.legend(fontsize=8)
    return fig


# --------------------------------------------------------------------------------------------
# Figures 6 and 7: blocked power spectrum (appendix C)
# --------------------------------------------------------------------------------------------
def _fits_mapping(fits):
    if fits is None:
        return {}
    if is_result(fits) or (isinstance(fits, Mapping) and "k" in fits):
        fits = [fits]
    if isinstance(fits, Mapping):
        return dict(fits)
    out = {}
    for f in fits:
        name = model_name(f)
        out[FIT_STYLE.get(name, {}).get("label", name)] = f
    return out


def fig6_psd(recording, fits=None, *, n_blocks=None, one_sided=True, ax=None):
    r"""Fig. 6: log-log blocked power spectrum with model fits.

    - `recording`: the ``Recording``.
    - `fits`: a ``CalibrationResult`` or a list of them (``calibrate(rec, method="psd",
      model=...)``), or a mapping label -> result; styled by model (``standard``/``blur``
      solid red, ``naive`` dashed blue, ``naive_aliased`` dotted green as in the paper).
    - `n_blocks`: blocks of the periodogram (default: what the fit used).
    - `one_sided`: plot ``2 P(f)`` for ``f > 0`` (the paper's convention).

    **Returns:** Figure with one axes.
    """
    fm = _fits_mapping(fits)
    nb = fit_n_blocks(next(iter(fm.values())) if fm else None, recording, n_blocks)
    f, p, nb = blocked_psd(recording, nb)
    fac = 2.0 if one_sided else 1.0
    fig, ax = new_axes(figsize=(6.4, 4.6), ax=ax)
    ax.loglog(f, fac * p * NM2, ".", color="0.35", ms=3,
              label=f"data: {nb} blocks of {recording.n_frames // nb} frames")
    for label, fit in fm.items():
        name = model_name(fit)
        style = dict(FIT_STYLE.get(name, dict(color=None, ls="-", lw=1.5)))
        style["label"] = label
        k, g, e2, _ = trap_params(fit)
        style["label"] += f": k = {k * 1e3:.4g} pN/nm, gamma = {g * 1e6:.4g} pN s/um"
        ax.loglog(f, fac * model_psd(fit, recording, f) * NM2, **style)
    ax.set_xlabel("frequency f [Hz]")
    ax.set_ylabel(("one-sided" if one_sided else "two-sided") + " PSD [nm$^2$/Hz]")
    ax.set_title(f"Fig. 6: power spectrum, fs = {recording.sampling_rate:.5g} Hz, "
                 f"W = {float(recording.exposure) * MS:.3g} ms")
    ax.legend(fontsize=7, loc="lower left", framealpha=0.85)
    return fig


def fig7_deviation(recording, fit, *, n_blocks=None, bins=25, fig=None):
    r"""Fig. 7: fractional deviation data/model of the blocked PSD: scatter vs frequency with
    the ``1 +- 1/sqrt(n_blocks)`` band, and its histogram with the normal approximation and
    the exact Gamma(n_blocks) law (mean 1) of an average of n_blocks periodograms
    (appendix C; Berg-Sorensen & Flyvbjerg 2004).

    - `recording`, `fit` (a ``CalibrationResult``), `n_blocks` (default: what the fit used).
    - `fig`: an empty figure to draw into (default: a new pyplot figure).

    **Returns:** Figure with two axes.
    """
    nb = fit_n_blocks(fit, recording, n_blocks)
    f, p, nb = blocked_psd(recording, nb)
    ratio = p / model_psd(fit, recording, f)
    sd = 1.0 / math.sqrt(nb)
    fig, (a1, a2) = new_figure(1, 2, figsize=(9.0, 3.8), fig=fig,
                               gridspec_kw=dict(width_ratios=(2, 1)))
    a1.plot(f, ratio, ".", color="0.3", ms=3, label="data / model")
    a1.axhline(1.0, color="k", lw=0.8)
    for s in (-1, 1):
        a1.axhline(1.0 + s * sd, color="C3", ls="--", lw=1.2,
                   label=r"$1 \pm 1/\sqrt{n_b}$" if s > 0 else None)
    a1.set_xlabel("frequency f [Hz]")
    a1.set_ylabel("P_data / P_model (dimensionless)")
    a1.set_title(f"Fig. 7: fractional deviation, model {model_name(fit)}, n_b = {nb}")
    a1.legend(fontsize=8)
    a2.hist(ratio, bins=bins, density=True, color="0.75", edgecolor="0.5", label="data / model")
    xs = np.linspace(max(0.0, 1 - 5 * sd), 1 + 5 * sd, 300)
    a2.plot(xs, normal_pdf(xs, 1.0, sd), color="C3", lw=1.6, label=f"normal, sd 1/sqrt({nb})")
    a2.plot(xs, gamma_pdf(xs, nb), color="k", ls="--", lw=1.2, label=f"Gamma({nb}), mean 1")
    a2.set_xlabel("P_data / P_model (dimensionless)")
    a2.set_ylabel("probability density (dimensionless)")
    a2.legend(fontsize=7)
    return fig


__all__ = [
    "fig1a_universal_curve",
    "fig1b_histogram",
    "fig3_fractional_variance",
    "fig4_stiffness_vs_power",
    "fig5_highpass",
    "fig6_psd",
    "fig7_deviation",
]

