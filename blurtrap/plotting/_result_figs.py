"""A calibration's own figures (``CalibrationResult.plot`` and ``.plot_residuals``): the
blocked power spectrum of the recordings it fitted with the fitted model (and, where the model
has blur or aliasing, the naive Lorentzian with the same k and gamma), and the data/model ratio
with the band an average of n_b periodograms falls in (Gamma(n_b), mean 1; DESIGN item 9)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._common import NM2, blocked_psd, kT, new_axes
from ._psd_figs import _plain_log_ticks

#: default block count of the figures for fits that did not use blocks (likelihood, variance,
#: Allan): at most 32 blocks of at least 512 frames, so that the lowest frequencies (where drift
#: shows) stay in view; the bands of :func:`fit_residuals` follow the count
MAX_BLOCKS = 32
MIN_BLOCK_FRAMES = 512


@dataclasses.dataclass(frozen=True)
class Spectrum:
    """One fitted recording's blocked spectrum: ``f`` [Hz], two-sided ``data`` and ``model``
    [m^2/Hz] (the model is what the fit compared the data with), ``naive`` (the Lorentzian
    with the same k and gamma), ``n_blocks`` and the recording's index."""

    index: int
    f: np.ndarray
    data: np.ndarray
    model: np.ndarray
    naive: np.ndarray
    n_blocks: int


def gamma_ratio_quantile(q, n_blocks: int) -> np.ndarray:
    """Quantiles `q` of Gamma(n_b, scale 1/n_b) (mean 1), the law of an average of n_b
    independent periodogram blocks divided by its expectation. Exact for integer n_b: the CDF
    is ``1 - exp(-y) sum_{j<n_b} y^j / j!`` at ``y = n_b r``, inverted by bisection."""
    n = int(n_blocks)
    if n < 1:
        raise ValueError(f"n_blocks must be an integer >= 1; got n_blocks = {n_blocks!r}")
    q = np.atleast_1d(np.asarray(q, dtype=float))
    if not np.all((q > 0) & (q < 1)):
        raise ValueError(f"quantile levels must lie in (0, 1); got {q.tolist()}")
    j = np.arange(n, dtype=float)
    log_fact = np.array([math.lgamma(i + 1.0) for i in j])

    def cdf(r):
        y = n * r[:, None]
        return 1.0 - np.exp(-y + j * np.log(y) - log_fact).sum(axis=1)

    lo, hi = np.zeros_like(q), np.full_like(q, 60.0 / math.sqrt(n) + 10.0)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        below = cdf(mid) < q
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def _inputs(result):
    inputs = getattr(result, "inputs", None)
    if inputs is None:
        raise ValueError(
            "this CalibrationResult holds no recordings (a result of fit_psd, rebuilt from "
            "JSON or made by hand): its figures need the trace it was fitted to. Plot a result "
            "returned by "
            "blurtrap.calibrate, or pass the recording yourself: "
            "blurtrap.plotting.fig6_psd(recording, result)")
    g = float(result.gamma)
    if not (math.isfinite(g) and g > 0):
        raise ValueError(
            f"this result (method {result.method!r}) has no friction gamma (gamma = {g!r}): "
            "without it there is no model spectrum to draw; calibrate with "
            "method='likelihood' or 'psd'")
    return inputs


