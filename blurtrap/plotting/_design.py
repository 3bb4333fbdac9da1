"""The figure of an experiment design (:func:`blurtrap.design`): predicted SE against the
exposure and the frame interval, with the candidates compared by the design marked."""

from __future__ import annotations

import numpy as np

from .._config import float64_scope
from ._common import MS

_MARKERS = ("*", "o", "s", "^", "D", "v", "P", "X")
#: SEs above this [%] are not drawn: such a design does not identify the parameter (the
#: information matrix is near singular and its inverse is numerical noise)
_SE_CAP = 1e3


@float64_scope
def _single_se(result, exposures, intervals):
    """Relative SE (fraction; worst over the k range) of k and gamma for one recording at
    each (exposure, frame interval) pair, with the settings of the design (same total time,
    or same frames per recording, and the same noise model)."""
    s = result.settings
    eps_ref2 = float(s["tracking_std_m"]) ** 2
    total = s.get("total_time_s")
    budget = float(total if total is not None else s["n_frames"])
    out = _grid_se()(np.asarray(exposures, dtype=float), np.asarray(intervals, dtype=float),
                   np.asarray(result.k, dtype=float), float(s["gamma_N_s_per_m"]),
                   float(s["temperature_K"]), eps_ref2, float(s["reference_exposure_s"]),
                   budget, _friction_se(s), photon=bool(s["photon_limited"]),
                   by_time=total is not None, noise=eps_ref2 > 0)
    out = np.array(out, dtype=float)
    out[~(out * 100 <= _SE_CAP)] = np.nan
    if _friction_se(s) == 0.0:
        out[:, 1] = np.nan  # gamma known exactly: no curve for it
    return out


def _friction_se(settings):
    """The design's friction prior (< 0: friction fitted), as ``design.relative_se`` takes it."""
    known = settings.get("friction_error")
    return -1.0 if known is None else float(known)


_GRID_SE: list = []  # the jitted grid evaluation, made on first use (jax imported lazily)


def _grid_se():
    """``f(exposures, intervals, ks, gamma, T, eps_ref^2, W_ref, budget, friction_se, *,
    photon, by_time, noise)`` -> (n, 2) relative SEs: one compiled, vmapped program reused by every call."""
    if not _GRID_SE:
        import jax
        import jax.numpy as jnp

        from ..design import relative_se

        def grid(exposures, intervals, ks, gamma, temperature, eps_ref2, w_ref, budget,
                 friction_se, *, photon, by_time, noise):
            def one(w, dt):
                n = budget / dt if by_time else budget
                se = relative_se([(dt, w, n)], ks, gamma, temperature, eps_ref2, w_ref, photon,
                                 noise, friction_se)
                return jnp.max(se[:, :2], axis=0)

            return jax.vmap(one)(exposures, intervals)

        _GRID_SE.append(jax.jit(grid, static_argnames=("photon", "by_time", "noise")))
    return _GRID_SE[0]


def _target_se(cand, target):
    """The SE of the design's target for a candidate (worst over the k range): from its
    predicted SEs for k / gamma / both, else its objective (determinant, force sensitivity;
    inf where the design does not identify what it must)."""
    se = cand.predicted_se
    if target == "k":
        return float(np.max(se["k"]))
    if target == "gamma":
        return float(np.max(se["gamma"]))
    if target == "both":
        return float(np.max(np.sqrt(np.asarray(se["k"]) * np.asarray(se["gamma"]))))
    return float(cand.objective)


