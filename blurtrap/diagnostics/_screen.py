"""Screening fits of candidate models whose spectrum has no closed form.

``diagnose`` refits the model once per candidate effect with the Whittle likelihood over every
periodogram ordinate. For the closed-form models (the core trap plus additive effects) that is
cheap. The others (``hydrodynamics``, ``detector_filter``, ``exposure_kernel``) fold a
continuous spectrum: each ordinate costs an explicit alias sum plus a Gauss-Legendre tail, ~45
evaluations of the continuous PSD, so a photodiode record of 2^20 samples took minutes per
candidate and, through reverse-mode autodiff, gigabytes of memory (benchmarks/RESULTS.md,
``bench_diagnose.py``).

Here the smooth (folded) part of the model is evaluated on :data:`N_NODES` log-spaced
frequencies per recording and carried to every ordinate by cubic Hermite interpolation of
``log P`` in ``log f``, with the node slopes ``d log P / d log f`` from fourth-order finite
differences of the node values (slopes by forward-mode autodiff made the gradient ~6x
dearer). Additive effects (drift, a narrow line) are evaluated at the ordinates themselves,
so a line of width 1/T is never interpolated. The likelihood is the same
Whittle sum over the same ordinates as ``calibrate``, so log-likelihoods stay comparable with
the base fit; the interpolation changes the model PSD by < 3e-8 relative (tested against the
exact model in ``tests/diagnostics/test_screen.py``), far below anything a likelihood-ratio
test can see. Cost per evaluation: O(N_NODES x 45) for the model plus O(M) cheap arithmetic;
memory O(M).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope
from ..inference._fit import fit_nll_only
from ..inference._ml_fits import screen_model
from ..inference._models import TrapModel, get_model
from ..inference._problems import SpectralArgs, make_layout, spectral_model_psd
from ..inference._spectral import _spectral_args, spectral_gof
from ..inference._starts import _start_vector

#: log-spaced nodes per recording at which the folded model is evaluated: the interpolation
#: error falls like 1/N_NODES^4 (largest relative error measured over the candidates' parameter
#: ranges, next to Nyquist: 2.3e-7 at 512 nodes, 2.7e-8 at 768, 6e-9 at 1024)
N_NODES = 768
#: below this many ordinates per recording the exact model is about as cheap: not interpolated
MIN_ORDINATES = 4096


class NodeArgs(eqx.Module):
    """The ordinates of all recordings (``spec``: as for the exact Whittle fit) and where the
    smooth part of the model is evaluated (``nodes``: same layout and metadata, ``f`` = the
    node frequencies, smooth model) with each ordinate's interval (``left``) and position in
    it (``t`` in [0, 1]); ``h`` is the node spacing in log f per recording."""

    spec: SpectralArgs
    nodes: SpectralArgs
    left: jax.Array  # (R, M) int
    t: jax.Array  # (R, M)
    h: jax.Array  # (R, 1)


def smooth_part(model: TrapModel) -> TrapModel:
    """``model`` without its additive effects (those are evaluated at the ordinates)."""
    return dataclasses.replace(model, extra=tuple(e for e in model.extra
                                                  if e.kind != "additive"))


def node_args(spec: SpectralArgs, n_nodes: int = N_NODES) -> NodeArgs:
    """Log-spaced nodes spanning each recording's ordinates, and the interpolation plan."""
    f = np.asarray(spec.f, dtype=float)
    lo, hi = f.min(axis=1), f.max(axis=1)
    hi = np.where(hi > lo, hi, lo * 1.001)
    h = (np.log(hi) - np.log(lo)) / (n_nodes - 1)
    nodes = np.exp(np.log(lo)[:, None] + h[:, None] * np.arange(n_nodes))
    u = (np.log(f) - np.log(lo)[:, None]) / h[:, None]
    left = np.clip(np.floor(u), 0, n_nodes - 2).astype(np.int32)
    t = np.clip(u - left, 0.0, 1.0)
    dts = np.asarray(spec.meta.dt, dtype=float)
    nspec = SpectralArgs(layout=spec.layout, model=smooth_part(spec.model), meta=spec.meta,
                         f=jnp.asarray(nodes),
                         s2=jnp.asarray(np.sin(np.pi * nodes * dts[:, None]) ** 2),
                         power=jnp.ones(nodes.shape), weight=jnp.zeros(nodes.shape),
                         log_ref=spec.log_ref, block_len=None)
    return NodeArgs(spec=spec, nodes=nspec, left=jnp.asarray(left), t=jnp.asarray(t),
                    h=jnp.asarray(h[:, None]))


