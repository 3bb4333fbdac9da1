"""The blocked power spectrum in pictures: the paper's Figs. 6 (spectrum with model fits) and
7 (data/model deviation and its law; appendix C), and the PSD residuals of two fits before and
after adding an effect."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ._common import (
    FIT_STYLE,
    MS,
    NM2,
    blocked_psd,
    fit_n_blocks,
    gamma_pdf,
    is_result,
    model_name,
    model_psd,
    new_axes,
    new_figure,
    normal_pdf,
    trap_params,
)


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
        ax.loglog(f, fac * model_psd(fit, recording, f, block_len=recording.n_frames // nb)
                  * NM2, **style)
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
    ratio = p / model_psd(fit, recording, f, block_len=recording.n_frames // nb)
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


def _binned(f, ratio, n_bins=20, var=None):
    """Log-binned means of `ratio` and the standard deviation of each bin mean (from the
    per-ordinate variances `var`, default 1)."""
    var = np.ones_like(ratio) if var is None else np.asarray(var, dtype=float)
    edges = np.unique(np.geomspace(f.min(), f.max() * (1 + 1e-12), n_bins + 1))
    idx = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, len(edges) - 2)
    fc, rm, sd = [], [], []
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            fc.append(float(np.exp(np.mean(np.log(f[sel])))))
            rm.append(float(np.mean(ratio[sel])))
            sd.append(float(np.sqrt(np.sum(var[sel])) / sel.sum()))
    return np.asarray(fc), np.asarray(rm), np.asarray(sd)


def _plain_log_ticks(axis, lims):
    """Log-axis ticks as plain numbers (0.01, 0.1, 1, 10 or 0.5, 1, 2), not powers of ten."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    if lims[1] / lims[0] < 100:  # under two decades: 1-2-5 ticks
        axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def _recordings(recording):
    if hasattr(recording, "positions") and hasattr(recording, "frame_interval"):
        return [recording]
    recs = list(recording)
    if not recs or not all(hasattr(r, "positions") for r in recs):
        raise ValueError("recording must be a Recording, a RecordingSet or a list of recordings")
    return recs


def _residuals(fit, recs, n_blocks, blocks_of):
    """Data/model ratios of `fit` for each recording: a list of ``(f, ratio, variance of
    each ratio = 1/n_blocks)``; the periodogram has `n_blocks` blocks (default: what
    `blocks_of` used)."""
    n_k = np.size(getattr(fit, "k_per_recording", [0.0]))
    out = []
    for i, rec in enumerate(recs):
        nb = fit_n_blocks(blocks_of, rec, n_blocks)
        nb = max(1, min(nb, rec.n_frames // 4))
        f, p, nb = blocked_psd(rec, nb)
        idx = i if len(recs) > 1 and n_k == len(recs) else 0
        model = model_psd(fit, rec, f, index=idx, block_len=rec.n_frames // nb)
        out.append((f, p / model, np.full(f.size, 1.0 / nb)))
    return out


def residuals_before_after(fit_a, fit_b, recording, *, n_blocks=None, labels=("before", "after"),
                           per_recording=False, fig=None):
    r"""Blocked-PSD residuals (data/model) of two fits of the same data, one row each: e.g.
    the ``naive`` model before and the ``standard`` model after adding motion blur, aliasing
    and tracking noise, or ``standard`` before and ``standard+drift`` after. Dots: each
    frequency; line: log-binned mean with its expected ``+- 2/sqrt(n_b n_bin)`` band; the
    title gives the goodness of fit. The ratio axis is logarithmic (a missing drift or line
    puts low-frequency ratios at 100x and more, a missing blur at 0.3x).

    - `fit_a`, `fit_b`: ``CalibrationResult`` objects (or mappings with ``k``, ``gamma``,
      ``tracking_var``, ``model``) for `recording`.
    - `recording`: a ``Recording``, or the ``RecordingSet`` (list of recordings) the fits
      were made on: recording i is compared with the fit's i-th stiffness.
    - `per_recording`: with several recordings, one column per recording; default: all
      recordings pooled in one panel per fit (their ratios together, one binned mean).
    - `n_blocks`: blocks of the periodogram (default: what `fit_b` used).
    - `fig`: an empty figure to draw into (default: a new pyplot figure).

    **Returns:** Figure with two rows of axes sharing the frequency axis.
    """
    recs = _recordings(recording)
    idx = list(range(len(recs)))
    groups = [[i] for i in idx] if per_recording and len(recs) > 1 else [idx]
    ncol = len(groups)
    fig, axes = new_figure(2, ncol, figsize=(6.4 if ncol == 1 else 3.6 * ncol, 5.6), fig=fig,
                           sharex=True, sharey=True, squeeze=False)
    lims = [math.inf, -math.inf]
    titles = []
    for row, (fit, tag) in enumerate(zip((fit_a, fit_b), labels, strict=False)):
        per_rec = _residuals(fit, recs, n_blocks, fit_b)
        for col, grp in enumerate(groups):
            parts = [per_rec[i] for i in grp]
            f, ratio, var = (np.concatenate([q[c] for q in parts]) for c in range(3))
            ax = axes[row, col]
            fb, rb, sd = _binned(f, ratio, var=var)
            ax.loglog(f, ratio, ".", color="0.6", ms=2.5, label="data / model")
            ax.fill_between(fb, np.maximum(1 - 2 * sd, 0.05), 1 + 2 * sd, color="C0",
                            alpha=0.25, label="expected +-2 sd of bin mean")
            ax.loglog(fb, rb, "-", color="C3", lw=1.6, label="log-binned mean")
            ax.axhline(1.0, color="k", lw=0.8)
            # every binned mean and every ratio above it; below, the lowest percent of
            # single ordinates (with few blocks they scatter down to ~1e-5)
            lims[0] = min(lims[0], 0.5 * float(rb.min()), float(np.quantile(ratio, 0.01)))
            lims[1] = max(lims[1], 2.0 * float(rb.max()), float(ratio.max()) * 1.3)
            gof = getattr(fit, "gof", None) or {}
            extra = ""
            if "statistic" in gof:
                extra = (f"; {gof.get('test', 'gof')}: {gof['statistic']:.4g}/{gof.get('dof')} "
                         f"(p = {gof.get('p_value', math.nan):.2g})")
            if ncol == 1:
                pooled = f" [{len(recs)} recordings pooled]" if len(recs) > 1 else ""
                ax.set_title(f"{tag}: model {model_name(fit)}{pooled}{extra}", fontsize=9)
            else:  # the fit's title once per row, the recording per panel
                ax.set_title(f"{tag}: recording {grp[0]}", fontsize=8)
                if col == 0:
                    titles.append(f"{tag}: model {model_name(fit)}{extra}")
            if col == 0:
                ax.set_ylabel("P_data / P_model (dimensionless)")
                if row == 0:
                    ax.legend(fontsize=7, loc="upper right")
    axes[0, 0].set_ylim(*lims)  # shared by all panels
    _plain_log_ticks(axes[0, 0].yaxis, lims)
    if titles:
        fig.suptitle("\n".join(titles), fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("frequency f [Hz]")
    return fig


__all__ = ["fig6_psd", "fig7_deviation", "residuals_before_after"]
