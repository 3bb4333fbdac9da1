"""The figures of ``blurtrap calibrate/diagnose --report``: per recording, the blocked spectrum
with the fit over its data/model deviation, and the frame histogram against the fitted
normal; for a diagnosis, the ranking of candidate effects and the PSD residuals before and
after adding the best one. Every figure is drawn by :mod:`blurtrap.plotting`; this module
picks the inputs (one recording's view of a fit, positions in metres) and the captions."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

#: recordings drawn one by one (spectrum, histogram); a larger set gets the first ones
MAX_RECORDING_FIGURES = 12


def label(rec, i: int) -> str:
    """A recording's name for titles and tables (its name, else ``recording i``)."""
    return f"recording {i} ({rec.name})" if rec.name else f"recording {i}"


def in_metres(rec, fit):
    """The recording in metres: a volts trace times the fit's displacement sensitivity Rd
    [m/V] (the fit's k, gamma and eps^2 are in SI), else unchanged."""
    if rec.position_unit != "V":
        return rec
    rd = fit.params.get("displacement_sensitivity", math.nan)
    if not (math.isfinite(rd) and rd > 0):
        raise ValueError("a volts recording needs the fit's displacement_sensitivity [m/V] to "
                         f"be drawn in nm; got {rd!r}")
    meta = dict(rec.metadata)
    meta["position_unit"] = "m"
    return rec.replace(positions=np.asarray(rec.positions) * rd, metadata=meta,
                       position_unit="m")


def fit_for(fit, i: int, n_recordings: int):
    """The fit as seen by recording ``i``: its own stiffness first (the plotting functions
    take the first recording's k)."""
    ks = np.asarray(fit.k_per_recording, dtype=float)
    if ks.size <= 1 or n_recordings <= 1:
        return fit
    es = np.asarray(fit.k_per_recording_err, dtype=float)
    j = i if ks.size == n_recordings else 0
    return dataclasses.replace(fit, k_per_recording=ks[j:j + 1], k_per_recording_err=es[j:j + 1])


def has_trap_model(fit) -> bool:
    """Whether the fit gives a model spectrum (finite k and gamma)."""
    return math.isfinite(fit.gamma) and fit.gamma > 0 and math.isfinite(fit.k) and fit.k > 0


def spectrum_figure(rec, fit, title: str):
    """The blocked spectrum with the fitted model (top) and data/model with its
    ``1 +- 1/sqrt(n_b)`` band and histogram against the Gamma(n_b) law (bottom); the data
    alone when the fit has no model spectrum."""
    import matplotlib.pyplot as plt

    from . import plotting as bp

    model = has_trap_model(fit)
    fig = plt.figure(figsize=(9.0, 8.4 if model else 4.6), layout="constrained")
    subs: Any = fig.subfigures(2, 1, height_ratios=(1.1, 1.0)) if model else (fig, None)
    top, bottom = subs
    ax = top.subplots()
    bp.fig6_psd(rec, fit if model else None, n_blocks=n_blocks_for(fit, [rec]), ax=ax)
    ax.set_title(f"power spectrum, {title}: fs = {rec.sampling_rate:.5g} Hz, "
                 f"W = {float(rec.exposure) * 1e3:.3g} ms", fontsize=9)
    if bottom is not None:
        bp.fig7_deviation(rec, fit, n_blocks=n_blocks_for(fit, [rec]), fig=bottom)
        bottom.axes[0].set_title(f"data / model ({fit.model}), expected band "
                                 "1 +- 1/sqrt(n_b)", fontsize=9)
    return fig


#: blocks drawn are at least this many relaxation times long: the figures divide by the
#: model P_d(f), which leaves out the finite block's leakage (the fits include it); that
#: leakage raises the ordinates by ~tau/T_block (measured 10 % at 11 tau, 0.6 % at 170 tau)
BLOCK_TAU = 100.0