def _slopes(y):
    """``dy/di`` on a uniform grid (last axis) by fourth-order finite differences: central
    inside, one-sided at the two ends on each side. Linear in ``y``: no autodiff through the
    model for the slopes, so the gradient of the objective costs one reverse pass."""
    inner = (y[..., :-4] - 8.0 * y[..., 1:-3] + 8.0 * y[..., 3:-1] - y[..., 4:]) / 12.0
    a0, a1, a2, a3, a4 = (y[..., j] for j in range(5))
    b0, b1, b2, b3, b4 = (y[..., -1 - j] for j in range(5))
    first = (-25.0 * a0 + 48.0 * a1 - 36.0 * a2 + 16.0 * a3 - 3.0 * a4) / 12.0
    second = (-3.0 * a0 - 10.0 * a1 + 18.0 * a2 - 6.0 * a3 + a4) / 12.0
    last = (25.0 * b0 - 48.0 * b1 + 36.0 * b2 - 16.0 * b3 + 3.0 * b4) / 12.0
    before_last = (3.0 * b0 + 10.0 * b1 - 18.0 * b2 + 6.0 * b3 - b4) / 12.0
    return jnp.concatenate([first[..., None], second[..., None], inner, before_last[..., None],
                            last[..., None]], axis=-1)


def _log_smooth(p, a: NodeArgs):
    """``log P`` of the smooth part at every ordinate, shape (R, M): cubic Hermite in log f
    from the node values and their fourth-order slopes (one gather of the four coefficients
    of each ordinate's interval)."""
    y = jnp.log(spectral_model_psd(p, a.nodes))
    m = _slopes(y)  # per interval of the node grid
    coef = jnp.stack([y[:, :-1], m[:, :-1], y[:, 1:], m[:, 1:]], axis=-1)  # (R, K-1, 4)
    c = jnp.take_along_axis(coef, a.left[..., None], axis=1)  # (R, M, 4)
    t = a.t
    s = 1.0 - t
    return (s * s * ((1.0 + 2.0 * t) * c[..., 0] + t * c[..., 1])
            + t * t * ((3.0 - 2.0 * t) * c[..., 2] - s * c[..., 3]))


def _additive(p, a: NodeArgs):
    """The additive effects (drift, a narrow line) at every ordinate, or None."""
    spec = a.spec
    extras = spec.layout.unpack_extras(p)
    out = None
    for e in spec.model.extra:
        if e.kind == "additive":
            term = e.psd_add(spec.f, spec.meta.dt[:, None], extras)
            out = term if out is None else out + term
    return out


def node_psd(p, a: NodeArgs):
    """The model PSD at every ordinate, shape (R, M): the smooth part interpolated from the
    nodes, the additive effects exact."""
    add = _additive(p, a)
    out = jnp.exp(_log_smooth(p, a))
    return out if add is None else out + add


def node_nll(p, a: NodeArgs):
    """Whittle negative log-likelihood over all ordinates (as ``spectral_nll``) with the model
    PSD of :func:`node_psd`."""
    s = a.spec
    add = _additive(p, a)
    log_p = _log_smooth(p, a)
    if add is None:  # no log of an exp, no division
        return jnp.sum(s.weight * (log_p - s.log_ref + s.power * jnp.exp(-log_p)))
    psd = jnp.exp(log_p) + add
    return jnp.sum(s.weight * (jnp.log(psd) - s.log_ref + s.power / psd))


_node_psd_jit = eqx.filter_jit(node_psd)


@float64_scope
def screen(recs, model, k, start=None):
    """Screening Whittle fit of ``model`` without standard errors: ``(params dict, nll, gof,
    ok)``, as :func:`blurtrap.inference._calibrate.screen_model` (used as it is for
    closed-form models and short records), with the folded spectrum interpolated from nodes."""
    mdl = get_model(model)
    if mdl.closed_form:
        return screen_model(recs, mdl, k, start=start)
    layout = make_layout(recs, k, mdl.noise, tuple(p.name for p in mdl.extra_params))
    spec = _spectral_args(recs, layout, mdl, 1, None)
    if spec.f.shape[-1] < MIN_ORDINATES:
        return screen_model(recs, mdl, k, start=start)
    args = node_args(spec)
    scale = _start_vector(recs, layout, mdl.noise, start)
    p, nll, ok = fit_nll_only(node_nll, scale, args)
    psd = _node_psd_jit(jnp.asarray(p), args)
    gof = spectral_gof(spec.power / psd, spec.weight, len(layout.names))
    return dict(zip(layout.names, map(float, p))), nll, gof, ok
