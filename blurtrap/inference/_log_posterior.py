"""The log-posterior of :func:`sample_posterior` (pure JAX) and its compiled, batched form
for emcee (``vectorize=True``): ``log post(theta) = log L(exp theta) + log prior + sum theta``.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._problems import ExactArgs, exact_nll, spectral_nll
from ._whittle_closed import _rational_whittle_nll, _RationalWhittleArgs

_TRACE_COUNT = [0]  # incremented each time the batched log-posterior is traced


def trace_count() -> int:
    """How many times the batched log-posterior has been traced (compiled) so far."""
    return _TRACE_COUNT[0]


class _PostArgs(eqx.Module):
    lik: Any  # _RationalWhittleArgs, SpectralArgs or ExactArgs
    priors: tuple  # one Prior per parameter, in layout.names order
    names: tuple = eqx.field(static=True)
    user_log_prior: tuple = eqx.field(static=True)  # JAX-traceable f(dict) -> scalar
    chunk: int | None = eqx.field(static=True, default=None)  # walkers per vmap chunk


def _nll(p, lik):
    if isinstance(lik, _RationalWhittleArgs):
        return _rational_whittle_nll(p, lik)
    if isinstance(lik, ExactArgs):
        return exact_nll(p, lik)
    return spectral_nll(p, lik)


def _log_posterior(theta, a: _PostArgs):
    p = jnp.exp(theta)
    lp = jnp.sum(theta)  # log |dp/dtheta|
    for i, prior in enumerate(a.priors):
        lp = lp + prior.log_prob(p[i])
    if a.user_log_prior:
        d = {name: p[i] for i, name in enumerate(a.names)}
        for fn in a.user_log_prior:
            lp = lp + jnp.asarray(fn(d), dtype=p.dtype)
    nll = _nll(p, a.lik)
    out = lp - nll
    return jnp.where(jnp.isnan(out), -jnp.inf, out)


def _batched_impl(thetas, a: _PostArgs):
    """Log-posterior of a batch of walkers ``thetas`` (n, d) -> (n,). The walker axis is
    vectorised (``vmap``) in chunks of ``a.chunk`` walkers, looped with ``lax.map``. Whittle
    likelihoods use a chunk of 1: the lag-sum evaluation's ``lax.cond`` (ordinate fallback)
    stays a real branch instead of a ``select`` that evaluates both sides, and the ordinate
    forms keep each walker's (R, M) intermediates in cache (~4x faster on CPU than one
    (n, R, M) vmap). The exact likelihood's sequential scan is vectorised over the whole
    batch."""
    _TRACE_COUNT[0] += 1  # Python side effect: runs only while tracing
    chunk = thetas.shape[0] if a.chunk is None else min(a.chunk, thetas.shape[0])
    if chunk >= thetas.shape[0]:
        return jax.vmap(_log_posterior, in_axes=(0, None))(thetas, a)
    one = lambda t: _log_posterior(t, a)
    if chunk == 1:
        return jax.lax.map(one, thetas)
    return jax.lax.map(one, thetas, batch_size=chunk)


_batched_log_posterior = eqx.filter_jit(_batched_impl)

# One jitted function per static configuration (model flags, layout names, prior kinds,
# user prior functions): data and prior values are its array arguments, so new data of the
# same shapes reuse the compiled code. Array leaves are flattened once per
# ``sample_posterior`` call and passed positionally, so each of emcee's calls takes JAX's C++
# dispatch path (no per-call pytree flattening of the arguments).
_JIT_CACHE: dict = {}


def _compiled_log_posterior(args: _PostArgs):
    """Return ``f(thetas) -> np.ndarray[float64]`` for emcee (``vectorize=True``)."""
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    leaves = [jnp.asarray(x) for x in leaves]  # on the device once, not on every call
    key = (treedef, static)
    fn = _JIT_CACHE.get(key)
    if fn is None:

        def impl(thetas, *lv):
            a = eqx.combine(jax.tree_util.tree_unflatten(treedef, lv), static)
            return _batched_impl(thetas, a)

        fn = _JIT_CACHE[key] = jax.jit(impl)

    def log_prob(thetas):
        return np.asarray(fn(np.asarray(thetas, dtype=np.float64), *leaves), dtype=np.float64)

    return log_prob