def n_blocks_for(fit, recs) -> int:
    """Blocks of the drawn periodograms: the fit's own for ``--method psd``, else up to 128
    blocks of >= 64 frames and >= BLOCK_TAU relaxation times (a Whittle fit uses the raw
    periodogram, whose single ordinates scatter by 100 % and hide the shape), never fewer
    than 4 frames a block."""
    n = min(r.n_frames for r in recs)
    nb = (fit.extras or {}).get("n_blocks") if fit.method == "psd" else None
    if nb is None:
        block = 64
        if has_trap_model(fit):
            tau = fit.gamma / float(np.min(fit.k_per_recording))
            dt = min(float(r.frame_interval) for r in recs)
            block = max(block, math.ceil(BLOCK_TAU * tau / dt))
        nb = max(1, min(128, n // block))
    return max(1, min(int(nb), n // 4))


def histogram_figure(rec, fit, title: str):
    """Frames against the fitted normal (``kT/k S(alpha) + eps^2`` with blur, ``kT/k + eps^2``
    without)."""
    from . import plotting as bp

    fig = bp.fig1b_histogram(rec, fit)
    fig.axes[0].set_title(f"frame histogram, {title}: fitted model {fit.model}", fontsize=9)
    return fig


def model_has_blur(fit) -> bool:
    """Whether the fitted model averages over the exposure (its frame variance has S)."""
    from .inference import get_model

    try:
        return bool(get_model(fit.model).blur)
    except ValueError:  # a model name the registry does not know: assume the camera default
        return True


def histogram_caption(rec, fit) -> str:
    which = ("solid: the fitted model's frame variance kT/k S(alpha) + eps^2 (motion blur); "
             "dotted: kT/k + eps^2 without blur" if model_has_blur(fit) else
             "dotted: the fitted model's frame variance kT/k + eps^2 (this model has no motion "
             "blur); solid: what blur over W would give")
    return f"Frame histogram (mean removed) against the normal of the fit; {which}."


def ranking_figure(diagnosis):
    from . import plotting as bp

    return bp.diagnose_ranking(diagnosis)


def before_after_figure(base, after, recs, effect: str):
    from . import plotting as bp

    fig = bp.residuals_before_after(base, after, recs, n_blocks=n_blocks_for(after, recs),
                                    labels=("before", f"after adding {effect}"))
    fig.set_size_inches(9.0, 6.0)  # room for the titles (model, recordings, gof)
    return fig


class Figures:
    """Saves figures into ``outdir``; ``entries`` lists (file, caption), ``failed`` the
    figures that raised (name: error) and ``skipped`` those that do not apply (name: why)."""

    def __init__(self, outdir):
        self.outdir = outdir
        self.entries: list[tuple[str, str]] = []
        self.failed: list[str] = []
        self.skipped: list[str] = []

    def attempt(self, name: str, make, caption: str) -> None:
        from .plotting import save

        try:
            fig = make()
        except Exception as exc:  # the report says which figure failed and why
            self.failed.append(f"{name}.png: {type(exc).__name__}: {exc}")
            return
        save(fig, self.outdir / f"{name}.png", dpi=100)
        self.entries.append((f"{name}.png", caption))

    @property
    def files(self) -> list[str]:
        return [f for f, _ in self.entries]


def recording_figures(figs: Figures, recs, fit) -> None:
    """Spectrum and histogram of each recording (the first MAX_RECORDING_FIGURES)."""
    n = len(recs)
    for i, raw in enumerate(recs[:MAX_RECORDING_FIGURES]):
        view = fit_for(fit, i, n)
        title = label(raw, i)
        try:
            rec = in_metres(raw, view)
        except ValueError as exc:
            figs.skipped.append(f"{title}: {exc}")
            continue
        spec = ("Blocked power spectrum (one-sided, nm^2/Hz; blocks of >= "
                f"{BLOCK_TAU:g} relaxation times unless the fit used its own) with the fitted "
                "model, and the data/model ratio with its expected 1 +- 1/sqrt(n_b) band and "
                "its histogram against the Gamma(n_b) law (Berg-Sorensen & Flyvbjerg 2004)")
        if not has_trap_model(view):
            spec = (f"Blocked power spectrum (data only: method {fit.method} fits no friction, "
                    "so there is no model spectrum)")
        figs.attempt(f"spectrum_{i}", lambda r=rec, v=view, t=title: spectrum_figure(r, v, t),
                     f"{title}: {spec}.")
        if has_trap_model(view):
            figs.attempt(f"histogram_{i}",
                         lambda r=rec, v=view, t=title: histogram_figure(r, v, t),
                         f"{title}: {histogram_caption(rec, view)}")
        else:
            figs.skipped.append(f"histogram_{i}.png: method {fit.method} fits no friction, so "
                                "the blurred frame variance kT/k S(alpha) is unknown")
    if n > MAX_RECORDING_FIGURES:
        figs.skipped.append(f"recordings {MAX_RECORDING_FIGURES}..{n - 1}: only the first "
                            f"{MAX_RECORDING_FIGURES} recordings are drawn one by one")