def design_se(result, ax=None):
    """Predicted relative SE [%] of k and gamma for one recording against the exposure W (at
    the recommended design's frame interval) and against the frame interval dt (W = dt minus
    the dead time), both under the design's constraints (total time or frames, tracking
    noise, photon-limited noise), worst case over the stiffness range. Every candidate the
    design compared is one marker on the exposure panel, at the geometric mean of its
    exposures (a series also gets a line spanning its exposures), at the SE of the design's
    target; the recommended one is the star.

    - `result`: a :class:`blurtrap.design.DesignResult`.
    - `ax`: two axes (exposure panel, frame-interval panel), or one axes for the exposure
      panel only; by default a new two-panel figure made with pyplot.

    **Returns:** the ``matplotlib.figure.Figure``.
    """
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
        ax_w, ax_dt = axes
    elif np.ndim(ax) == 0:
        ax_w, ax_dt = ax, None
        fig = ax.figure
    else:
        ax_w, ax_dt = ax
        fig = ax_w.figure
    s = result.settings
    dead = float(s["dead_time_s"])
    w_min = float(s["min_exposure_s"])
    dt_min = 1.0 / float(s["max_fps_Hz"])
    dt_best = float(result.best.recordings[0][0])

    ws = np.geomspace(w_min, dt_best - dead, 60)
    se_w = 100 * _single_se(result, ws, np.full_like(ws, dt_best))
    ax_w.plot(ws * MS, se_w[:, 0], "C0-", label="k, one recording")
    ax_w.plot(ws * MS, se_w[:, 1], "C1--", label="gamma, one recording")
    for i, c in enumerate(result.candidates):
        exps = np.array([r[1] for r in c.recordings])
        x = float(np.exp(np.mean(np.log(exps)))) * MS
        y = 100 * _target_se(c, result.target)
        best = c is result.best
        bad = "" if np.isfinite(y) and y <= _SE_CAP else " (SE > 1000 % or not finite)"
        color = "C3" if best else f"C{(i % 6) + 4}"
        if len(exps) > 1 and exps.max() > exps.min() * 1.001:
            ax_w.plot([exps.min() * MS, exps.max() * MS], [y, y], "-", color=color, lw=1,
                      alpha=0.6)
        dts = {round(r[0] / dt_best, 6) for r in c.recordings}
        other_dt = "" if dts == {1.0} else " (dt = " + ", ".join(
            f"{r[0] * MS:.3g}" for r in c.recordings[:1]) + " ms)"
        ax_w.plot([x], [y if not bad else np.nan], _MARKERS[0] if best else _MARKERS[1 + i % 7], color=color,
                  ms=14 if best else 8, ls="none", gid="candidate",
                  label=("recommended: " if best else "") + c.label + other_dt + bad)
    shown = [ln.get_ydata() for ln in ax_w.get_lines()]
    if not any(np.isfinite(np.asarray(y, dtype=float)).any() for y in shown):
        ax_w.set_ylim(1.0, _SE_CAP)  # nothing to scale the log axis to
    if not np.isfinite(se_w).any():
        ax_w.text(0.5, 0.5, "one recording: SE > 1000 % at every W", ha="center",
                  transform=ax_w.transAxes, fontsize=8)
    ax_w.set_xscale("log")
    ax_w.set_yscale("log")
    ax_w.set_xlabel(f"exposure W [ms] (dt = {dt_best * MS:.3g} ms)")
    ax_w.set_ylabel("predicted relative SE [%]")
    ax_w.set_title(f"markers: SE of {result.target} of each candidate", fontsize=9)
    ax_w.legend(fontsize=7, loc="best")

    if ax_dt is not None:
        dts = np.geomspace(dt_min, 10 * dt_min, 40)
        se_dt = 100 * _single_se(result, np.maximum(dts - dead, w_min), dts)
        ax_dt.plot(dts * MS, se_dt[:, 0], "C0-", label="k")
        ax_dt.plot(dts * MS, se_dt[:, 1], "C1--", label="gamma")
        ax_dt.axvline(dt_best * MS, color="C3", ls=":", lw=1, label="recommended dt")
        # a single W = dt recording with dt >> tau hardly separates gamma from eps^2: its SE
        # grows without bound, so the axis stops at 1000 %
        ax_dt.set_xscale("log")
        ax_dt.set_yscale("log")
        from matplotlib.ticker import NullFormatter

        ax_dt.xaxis.set_minor_formatter(NullFormatter())
        finite = se_dt[np.isfinite(se_dt) & (se_dt > 0)]
        if finite.size:
            ax_dt.set_ylim(0.7 * finite.min(), min(1.5 * finite.max(), _SE_CAP))
        else:  # nothing to scale the log axis to
            ax_dt.set_ylim(1.0, _SE_CAP)
            ax_dt.text(0.5, 0.5, "one recording: SE > 1000 % at every dt", ha="center",
                       transform=ax_dt.transAxes, fontsize=8)
        ax_dt.set_xlabel("frame interval dt [ms] (W = dt" + (" - dead time)" if dead else ")"))
        ax_dt.set_ylabel("predicted relative SE [%]")
        ax_dt.set_title("one recording, W = dt", fontsize=9)
        ax_dt.legend(fontsize=7)
    return fig
