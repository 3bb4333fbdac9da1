"""Figures beyond the paper: posterior corner plot, residuals before/after adding an effect,
naive-calibration error maps and the ranking of missing effects."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ._common import (
    MS,
    blocked_psd,
    fit_n_blocks,
    lab,
    model_name,
    model_psd,
    new_axes,
    new_figure,
)


def _inner_ticks_locator():
    from matplotlib.ticker import MaxNLocator

    class InnerTicks(MaxNLocator):
        """2-3 round ticks away from the ends of the axis: a label centred on a tick near an
        end would run into the tick labels of the neighbouring panel."""

        def __init__(self):
            super().__init__(nbins=3)

        def __call__(self):
            assert self.axis is not None  # matplotlib calls a locator only once it is set on an axis
            lo, hi = sorted(self.axis.get_view_interval())
            m = 0.12 * (hi - lo)
            for nb in (3, 5):
                self.set_params(nbins=nb)
                ticks = [t for t in self.tick_values(lo, hi) if lo + m <= t <= hi - m]
                if len(ticks) >= 2:
                    break
            self.set_params(nbins=3)
            return ticks

    return InnerTicks()


def corner(samples, truths=None, *, bins=30, labels=None, quantiles=(0.16, 0.5, 0.84),
           fig=None):
    r"""Corner plot of posterior samples, in lab units.

    - `samples`: mapping ``name -> 1-D array`` of samples in SI units (names such as ``k``,
      ``gamma``, ``tracking_var``, ``c``, ``diffusion`` are converted to pN/nm, pN s/um,
      nm^2, pN/nm/W, um^2/s; other names are plotted as given).
    - `truths`: optional mapping ``name -> value`` [SI] drawn as lines.
    - `labels`: optional mapping ``name -> axis label`` (overrides the default
      ``"name [unit]"``).
    - `quantiles`: drawn as dashed lines on the marginal histograms.
    - `fig`: an empty figure to draw into (default: a new pyplot figure).

    Ticks: 2-3 per axis, none near the ends, so that neighbouring panels' tick labels do
    not overlap.

    **Returns:** Figure with an ``n x n`` grid of axes (upper triangle hidden).
    """
    if not isinstance(samples, Mapping) or not samples:
        raise ValueError("samples must be a non-empty mapping name -> 1-D array of samples")
    names = list(samples)
    data = []
    for nme in names:
        arr = np.asarray(samples[nme], dtype=float).ravel()
        if arr.size < 2:
            raise ValueError(f"samples[{nme!r}] needs at least 2 samples; got {arr.size}")
        fac, _, _ = lab(nme)
        data.append(arr * fac)
    n = len(names)
    fig, axes = new_figure(n, n, figsize=(2.3 * n + 0.6, 2.3 * n + 0.4), fig=fig)
    axes = np.asarray(axes).reshape(n, n)

    def axis_label(nme):
        if labels and nme in labels:
            return labels[nme]
        fac, unit, pretty = lab(nme)
        return f"{pretty} [{unit}]" if unit != "SI" else f"{nme} (SI)"

    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            if j > i:
                ax.set_axis_off()
                continue
            if i == j:
                ax.hist(data[i], bins=bins, color="0.6", histtype="stepfilled", density=True)
                for q in np.quantile(data[i], quantiles):
                    ax.axvline(q, color="k", ls="--", lw=0.8)
                lo, mid, hi = np.quantile(data[i], (0.16, 0.5, 0.84))
                ax.set_title(f"{lab(names[i])[2]} = {mid:.4g} (+{hi - mid:.2g}/-{mid - lo:.2g})",
                             fontsize=8)
                ax.set_yticks([])
                if truths and names[i] in truths:
                    ax.axvline(float(truths[names[i]]) * lab(names[i])[0], color="C3", lw=1.2)
            else:
                ax.hist2d(data[j], data[i], bins=bins, cmap="Greys")
                if truths and names[j] in truths and names[i] in truths:
                    tx = float(truths[names[j]]) * lab(names[j])[0]
                    ty = float(truths[names[i]]) * lab(names[i])[0]
                    ax.axvline(tx, color="C3", lw=1.0)
                    ax.axhline(ty, color="C3", lw=1.0)
                    ax.plot([tx], [ty], "s", color="C3", ms=4)
            ax.xaxis.set_major_locator(_inner_ticks_locator())
            ax.tick_params(axis="x", labelsize=8)
            if i != j:
                ax.yaxis.set_major_locator(_inner_ticks_locator())
                ax.tick_params(axis="y", labelsize=8)
            if i == n - 1:
                ax.set_xlabel(axis_label(names[j]))
            else:
                ax.tick_params(labelbottom=False)
            if j == 0 and i > 0:
                ax.set_ylabel(axis_label(names[i]))
            elif i != j:
                ax.tick_params(labelleft=False)
    if n == 1:
        axes[0, 0].set_xlabel(axis_label(names[0]))
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
        out.append((f, p / model_psd(fit, rec, f, index=idx), np.full(f.size, 1.0 / nb)))
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


_SIG_COLOR, _NOT_SIG_COLOR, _NO_VERDICT_COLOR, _IMPLAUSIBLE_COLOR = "C3", "0.6", "C0", "0.85"
AIC_LABEL = ("AIC improvement = AIC_old - AIC_new = AIC(model) - AIC(model + effect)\n"
             "(> 0: adding the effect helps; dimensionless)")


def _ranking_rows(ranking):
    """Rows ``{effect, delta_aic, p_value, significant, plausible}`` and the Diagnosis (or
    None) from a Diagnosis, a sequence of Candidates or a sequence of mappings."""
    diag = ranking if hasattr(ranking, "ranking") and hasattr(ranking, "adequate") else None
    items = diag.ranking if diag is not None else ranking
    rows = []
    for r in items:
        if isinstance(r, Mapping):
            r = dict(r)
            if "effect" not in r or "delta_aic" not in r:
                raise ValueError(f"each ranking entry needs 'effect' and 'delta_aic'; got {r!r}")
        elif hasattr(r, "effect") and hasattr(r, "delta_aic"):
            r = {k: getattr(r, k) for k in ("effect", "delta_aic", "p_value", "significant",
                                               "plausible", "evidence") if hasattr(r, k)}
        else:
            raise ValueError("ranking must be a Diagnosis, a sequence of Candidates or of "
                             f"mappings with 'effect' and 'delta_aic'; got an item {r!r}")
        dA = r["delta_aic"]
        rows.append({"effect": str(r["effect"]),
                     "delta_aic": None if dA is None else float(dA),
                     "p_value": None if r.get("p_value") is None else float(r["p_value"]),
                     "significant": None if r.get("significant") is None
                     else bool(r["significant"]),
                     "plausible": bool(r.get("plausible", True))})
    return rows, diag


def _ranking_key(item):
    i, r = item
    sig = r["significant"] is True
    d = r["delta_aic"]
    if d is None:  # not comparable by AIC: a significant one leads (as in diagnose), else last
        d = math.inf if sig else -math.inf
    return (not sig, not r["plausible"], -d, i)


def _verdict_title(diag, rows):
    if diag is None:
        if any(r["significant"] is not None for r in rows):
            return "missing-effect ranking"
        return ("missing-effect ranking (no verdicts given: pass the Diagnosis for "
                "significance and adequacy)")
    g = diag.gof or {}
    p = g.get("p_value", math.nan)
    head = (f"model {diag.model}: " + ("adequate" if diag.adequate else "NOT adequate")
            + f" (gof p = {p:.3g}; significant: p < {diag.threshold:.3g}, Bonferroni)")
    best = getattr(diag, "best", None)
    if not diag.adequate:
        head += (f"\nmissing effect: {best.effect}" if best is not None else
                 "\nno candidate effect explains the misfit")
    return head


def diagnose_ranking(ranking, *, ax=None, thresholds=None):
    r"""Bar chart of the candidate missing effects of a :func:`blurtrap.diagnose` run.

    The picture states the Diagnosis's own verdicts, computed nowhere else: a bar is red
    when ``diagnose`` found the effect significant (likelihood-ratio p below the Bonferroni
    threshold, AIC improved, physically plausible), grey when not; a physically implausible
    candidate is hatched, labelled ``IMPLAUSIBLE`` and drawn after the plausible ones,
    whatever its AIC; a candidate that is not part of the likelihood (``timing_jitter``:
    ``delta_aic`` is None) is drawn as a hatched band labelled "not comparable by AIC" with
    its p-value. The title gives the adequacy verdict, the goodness-of-fit p-value and the
    threshold, as :meth:`Diagnosis.summary` words them.

    - `ranking`: the :class:`~blurtrap.diagnostics.Diagnosis` (preferred), its ``ranking``
      (Candidates), or a list of dicts (``Candidate.to_dict()``) with keys ``effect`` and
      ``delta_aic`` (``AIC(model) - AIC(model + effect)``, > 0: the effect improves the
      fit; None: not comparable by AIC) and optionally ``p_value``, ``significant`` and
      ``plausible``. Dicts without ``significant`` are drawn blue: no verdict.
    - `thresholds`: optional AIC-improvement levels drawn as dotted guides (they do not
      change the colours).
    - `ax`: draw into an existing axes.

    **Returns:** Figure with one axes (one bar per effect, the Diagnosis's best at the top).
    An empty ranking gives a figure that says that nothing is missing.
    """
    from matplotlib.patches import Patch, Rectangle
    from matplotlib.transforms import blended_transform_factory

    rows, diag = _ranking_rows(ranking)
    rows = [r for _, r in sorted(enumerate(rows), key=_ranking_key)]
    fig, ax = new_axes(figsize=(9.0, 0.45 * max(len(rows), 2) + 1.7), ax=ax)
    ax.set_xlabel(AIC_LABEL, fontsize=8)
    ax.set_title(_verdict_title(diag, rows), fontsize=9)
    if not rows:
        msg = "no candidate effect improves the fit: nothing is missing"
        if diag is not None and not diag.adequate:
            msg = "no candidate effects were tried, and the model is NOT adequate"
        ax.text(0.5, 0.5, msg, ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
        return fig
    n = len(rows)
    ypos = np.arange(n)[::-1]
    band = blended_transform_factory(ax.transAxes, ax.transData)
    kinds = set()
    for y, r in zip(ypos, rows, strict=True):
        sig, v, p = r["significant"], r["delta_aic"], r["p_value"]
        color = (_NO_VERDICT_COLOR if sig is None else _SIG_COLOR if sig else _NOT_SIG_COLOR)
        ptxt = "" if p is None else f"p = {p:.2g}"
        if not r["plausible"]:
            kinds.add("implausible")
            color = _IMPLAUSIBLE_COLOR
        else:
            kinds.add({None: "none", True: "sig", False: "not"}[sig])
        if v is None:
            kinds.add("n/a")
            ax.add_patch(Rectangle((0.0, y - 0.4), 1.0, 0.8, transform=band, facecolor="none",
                                   edgecolor=color if sig else "0.45", hatch="//", lw=1.0,
                                   gid=f"not comparable: {r['effect']}"))
            ax.text(0.5, y, f"not comparable by AIC{', ' + ptxt if ptxt else ''}"
                    + (" (significant)" if sig else ""),
                    transform=band, ha="center", va="center", fontsize=8,
                    bbox=dict(facecolor="white", edgecolor="none", pad=1.0))
            continue
        ax.barh([y], [v], color=color, hatch=None if r["plausible"] else "xx",
                edgecolor="0.3" if not r["plausible"] else color, gid=f"bar: {r['effect']}")
        note = f" {v:.3g}" + (f", {ptxt}" if ptxt else "")
        if not r["plausible"]:
            note += ", IMPLAUSIBLE"
        ax.text(max(v, 0.0), y, note, va="center", ha="left", fontsize=8)
    labels = [r["effect"] + ("\n(IMPLAUSIBLE)" if not r["plausible"] else "") for r in rows]
    ax.set_yticks(ypos, labels)
    ax.set_ylim(-0.6, n - 0.4)
    ax.axvline(0.0, color="k", lw=0.8)
    for t in thresholds or ():
        ax.axvline(float(t), color="k", ls=":", lw=0.8)
    vals = [r["delta_aic"] for r in rows if r["delta_aic"] is not None]
    lo, hi = (min(vals + [0.0]), max(vals + [0.0])) if vals else (-1.0, 1.0)
    span = max(hi - lo, 1.0)
    # room for the value labels, written right of each bar's end (of 0 for a negative bar)
    ax.set_xlim(lo - 0.05 * span, hi + 0.4 * span)
    legend = {
        "sig": Patch(facecolor=_SIG_COLOR, label="significant (diagnose's verdict)"),
        "not": Patch(facecolor=_NOT_SIG_COLOR, label="not significant"),
        "none": Patch(facecolor=_NO_VERDICT_COLOR, label="no verdict given"),
        "implausible": Patch(facecolor=_IMPLAUSIBLE_COLOR, hatch="xx", edgecolor="0.3",
                             label="physically implausible: never significant"),
        "n/a": Patch(facecolor="none", hatch="//", edgecolor="0.45",
                     label="not comparable by AIC (outside the likelihood)"),
    }
    ax.legend(handles=[legend[k] for k in ("sig", "not", "none", "implausible", "n/a")
                       if k in kinds], fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              borderaxespad=0.0)
    return fig


__all__ = ["corner", "residuals_before_after", "naive_error_map", "diagnose_ranking"]
