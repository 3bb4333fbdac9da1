"""Folded spectra on log-spaced nodes, carried to every periodogram ordinate.

A model without closed form (``hydrodynamics``, ``detector_filter``, ``exposure_kernel``)
folds a continuous spectrum: each ordinate costs an explicit alias sum plus a Gauss-Legendre
tail, ~45 evaluations of the continuous PSD, and reverse-mode autodiff keeps all of them
(gigabytes at 2^17 samples). The folded part is smooth in log f, so for long records it is
evaluated on :data:`N_NODES` log-spaced frequencies per recording spanning the ordinates and
carried to every ordinate by cubic Hermite interpolation of ``log P`` in ``log f``, the node
slopes ``d log P / d log f`` by fourth-order finite differences of the node values (linear
in them: no autodiff through the model for the slopes, one reverse pass for the gradient).
Additive terms (tracking noise, drift, a narrow line of width 1/T) are never interpolated:
the model adds them at the ordinates themselves.

Accuracy (``tests/inference/test_fold_nodes.py``, ``tests/diagnostics/test_screen.py``):
relative error of the folded PSD <= 2.7e-8 next to Nyquist over the candidates' parameter
ranges at 768 nodes (2.3e-7 at 512, 6e-9 at 1024, falling like 1/N_NODES^4). Cost per
evaluation: O(N_NODES x 45) for the folded sum plus O(M) arithmetic and one gather; memory
O(M).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

#: log-spaced nodes per recording at which the folded spectrum is evaluated
N_NODES = 768
#: below this many ordinates per recording the exact folded sum is about as cheap: not
#: interpolated (a static decision on the shape of the frequency array)
MIN_ORDINATES = 4096


def use_nodes(f, n_nodes: int = N_NODES) -> bool:
    """Whether the folded spectrum at frequencies ``f`` (shape (R, M)) goes through nodes."""
    return n_nodes > 0 and f.ndim == 2 and f.shape[-1] >= max(MIN_ORDINATES, 2 * n_nodes)


def frequency_span(f, xp=jnp):
    """Each row's smallest positive and largest ``|f|`` (shape (R, 2); inf where no
    frequency is positive): what :func:`node_plan` spans its nodes over, so that frequencies
    with the same span have the same nodes."""
    af = xp.abs(f)
    return xp.concatenate([xp.min(xp.where(af > 0, af, xp.inf), axis=-1, keepdims=True),
                           xp.max(af, axis=-1, keepdims=True)], axis=-1)


def node_plan(f, n_nodes: int = N_NODES, xp=jnp):
    """Nodes spanning each row of ``|f|`` (shape (R, M)) and the interpolation plan:
    ``(nodes (R, K), left (R, M) int, t (R, M) in [0, 1])``. The span is from the smallest
    positive to the largest ``|f|`` of the row (the folded PSD is even, and flat at f = 0:
    a zero frequency takes the value at the lowest node). Traceable; ``f`` is data, so
    nothing here enters a gradient. ``xp=numpy`` computes it on the host."""
    af = xp.abs(f)
    span = frequency_span(f, xp)
    lo, hi = span[..., :1], span[..., 1:]
    lo = xp.where(xp.isfinite(lo), lo, 1.0)
    hi = xp.where(hi > lo, hi, lo * 1.001)
    h = (xp.log(hi) - xp.log(lo)) / (n_nodes - 1)
    nodes = xp.exp(xp.log(lo) + h * xp.arange(n_nodes))
    u = (xp.log(xp.maximum(af, lo)) - xp.log(lo)) / h
    left = xp.clip(xp.floor(u), 0, n_nodes - 2).astype(xp.int32)
    t = xp.clip(u - left, 0.0, 1.0)
    return nodes, left, t


def fd_slopes(y):
    """``dy/di`` on a uniform grid (last axis) by fourth-order finite differences: central
    inside, one-sided at the two ends on each side."""
    inner = (y[..., :-4] - 8.0 * y[..., 1:-3] + 8.0 * y[..., 3:-1] - y[..., 4:]) / 12.0
    a0, a1, a2, a3, a4 = (y[..., j] for j in range(5))
    b0, b1, b2, b3, b4 = (y[..., -1 - j] for j in range(5))
    first = (-25.0 * a0 + 48.0 * a1 - 36.0 * a2 + 16.0 * a3 - 3.0 * a4) / 12.0
    second = (-3.0 * a0 - 10.0 * a1 + 18.0 * a2 - 6.0 * a3 + a4) / 12.0
    last = (25.0 * b0 - 48.0 * b1 + 36.0 * b2 - 16.0 * b3 + 3.0 * b4) / 12.0
    before_last = (3.0 * b0 + 10.0 * b1 - 18.0 * b2 + 6.0 * b3 - b4) / 12.0
    return jnp.concatenate([first[..., None], second[..., None], inner, before_last[..., None],
                            last[..., None]], axis=-1)


def hermite_log(y, left, t):
    """Cubic Hermite interpolation of node values ``y`` (R, K) (uniform grid, slopes from
    :func:`fd_slopes`) at positions ``(left, t)`` (R, M): one gather of the four
    coefficients of each ordinate's interval."""
    m = fd_slopes(y)
    coef = jnp.stack([y[:, :-1], m[:, :-1], y[:, 1:], m[:, 1:]], axis=-1)  # (R, K-1, 4)
    c = jnp.take_along_axis(coef, left[..., None], axis=1)  # (R, M, 4)
    s = 1.0 - t
    return (s * s * ((1.0 + 2.0 * t) * c[..., 0] + t * c[..., 1])
            + t * t * ((3.0 - 2.0 * t) * c[..., 2] - s * c[..., 3]))


class NodeValues(eqx.Module):
    """The folded spectrum's log values at the nodes (R, K) and where each ordinate falls
    between them (:func:`node_plan`'s ``left``, ``t``, (R, M)): what :func:`folded_on_nodes`
    would compute, given (the fold once for many ordinate chunks, the plan once for many
    evaluations)."""

    logp: jax.Array
    left: jax.Array
    t: jax.Array


def folded_on_nodes(folded, f, n_nodes: int = N_NODES, values: NodeValues | None = None):
    """``folded(g)`` (a positive, smooth, even spectrum; ``g`` of shape (R, K)) at every
    ``f`` (R, M), evaluated at ``n_nodes`` log-spaced nodes and interpolated in log-log;
    with ``values`` given, interpolated from them (``folded`` and ``f`` unused)."""
    if values is not None:
        return jnp.exp(hermite_log(values.logp, values.left, values.t))
    nodes, left, t = node_plan(f, n_nodes)
    return jnp.exp(hermite_log(jnp.log(folded(nodes)), left, t))
