"""diagnose's screening fits of models folded on nodes (detector_filter, hydrodynamics,
exposure_kernel) with one compiled BFGS program for records of many lengths.

Their BFGS fit (``_screen_fit._bfgs_value_only``) was compiled per padded length: 3-5 s per
folded candidate in every new power-of-two bucket (~13 s per ``diagnose`` of a photodiode
record). Newton on the host over ordinate chunks does not help them (a record without a
filter puts detector_filter's optimum in a narrow curved valley towards alpha = 1: > 64
Newton passes against ~180 BFGS steps; benchmarks/RESULTS.md, session 17). Here the
record's ordinates (bucket padding left out) are cut into chunks of
:data:`._chunked.CHUNK` and stacked to a fixed capacity (:data:`CAPACITIES` chunks), each
ordinate's place between the record's nodes computed once on the host, and the objective
runs over the real chunks only (a loop with a traced trip count, :data:`GROUP` chunks per
trip), with the fold once per evaluation: the value and gradient come from one evaluation
of the nodes (:meth:`TrapModel.node_logp` at the record's frequency span) and its VJP, and
per trip the value and gradient of the Whittle sum with the node values as an input. The
objective is a :func:`jax.custom_jvp` whose tangent is the gradient's dot product (linear:
BFGS linearises and transposes it; tangents of the data are ignored: differentiable in the
parameters only). So every record of up to ``capacity * CHUNK`` ordinates shares one
compiled program per model, number of recordings and capacity (:data:`CAPACITIES`). The
stack costs memory (``capacity x R x CHUNK x 6`` numbers: 24 MB per recording at 32
chunks) and the last trip's padding chunks time (at most ``GROUP - 1`` chunks per
evaluation).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _chunked
from ._nodes import NodeValues, frequency_span, node_plan
from ._problems import SpectralArgs, SpectralObjective, _spectral_nll, spectral_node_logp

#: the numbers of chunks a stack holds (each a multiple of :data:`GROUP`), smallest first: a
#: record takes the smallest that fits its chunks, so one program per capacity serves every
#: length up to it (32: 2^19 ordinates, 2^20 samples; 128: 2^22 samples; 512: 2^24 samples)
#: and the stack's memory stays within 4x the record's above the first capacity (a single
#: large capacity would cost every short record its memory); longer records keep BFGS on
#: their padded ordinates (compiled per padded length). The first was 16 chunks: a record
#: of 2^20 samples then compiled again after shorter ones (4.9 s); at 32 it does not (warm
#: diagnose at 2^18 samples +0.2 s; benchmarks/RESULTS.md, session 23)
CAPACITIES = (32, 128, 512)
#: chunks evaluated together in each trip of the loop (2 was faster than 1 and 4 at 2^15 and
#: 2^17 ordinates)
GROUP = 2
#: screening fits of models folded on nodes on stacked chunks; False: BFGS compiled per
#: padded length (the previous behaviour)
STACKED = True


class StackedChunks(eqx.Module):
    """Ordinate chunks of one :class:`SpectralArgs` stacked along a leading axis of fixed
    capacity, ``n`` of them real (the rest copies of the last one at weight 0), with each
    ordinate's place between the nodes (``left``, ``t``: :func:`._nodes.node_plan`, on the
    host once, not in every evaluation)."""

    first: SpectralArgs  # structure and meta; its frequencies: each row's span (R, 2)
    f: jax.Array  # (C / GROUP, R, GROUP W): the chunks of each trip side by side
    s2: jax.Array
    power: jax.Array
    weight: jax.Array
    left: jax.Array  # int32
    t: jax.Array
    n: jax.Array  # () int32


def applies(nll, args) -> bool:
    """The stacked screening fit applies: the Whittle objective of a model whose spectrum is
    folded on nodes spanning each record, in ordinate chunks (static fields and shapes)."""
    return (STACKED and isinstance(nll, SpectralObjective)
            and _chunked.objective_chunkable(nll, args) and _chunked._spans_nodes(args))


def stack(args: SpectralArgs) -> StackedChunks | None:
    """``args``' ordinates up to the last one of weight > 0 in chunks of
    :data:`._chunked.CHUNK`, stacked to the smallest of :data:`CAPACITIES` that holds them
    (the last real chunk and the padding chunks: copies of the last ordinate at weight 0),
    each ordinate's place between the record's nodes computed here on the host; None where
    they take more chunks than the largest."""
    width = _chunked.CHUNK
    if width is None:  # chunking off
        return None
    f, s2, pw, wt = (np.asarray(z) for z in (args.f, args.s2, args.power, args.weight))
    used = np.nonzero(np.any(wt != 0, axis=0))[0]
    m_real = int(used[-1]) + 1 if used.size else 1
    n = -(-m_real // width)
    capacity = next((c for c in CAPACITIES if n <= c), None)
    if capacity is None:
        return None
    _, left, t = node_plan(f, args.model.fold_nodes, xp=np)  # the whole record's nodes
    size = capacity * width

    def stacked(z, zero_pad=False):
        z = z[:, :m_real]
        z = np.pad(z, [(0, 0), (0, size - m_real)], mode="constant" if zero_pad else "edge")
        # (R, C W) -> (C / GROUP, R, GROUP W): the chunks of each trip side by side
        return jnp.asarray(np.moveaxis(z.reshape(z.shape[0], capacity // GROUP, -1), 0, 1))

    # the node stage's frequencies: each row's span, so that :meth:`TrapModel.node_logp`
    # places the record's nodes
    span = jnp.asarray(frequency_span(f, np))
    first = eqx.tree_at(lambda a: (a.f, a.s2, a.power, a.weight), args,
                        (span, jnp.zeros_like(span), jnp.ones_like(span), jnp.zeros_like(span)))
    return StackedChunks(first=first, f=stacked(f), s2=stacked(s2), power=stacked(pw),
                         weight=stacked(wt, zero_pad=True), left=stacked(left), t=stacked(t),
                         n=jnp.asarray(n, dtype=jnp.int32))


def _group(s: StackedChunks, i, y) -> SpectralArgs:
    """Chunks ``i * GROUP ... (i + 1) * GROUP - 1`` side by side (one piece of
    ``GROUP * CHUNK`` ordinates) with the node values ``y`` given."""
    def cut(z):
        return jax.lax.dynamic_index_in_dim(z, i, axis=0, keepdims=False)  # (R, G W)

    values = NodeValues(logp=y, left=cut(s.left), t=cut(s.t))
    return eqx.tree_at(lambda a: (a.f, a.s2, a.power, a.weight, a.nodes), s.first,
                       (cut(s.f), cut(s.s2), cut(s.power), cut(s.weight), values),
                       is_leaf=lambda z: z is None)


def _trips(s: StackedChunks):
    return (s.n + GROUP - 1) // GROUP


def _group_nll(p, y, s: StackedChunks, i):
    return _spectral_nll(p, _group(s, i, y))


def _value_and_grad(p, s: StackedChunks):
    y, node_vjp = jax.vjp(lambda q: spectral_node_logp(q, s.first), p)
    vg = jax.value_and_grad(_group_nll, argnums=(0, 1))

    def body(i, acc):
        v, (gp, gy) = vg(p, y, s, i)
        return acc[0] + v, acc[1] + gp, acc[2] + gy

    zero = (jnp.zeros((), p.dtype), jnp.zeros_like(p), jnp.zeros_like(y))
    v, gp, gy = jax.lax.fori_loop(0, _trips(s), body, zero)
    return v, gp + node_vjp(gy)[0]


def _value(p, s: StackedChunks):
    y = spectral_node_logp(p, s.first)

    def body(i, acc):
        return acc + _group_nll(p, y, s, i)

    return jax.lax.fori_loop(0, _trips(s), body, jnp.zeros((), p.dtype))


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _nll(p, dynamic, static):
    # the value alone (BFGS's last evaluation, the value fit_nll_only returns: optimistix's
    # BFGS linearises at every trial point, i.e. runs the rule below): no gradient carried
    return _value(p, eqx.combine(dynamic, static))


@_nll.defjvp
def _nll_jvp(static, primals, tangents):
    p, dynamic = primals
    v, g = _value_and_grad(p, eqx.combine(dynamic, static))
    return v, jnp.dot(g, tangents[0])


def stacked_nll(p, s: StackedChunks):
    """The Whittle negative log-likelihood of the stacked chunks' real ordinates (forward
    and reverse differentiable in ``p`` only)."""
    dynamic, static = eqx.partition(s, eqx.is_array)
    return _nll(p, dynamic, static)
