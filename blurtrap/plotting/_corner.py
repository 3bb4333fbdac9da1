"""Corner plot of posterior samples in lab units."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ._common import lab, new_figure


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


__all__ = ["corner"]
