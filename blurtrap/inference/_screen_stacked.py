"""diagnose's screening fits of models folded on nodes (detector_filter, hydrodynamics,
exposure_kernel) with one compiled BFGS program for records of many lengths.

Their BFGS fit (``_screen_fit._bfgs_value_only``) was compiled per padded length: 3-5 s per
folded candidate in every new power-of-two bucket (~13 s per ``diagnose`` of a photodiode
record). Newton on the host over ordinate chunks does not help them (a record without a
filter puts detector_filter's optimum in a narrow curved valley towards alpha = 1: > 64
Newton passes against ~180 BFGS steps; benchmarks/RESULTS.md, session 17). Here the
record's ordinate chunks (:func:`._chunked.ordinate_chunks`, each carrying the record's
frequency span, so every chunk has the record's nodes) are stacked to a fixed capacity of
:data:`CAPACITY` chunks, with each ordinate's place between the nodes computed once on the
host, and the objective runs over the real chunks only (a loop with a traced trip count,
:data:`GROUP` chunks per trip), with the fold once per evaluation: the value and gradient
come from one evaluation of the nodes (:meth:`TrapModel.node_logp`) and its VJP, and per
trip the value and gradient of the Whittle sum with the node values as an input. The
objective is a :func:`jax.custom_jvp` whose tangent is the gradient's dot product (linear:
BFGS linearises and transposes it). So every record of up to ``CAPACITY * CHUNK``
ordinates shares one compiled program per model and number of recordings; the padding
chunks cost memory (``CAPACITY x R x CHUNK x 6`` numbers, 12 MB per recording), not time.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _chunked
from ._nodes import NodeValues, node_plan
from ._problems import SpectralArgs, SpectralObjective, _spectral_nll, spectral_node_logp

#: the number of chunks the stack holds (a multiple of :data:`GROUP`): records of up to
#: ``CAPACITY * CHUNK`` ordinates (2^18: 2^19 samples) are stacked; longer ones keep BFGS on
#: their padded ordinates (compiled per padded length, faster there when warm: the whole
#: program hoists the ordinates' data-only work out of its loop; 2^20 samples, one
#: photodiode record: detector_filter + hydrodynamics screens 4.8 s compiled, 7.5 s stacked)
CAPACITY = 16
#: chunks evaluated together in each trip of the loop: larger arrays per operation
GROUP = 4
#: screening fits of models folded on nodes on stacked chunks; False: BFGS compiled per
#: padded length (the previous behaviour)
STACKED = True


class StackedChunks(eqx.Module):
    """Ordinate chunks of one :class:`SpectralArgs` stacked along a leading axis of fixed
    capacity, ``n`` of them real (the rest copies of the last one at weight 0), with each
    ordinate's place between the nodes (``left``, ``t``: :func:`._nodes.node_plan`, on the
    host once, not in every evaluation)."""

    first: SpectralArgs  # the first chunk: structure, meta and the frequency span
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
    """``args``' ordinate chunks (bucket padding skipped) stacked to :data:`CAPACITY`, or
    None where they are more."""
    chunks = _chunked.ordinate_chunks(args)
    n = len(chunks)
    cap = CAPACITY
    if n > cap:
        return None
    fold_nodes = args.model.fold_nodes
    plans = [node_plan(np.asarray(c.f), fold_nodes, xp=np)[1:] for c in chunks]

    def stacked(parts, zero_pad=False):
        # (C, R, W, ...) -> (C / GROUP, R, GROUP W, ...): each trip's ordinates contiguous
        z = np.stack(parts)
        pad = np.repeat(z[-1:], cap - n, axis=0)
        z = np.concatenate([z, np.zeros_like(pad) if zero_pad else pad])
        c, r, w = z.shape[:3]
        return jnp.asarray(np.moveaxis(z.reshape(c // GROUP, GROUP, r, w, *z.shape[3:]), 1, 2)
                           .reshape(c // GROUP, r, GROUP * w, *z.shape[3:]))

    def field(name):
        return [np.asarray(getattr(c, name)) for c in chunks]

    return StackedChunks(first=chunks[0], f=stacked(field("f")), s2=stacked(field("s2")),
                         power=stacked(field("power")),
                         weight=stacked(field("weight"), zero_pad=True),
                         left=stacked([q[0] for q in plans]), t=stacked([q[1] for q in plans]),
                         n=jnp.asarray(n, dtype=jnp.int32))


def _group(s: StackedChunks, i, y) -> SpectralArgs:
    """Chunks ``i * GROUP ... (i + 1) * GROUP - 1`` side by side (one chunk of
    ``GROUP * CHUNK`` ordinates; their span ordinates carry weight 0) with the node values
    ``y`` given."""
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
    # the value alone (BFGS's line search): no gradient carried through the loop
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
