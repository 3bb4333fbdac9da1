"""Motion blur in pictures: the paper's Fig. 1 (simulated variance collapsing on S(alpha);
the histogram of blurred frames) and the error map of naive equipartition over stiffness and
exposure (Wong & Halvorsen, Opt. Express 14, 12517 (2006))."""

from __future__ import annotations

import math

import numpy as np

from ._common import (
    MS,
    NM,
    NM2,
    blur_factor_np,
    kT,
    new_axes,
    normal_pdf,
    sample_variance_se_np,
    trap_params,
)

_ALPHA_LABEL = r"dimensionless exposure $\alpha = W/\tau$ (dimensionless)"
_FRAC_LABEL = r"fractional variance var$(X_m)$ / ($k_BT/k$) (dimensionless)"


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


def naive_error_map(k_grid, w_grid, error, *, ax=None,
                    contours=(-50, -20, -10, -5, 5, 10, 20, 50, 100, 200),
                    title=None):
    r"""Heatmap of the relative error of naive equipartition ``kT/var(X_m)`` over a grid of
    true stiffness k and exposure W.

    - `k_grid` [N/m] (rows), `w_grid` [s] (columns).
    - `error`: array of shape ``(len(k_grid), len(w_grid))``: relative error
      ``(k_naive - k)/k`` (a fraction; shown in %).
    - `contours`: error levels [%] drawn as labelled contour lines.
    - `ax`: draw into an existing axes (e.g. one panel per bead size).

    **Returns:** the Figure (of `ax` if given).
    """
    k = np.asarray(k_grid, dtype=float).ravel()
    w = np.asarray(w_grid, dtype=float).ravel()
    e = np.asarray(error, dtype=float)
    if e.shape != (k.size, w.size):
        raise ValueError(
            f"error must have shape (len(k_grid), len(w_grid)) = ({k.size}, {w.size}); "
            f"got {e.shape}"
        )
    from matplotlib.colors import TwoSlopeNorm

    fig, ax = new_axes(figsize=(6.0, 4.6), ax=ax)
    pct = 100.0 * e
    vmin = min(float(np.nanmin(pct)), -1e-6)
    vmax = max(float(np.nanmax(pct)), 1e-6)
    norm = TwoSlopeNorm(vmin=vmin, vcenter=0.0, vmax=vmax)
    mesh = ax.pcolormesh(w * MS, k * 1e3, pct, cmap="RdBu_r", norm=norm, shading="nearest")
    cb = fig.colorbar(mesh, ax=ax)
    cb.set_label("naive k error (k_naive - k)/k [%]")
    if contours and k.size > 1 and w.size > 1:
        lv = sorted(c for c in contours if vmin < c < vmax)
        if lv:
            cs = ax.contour(w * MS, k * 1e3, pct, levels=lv, colors="k", linewidths=0.8)
            ax.clabel(cs, fmt="%g %%", fontsize=7)
    if w.size > 1 and w.min() > 0 and w.max() / w.min() > 20:
        ax.set_xscale("log")
    if k.size > 1 and k.min() > 0 and k.max() / k.min() > 20:
        ax.set_yscale("log")
    ax.set_xlabel("exposure W [ms]")
    ax.set_ylabel("true stiffness k [pN/nm]")
    ax.set_title(title or "naive equipartition error")
    return fig


__all__ = ["fig1a_universal_curve", "fig1b_histogram", "naive_error_map"]
