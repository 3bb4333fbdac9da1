"""Screening fits for diagnose: the minimum of an objective without standard errors (only
the likelihood ratio is used), by the chunked Newton loop where the fused Whittle pass applies
(nothing compiled per padded length), else by BFGS: for models folded on nodes on stacked
ordinate chunks (:mod:`._screen_stacked`: one program for records of many lengths)."""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import optimistix as optx

from . import _screen_stacked
from ._chunked import objective_chunkable
from ._fit import _bfgs, _chunked_newton
from ._whittle_pass import _fused_pass_applies as fused_pass_applies

#: a screening fit (:func:`fit_nll_only`) by chunked Newton stops once the decrease still to
#: come is below this (log-likelihood units; its likelihood-ratio and AIC uses need ~1e-3): a
#: parameter running to its bound (drift on drift-free data) otherwise took ~20 passes
SCREEN_NLL_ATOL = 1e-6
#: screening fits by the chunked Newton loop where it applies; False: BFGS compiled per
#: padded length (the previous behaviour)
SCREEN_CHUNKED = True


@eqx.filter_jit
def _bfgs_value_only(nll, scale, args, rtol, atol, max_steps):
    f, x, result, n = _bfgs(nll, scale, args, rtol, atol, max_steps)
    return scale * jnp.exp(x), f(x, (args, scale)), result == optx.RESULTS.successful


def fit_nll_only(nll: Callable, scale, args, *, rtol=1e-8, atol=1e-8, max_steps=400):
    """Minimum of ``nll``: ``(p, nll, ok)``, for screening many candidate models where only
    the likelihood ratio is needed. Where the Whittle objective runs in chunks with the fused
    pass (the core model and additive effects) the chunked Newton loop runs first,
    so that a record in a new power-of-two bucket compiles no screening program (BFGS was
    compiled per padded length: ~2.6 s per candidate model at 2^17 frames); elsewhere, or
    where Newton fails, BFGS (no Hessian: cheaper than Newton with autodiff Hessians of a
    folded model, measured 2.1 -> 5.7 s warm on five 65 536-frame records); for a model
    folded on nodes on the record's stacked ordinate chunks, the fold once per evaluation
    (:mod:`._screen_stacked`), so that a new padded length compiles nothing within a
    capacity (2^19, 2^21, 2^23 samples)."""
    if SCREEN_CHUNKED and objective_chunkable(nll, args) and fused_pass_applies(args):
        out = _chunked_newton(nll, scale, args, rtol, atol, value_atol=SCREEN_NLL_ATOL)
        if bool(out.converged) and bool(out.hessian_pd):
            return out.value, float(out.nll), True
    stacked = _screen_stacked.stack(args) if _screen_stacked.applies(nll, args) else None
    if stacked is not None:
        # folded on nodes: one compiled BFGS per capacity of the stack (up to 2^22 ordinates)
        nll, args = _screen_stacked.stacked_nll, stacked
    p, v, ok = _bfgs_value_only(nll, scale, args, rtol, atol, max_steps)
    return p, float(v), bool(ok)
