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
    import jax
    import jax.numpy as jnp

    from ..design import whittle_information

    s = result.settings
    eps_ref2 = float(s["tracking_std_m"]) ** 2
    w_ref = float(s["reference_exposure_s"])
    photon = bool(s["photon_limited"])
    temperature = float(s["temperature_K"])
    gamma = float(s["gamma_N_s_per_m"])
    total = s.get("total_time_s")
    n_fixed = s.get("n_frames")

    def one(w, dt):
        n = total / dt if total is not None else float(n_fixed)
        e2 = eps_ref2 * (w_ref / w) if photon else eps_ref2
        se = []
        for k in result.k:
            info = whittle_information(k, gamma, w, dt, n, temperature, e2)
            se.append(jnp.sqrt(jnp.diag(jnp.linalg.inv(info)))[:2])
        return jnp.max(jnp.stack(se), axis=0)

    out = jax.jit(jax.vmap(one))(jnp.asarray(exposures), jnp.asarray(intervals))
    out = np.array(out, dtype=float)
    out[~(out * 100 <= _SE_CAP)] = np.nan
    return out


def _target_se(cand, target):
    se = cand.predicted_se
    if target == "k":
        return float(np.max(se["k"]))
    if target == "gamma":
        return float(np.max(se["gamma"]))
    return float(np.max(np.sqrt(np.asarray(se["k"]) * np.asarray(se["gamma"]))))


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