def _block_count(result, recs, n_blocks):
    n_min = min(r.n_frames for r in recs)
    if n_blocks is not None:
        nb = int(n_blocks)
        if nb != n_blocks or nb < 1 or n_min // nb < 4:
            raise ValueError(f"n_blocks must be an integer >= 1 leaving at least 4 frames "
                             f"per block of the shortest recording ({n_min} frames); got "
                             f"n_blocks = {n_blocks!r}")
        return nb
    extras = getattr(result, "extras", None) or {}
    if result.method == "psd" and int(extras.get("n_blocks", 0)) >= 1:
        return int(extras["n_blocks"])
    return max(1, min(MAX_BLOCKS, n_min // MIN_BLOCK_FRAMES))


def _model_psd(result, mdl, rec, f, index, block_len):
    """Two-sided PSD [m^2/Hz] the fit compared with recording `index`'s blocked periodogram:
    the exact expected periodogram of a block of `block_len` frames for the closed-form aliased
    models (as the spectral fits use), P_d(f) otherwise."""
    import jax.numpy as jnp

    from .._config import x64_context

    ks = np.asarray(result.k_per_recording, dtype=float)
    k = float(ks[min(index, ks.size - 1)])
    params = result.params
    extras = {p.name: params[p.name] for p in mdl.extra_params if p.name in params}
    with x64_context(True):
        one = lambda v: jnp.asarray([float(v)])  # noqa: E731
        bl = one(block_len) if (mdl.alias and mdl.closed_form) else None
        p = mdl.psd(jnp.asarray(np.asarray(f, dtype=float)[None, :]), one(k),
                    one(result.gamma), jnp.asarray(float(result.tracking_var)),
                    one(rec.frame_interval), one(rec.exposure), one(rec.temperature),
                    extras={n: jnp.asarray(v) for n, v in extras.items()}, block_len=bl)
        return np.asarray(p, dtype=float)[0], k


def spectra(result, n_blocks=None) -> list[Spectrum]:
    """The blocked spectrum, fitted model and naive Lorentzian of each recording a result was
    fitted to (SI). Positions in volts are scaled to metres with the fitted displacement
    sensitivity Rd."""
    inputs = _inputs(result)
    recs = inputs.recordings
    nb = _block_count(result, recs, n_blocks)
    params = result.params
    scale = params.get("displacement_sensitivity", 1.0) ** 2  # V^2/Hz -> m^2/Hz
    out = []
    for i, rec in enumerate(recs):
        f, p, nb_i = blocked_psd(rec, nb)
        model, k = _model_psd(result, inputs.model, rec, f, i, rec.n_frames // nb_i)
        fc = k / (2.0 * math.pi * float(result.gamma))
        diffusion = kT(rec.temperature) / float(result.gamma)
        naive = diffusion / (2.0 * math.pi**2 * (fc**2 + f**2))  # two-sided Lorentzian
        out.append(Spectrum(i, f, p * scale, model, naive, nb_i))
    return out


def _shade_unfitted(ax, result, f_lo, f_hi):
    inputs = result.inputs
    spans = []
    if inputs.f_range is not None:
        a, b = inputs.f_range
        spans += [(f_lo, a), (b, f_hi)]
    spans += [tuple(r) for r in inputs.excluded]
    first = True
    for a, b in spans:
        if b > a and b > f_lo and a < f_hi:
            ax.axvspan(max(a, f_lo), min(b, f_hi), color="0.85", zorder=0,
                       label="not fitted" if first else None)
            first = False


def _title(result) -> str:
    model = getattr(result.inputs.model, "name", result.model)
    return (f"{result.method} fit, model {model}\nk = {result.k * 1e3:.4g} pN/nm, "
            f"gamma = {result.gamma * 1e6:.4g} pN s/um, f_c = {result.corner_frequency:.4g} Hz")


def fit_spectrum(result, *, n_blocks=None, ax=None):
    """Blocked power spectrum (one-sided, ``2 P(f)`` for f > 0, nm^2/Hz against Hz, log-log) of
    the recordings `result` was fitted to, with the fitted model (what the fit compared the
    data with) and, when that model has blur or aliasing, the naive Lorentzian
    ``D / (pi^2 (f_c^2 + f^2))`` with the same k and gamma (no blur, aliasing or noise).
    Bands the fit left out are shaded. The recordings are the ones the fit used (after
    ``calibrate`` subtracted any lines it found; its notes name them).

    - `result`: a ``CalibrationResult`` from :func:`blurtrap.calibrate` (it keeps its
      recordings and model; a result rebuilt from JSON does not: ``ValueError``).
    - `n_blocks`: blocks of the periodogram (default: the fit's for ``method="psd"``, else
      up to 32 blocks of at least 512 frames).
    - `ax`: axes to draw into (default: a new pyplot figure).

    **Returns:** the Figure.
    """
    specs = spectra(result, n_blocks)
    mdl = result.inputs.model
    show_naive = bool(mdl.blur or mdl.alias)
    fig, ax = new_axes(figsize=(6.4, 4.6), ax=ax)
    one = len(specs) == 1
    for s in specs:
        rec = result.inputs.recordings[s.index]
        c = f"C{s.index % 10}"
        ax.loglog(s.f, 2.0 * s.data * NM2, ".", ms=2.5, color="0.45" if one else c,
                  label=(f"data{'' if one else f' {s.index}'}: {s.n_blocks} blocks, "
                         f"W = {float(rec.exposure) * 1e3:.3g} ms, "
                         f"dt = {float(rec.frame_interval) * 1e3:.3g} ms"))
        ax.loglog(s.f, 2.0 * s.model * NM2, "-", lw=1.8, color="C3" if one else c,
                  label=f"fit ({getattr(mdl, 'name', result.model)})" if s.index == 0 else None)
        if show_naive:
            ax.loglog(s.f, 2.0 * s.naive * NM2, "--", lw=1.3, color="C0" if one else c,
                      label=("naive Lorentzian, same k and gamma" if s.index == 0 else None))
    f_all = np.concatenate([s.f for s in specs])
    _shade_unfitted(ax, result, float(f_all.min()), float(f_all.max()))
    _plain_log_ticks(ax.xaxis, (float(f_all.min()), float(f_all.max())))
    ax.set_xlabel("frequency f [Hz]")
    ax.set_ylabel("one-sided PSD [nm$^2$/Hz]")
    ax.set_title(_title(result), fontsize=9)
    ax.legend(fontsize=7, loc="lower left", framealpha=0.85)
    return fig


def fit_residuals(result, *, n_blocks=None, ax=None):
    """Data/model ratio of the blocked spectrum of the recordings `result` was fitted to,
    against frequency (log axes), with the central 68 % and 95 % bands of a ratio of an
    average of n_b periodogram blocks to its expectation (Gamma(n_b) with mean 1, DESIGN item
    9): a model that fits leaves about 5 % of the points outside the outer band, scattered
    without a trend. Arguments as :func:`fit_spectrum`.

    **Returns:** the Figure.
    """
    specs = spectra(result, n_blocks)
    fig, ax = new_axes(figsize=(6.4, 4.0), ax=ax)
    nbs = sorted({s.n_blocks for s in specs})
    one = len(specs) == 1
    ratios = []
    for s in specs:
        r = s.data / s.model
        ratios.append(r)
        lo95, hi95 = gamma_ratio_quantile([0.025, 0.975], s.n_blocks)
        out = float(np.mean((r < lo95) | (r > hi95))) * 100
        ax.loglog(s.f, r, ".", ms=2.5, color="0.35" if one else f"C{s.index % 10}",
                  label=("data / model" if one else f"recording {s.index}")
                  + f": {out:.1f} % outside the 95 % band")
    f_all = np.concatenate([s.f for s in specs])
    lo, hi = float(f_all.min()), float(f_all.max())
    for nb in nbs:
        q = gamma_ratio_quantile([0.025, 0.16, 0.84, 0.975], nb)
        tag = f" (n_b = {nb})"
        ax.fill_between([lo, hi], q[0], q[3], color="C0", alpha=0.18, lw=0,
                        label=f"95 % band{tag}")
        ax.hlines([q[1], q[2]], lo, hi, colors="C0", linestyles="--", lw=1.0,
                  label=f"68 % band{tag}")
    ax.axhline(1.0, color="k", lw=0.8)
    _shade_unfitted(ax, result, lo, hi)
    r_all = np.concatenate(ratios)
    q_lo = gamma_ratio_quantile([0.025], nbs[0])[0]
    lims = (min(0.8 * q_lo, float(np.quantile(r_all, 0.005))),
            max(1.25 * float(gamma_ratio_quantile([0.975], nbs[0])[0]), 1.1 * float(r_all.max())))
    if lims[1] / lims[0] < 4.0:  # a narrow band: linear ratio axis (as pylake draws it)
        ax.set_yscale("linear")
    else:  # a missing effect puts ratios at 0.1x or 100x: log axis with plain numbers
        _plain_log_ticks(ax.yaxis, lims)
    ax.set_ylim(*lims)
    _plain_log_ticks(ax.xaxis, (lo, hi))
    ax.set_xlabel("frequency f [Hz]")
    ax.set_ylabel("P_data / P_model (dimensionless)")
    ax.set_title(_title(result), fontsize=9)
    ax.legend(fontsize=7, loc="best", framealpha=0.85)
    return fig


__all__ = ["fit_residuals", "fit_spectrum", "gamma_ratio_quantile", "spectra"]
