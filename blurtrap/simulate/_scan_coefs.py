"""Coefficients of the frame scan (``blurtrap.simulate._core``) for each scan method.

``"exact_frames"``: the exact law of the exposure segments given the start
(:func:`blurtrap.simulate._coeffs.segment_law`), or with one window and regular frames the
frames' innovations form (:func:`~blurtrap.simulate._coeffs.innovations_law`).
``"exact"`` / ``"euler"``: the substep sizes, their OU / Euler step coefficients and the
trapezoid weights of each window over the substeps (times an optional exposure profile);
too coarse substeps warn (:class:`SubstepBiasWarning`). All in units of sigma and tau,
computed in float64 on the host and handed to the scan as one :class:`ScanCoefs`.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, NamedTuple

import jax
import numpy as np

from . import _coeffs as co
from ._exposure import Grid
from ._validate import count

AUTO_BIAS = 1e-3  # target relative variance bias when substeps=None


class SubstepBiasWarning(RuntimeWarning):
    """The substep size is too coarse for the requested accuracy (``bias_tol``)."""


class ScanCoefs(NamedTuple):
    """Per-grid-point coefficients of the scan (leading axis ``G``); None where unused."""

    rdead: Any  # (G,) dead time / tau
    scale: Any  # (G,) sigma [m]: the frames are written in metres
    jstd: Any = None  # (G,) timing-jitter std / tau
    k: Any = None  # (G,) stiffness [N/m] (euler with a force)
    A: Any = None  # (G, n_exp) exact: exp(-h) - 1; euler: h
    B: Any = None  # (G, n_exp) noise amplitude of a substep
    Wt: Any = None  # (G, n_exp + 1, n_win) trapezoid weights of each window
    em1: Any = None  # (G, n_seg) exact_frames segment law (see _coeffs.segment_law)
    p: Any = None
    sm: Any = None
    cx: Any = None
    sx: Any = None
    M: Any = None  # (G, n_seg, n_win): window j = sum_s M[s, j] m_s
    icm1: Any = None  # (G,) innovations form: c - 1, c + b, s, start scale
    icb: Any = None
    istd: Any = None
    ix: Any = None


class ScanPlan(NamedTuple):
    coefs: ScanCoefs  # on the device, in the output dtype
    n_exp: int  # substeps inside the exposure (0 for exact_frames)
    n_dead: int  # substeps in the dead time
    innovations: bool  # exact_frames by its innovations form


def _frames_coefs(g: Grid, innovations: bool) -> dict:
    if innovations:  # one normal per frame (see _coeffs.innovations_law)
        icm1, icb, istd, ix = co.innovations_law(g.L[:, 0], np.maximum(g.dt / g.tau, g.L[:, 0]))
        return dict(icm1=icm1, icb=icb, istd=istd, ix=ix)
    em1, p, sm, cx, sx = co.segment_law(g.L)
    # window j (sorted) = sum_{s <= j} L_s m_s / a_j
    M = np.where(
        np.arange(g.n_seg)[:, None] <= np.arange(g.n_win)[None, :],
        g.L[:, :, None] / g.a_win[:, None, :],
        0.0,
    )
    return dict(em1=em1, p=p, sm=sm, cx=cx, sx=sx, M=M[:, :, np.argsort(g.order)])


def _substep_count(method, g: Grid, substeps):
    if substeps is not None:
        return count("substeps", substeps)
    a_max = float(g.a_win[:, -1].max())
    if method == "exact":
        n_tot = math.ceil(math.sqrt(a_max / (6 * AUTO_BIAS * float(co.s_blur(a_max)))))
    else:
        n_tot = math.ceil(a_max / (2 * AUTO_BIAS))
    # next power of two (the bias only gets smaller): nearby parameter values
    # share the static scan length, so new values seldom recompile
    return 1 << (max(n_tot, 4) - 1).bit_length()


def _trapezoid_weights(g: Grid, h, seg_n, exposure_profile):
    """Normalised trapezoid weights (G, n_exp + 1, n_win) of each window (sorted) over the
    substep grid points, times ``exposure_profile(t/W)``."""
    G, n_win = g.G, g.n_win
    cum = np.cumsum(seg_n)
    Wt = np.zeros((G, int(cum[-1]) + 1, n_win))
    for j in range(n_win):
        hj = h[:, : cum[j]]
        Wt[:, : cum[j], j] += hj / 2
        Wt[:, 1 : cum[j] + 1, j] += hj / 2
    if exposure_profile is not None:
        u = np.concatenate([np.zeros((G, 1)), np.cumsum(h, axis=1)], axis=1) / g.L[:, :1]
        prof = np.asarray(exposure_profile(u), dtype=np.float64)
        if prof.shape != u.shape or not np.all(np.isfinite(prof)) or np.any(prof < 0):
            raise ValueError(
                "exposure_profile(u) must return finite weights >= 0 of u's shape"
            )
        Wt = Wt * prof[:, :, None]
    norm = Wt.sum(axis=1, keepdims=True)
    if np.any(norm <= 0):
        raise ValueError("exposure_profile has zero total weight over the exposure")
    return Wt / norm, cum


def _substep_coefs(method, g: Grid, substeps, exposure_profile, bias_tol, stacklevel):
    """``"exact"`` / ``"euler"``: returns (coefficients, n_exp, n_dead)."""
    n_tot = _substep_count(method, g, substeps)
    if g.ends is not None:
        seg_n = [max(1, round(n_tot * s / g.ends[-1])) for s in g.seg_len_s]  # pyright: ignore
    else:
        seg_n = [n_tot]
    n_exp = int(sum(seg_n))
    h = np.concatenate([np.repeat(g.L[:, j : j + 1] / seg_n[j], seg_n[j], axis=1)
                        for j in range(g.n_seg)], axis=1)
    Wt, cum = _trapezoid_weights(g, h, seg_n, exposure_profile)
    P: dict = {"Wt": Wt[:, :, np.argsort(g.order)]}
    if method == "exact":
        P["A"], P["B"] = co.ou_step(h)  # A = exp(-h) - 1: updates by increments
        n_dead = 1
        bias = co.trapezoid_bias(g.a_win, cum[None, :])
    else:
        P["A"], P["B"] = h, np.sqrt(2.0 * h)
        hmax = h.max(axis=1)
        rdead = g.rdead
        n_dead = (max(1, math.ceil(float(np.max(rdead / hmax)) - 1e-9)) if rdead.max() > 0
                  else 1)
        bias = co.euler_bias(hmax)[:, None] + co.trapezoid_bias(g.a_win, cum[None, :])
        P["k"] = g.k  # (sigma is the scale)
    worst = float(np.max(bias))
    if worst > bias_tol:
        i = np.unravel_index(np.argmax(bias), bias.shape)
        hrel = float(np.max(h, axis=1)[i[0]])
        warnings.warn(
            f"substeps = {n_tot} is too coarse for method={method!r}: h/tau = {hrel:.3g}, "
            f"estimated relative bias of var(X_m) ~ {worst:.3g} > bias_tol = {bias_tol:g}; "
            "increase substeps (or use method='exact_frames' for a harmonic trap)",
            SubstepBiasWarning,
            stacklevel=stacklevel + 1,
        )
    return P, n_exp, n_dead


def scan_plan(method, g: Grid, jitter, substeps, exposure_profile, bias_tol, dtype,
              stacklevel=1) -> ScanPlan:
    """The scan's coefficients for `method` (``"exact"``, ``"euler"`` or ``"exact_frames"``)
    on grid `g`; `jitter`: a TimingJitter or None; warnings point `stacklevel` frames up."""
    innovations = method == "exact_frames" and g.ends is None and jitter is None
    if method == "exact_frames":
        P, n_exp, n_dead = _frames_coefs(g, innovations), 0, 1
    else:
        P, n_exp, n_dead = _substep_coefs(method, g, substeps, exposure_profile, bias_tol,
                                          stacklevel + 1)
    if jitter is not None:
        P["jstd"] = np.broadcast_to(np.asarray(jitter.std, np.float64), (g.G,)) / g.tau
    P["rdead"], P["scale"] = g.rdead, g.sigma
    coefs = ScanCoefs(**{name: np.asarray(v, dtype=dtype) for name, v in P.items()})
    return ScanPlan(jax.device_put(coefs), n_exp, n_dead, innovations)
