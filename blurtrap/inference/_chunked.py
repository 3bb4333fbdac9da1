"""The default Whittle fit with the ordinates in fixed-size chunks, so that a recording of a
new length compiles (almost) nothing.

The Whittle/Gamma negative log-likelihood is a sum over ordinates, so its value, gradient and
Hessian are sums over any split of the ordinates into chunks: the one-pass
value/gradient/Hessian (:func:`._whittle_pass.spectral_newton_pass`) of each chunk, added.
Here the ordinates of :class:`._problems.SpectralArgs` (padded to a power of two,
``_problems.bucket_length``) are cut into chunks of :data:`CHUNK` ordinates (or one chunk of
the padded length when it is shorter), and the safeguarded Newton iteration
(:class:`._newton.SafeguardedNewton`, the same steps as inside ``optx.minimise``) runs on the
host: per Newton step one compiled call per chunk and one for the update. Only the chunk pass
depends on the record length, and only through the chunk width, a power of two up to
:data:`CHUNK`: once a recording of at least ``CHUNK`` ordinates (2^15 frames) was fitted, a
longer one of any length reuses every compiled program (before, each new power-of-two bucket
recompiled the whole fit: 3-5 s, benchmarks/RESULTS.md "Shape buckets"). Chunks whose weight
is all 0 (bucket padding) add exactly 0 and are skipped, so the padding costs nothing.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._newton import FixedArgs, ReducedObjective, SafeguardedNewton
from ._nodes import frequency_span, use_nodes
from ._problems import SpectralArgs, SpectralObjective
from ._whittle_pass import (
    _COARSE_GROUPS,
    _COARSE_MAX_WIDTH,
    _fused_pass_applies,
    coarse_start_applies,
)

#: ordinates per chunk (a power of two); ``None`` turns the chunked fit off (one compiled
#: Newton loop per padded length, the previous behaviour)
CHUNK: int | None = 1 << 14
#: the exact (finite-difference Newton) fits also run their loop on the host, so that only
#: their pass depends on the length (the exact likelihood's pass in fixed frame chunks:
#: ``_exact_chunks``); False: one compiled loop (the previous way)
HOST_NEWTON = True


#: models with effects (autodiff pass) also run their Newton loop in ordinate chunks on the
#: host, so a recording of a new length compiles no fit program for them either (a compiled
#: loop per power-of-two bucket cost 4-11 s at 2^16 frames). Each warm fit pays host
#: dispatches and the data-only work a compiled loop keeps out of its body (benchmarks/
#: RESULTS.md "Session 13"); False: one compiled Newton loop per padded length. The Hessian
#: at a bound and the fitted spectrum (one-shot evaluations) are chunked either way
EFFECTS = True


def chunked_applies(nll, args) -> bool:
    """The chunked Newton fit applies: the Whittle objective
    (:class:`._problems.SpectralObjective`) of the closed-form core model (fused pass), or,
    with :data:`EFFECTS`, of a model whose spectrum can be evaluated chunk by chunk
    (:func:`args_chunkable`), or either with parameters held; chunking on."""
    return objective_chunkable(nll, args) and (EFFECTS or _fused_pass_applies(_inner(args)))


def objective_chunkable(nll, args) -> bool:
    """``nll`` is the Whittle objective (or its :class:`._newton.ReducedObjective` with held
    parameters) and ``args`` can be evaluated in ordinate chunks (:func:`args_chunkable`):
    its sums (value, gradient, Hessian) are sums over chunks."""
    if isinstance(nll, ReducedObjective) and isinstance(args, FixedArgs):
        nll, args = nll.inner, args.inner
    return isinstance(nll, SpectralObjective) and args_chunkable(args)


def _inner(args):
    """The full objective's args of ``args`` (:class:`._newton.FixedArgs` unwrapped)."""
    return args.inner if isinstance(args, FixedArgs) else args


def _rewrap(args, parts):
    """``parts`` (chunks of ``_inner(args)``, or None) in ``args``' held-parameter wrapper."""
    if parts is None or not isinstance(args, FixedArgs):
        return parts
    return [eqx.tree_at(lambda z: z.inner, args, c) for c in parts]


def args_chunkable(args) -> bool:
    """The objective on ``args`` is a sum over ordinates whose model spectrum at each one
    can be evaluated from a chunk of them: the closed-form core model (fused pass), any
    model whose spectrum at an ordinate depends on that frequency alone (closed forms with
    additive or relation effects: drift, line noise, heating ...; unaliased models; the
    exact fold), and a model folded on nodes (:mod:`._nodes`): each chunk then carries the
    record's frequency span (:func:`_spans_nodes`), and a record too short to use nodes on
    its own (``_nodes.MIN_ORDINATES``) uses them in its chunk, so that its fit shares the
    long records' chunk program instead of compiling one per padded length (the two agree
    to the nodes' accuracy, ~1e-7 of the spectrum). Decided from static fields and shapes
    only."""
    if CHUNK is None or not isinstance(args, SpectralArgs):
        return False
    if _fused_pass_applies(args):
        return True
    m = args.model
    if m.closed_form or not m.alias:
        return True
    # folded: on nodes spanning the record in every chunk (a short record too: its one chunk
    # then holds the nodes, so records of any length share the chunk program), or by the
    # exact sum at each ordinate where a chunk would not use nodes either
    return _chunk_uses_nodes(m) or not use_nodes(args.f, m.fold_nodes)


def _chunk_uses_nodes(model) -> bool:
    """A chunk of :data:`CHUNK` ordinates folds ``model``'s spectrum on nodes."""
    return CHUNK is not None and use_nodes(np.empty((1, CHUNK)), model.fold_nodes)


def _spans_nodes(args: SpectralArgs) -> bool:
    """The model spectrum is folded on nodes spanning each row's frequencies: every chunk
    then carries two more ordinates at weight 0, the row's smallest positive and its largest
    |f|, so that its nodes are the whole record's (and so is every interpolated value)."""
    m = args.model
    return (not _fused_pass_applies(args) and m.alias and not m.closed_form
            and _chunk_uses_nodes(m))


def _with_ordinates(args: SpectralArgs, f, s2, power, weight) -> SpectralArgs:
    return eqx.tree_at(lambda a: (a.f, a.s2, a.power, a.weight), args,
                       tuple(jnp.asarray(z) for z in (f, s2, power, weight)))


def _pad_to(z, size, mode):
    """``z`` padded along its last axis to ``size`` (copies of the last entry, or zeros)."""
    return np.pad(z, [(0, 0)] * (z.ndim - 1) + [(0, size - z.shape[-1])], mode=mode)


def ordinate_step(args: SpectralArgs) -> int:
    """Real ordinates per chunk: :data:`CHUNK` (the padded length with chunking off), less
    the two span ordinates where the chunks carry them (:func:`_spans_nodes`)."""
    if CHUNK is None:
        return int(args.f.shape[-1])
    return CHUNK - 2 if _spans_nodes(args) else CHUNK


def ordinate_chunks(args, skip_empty=True) -> list:
    """``args`` cut along the ordinates into consecutive pieces of :func:`ordinate_step`
    ordinates, the last one (or the only one) padded with copies of the last ordinate at
    weight 0 (and, for a spectrum folded on nodes, two span ordinates at weight 0 appended),
    so that every piece has the same shape, :data:`CHUNK` wide, whatever the record length;
    with ``skip_empty`` the pieces whose weight is all 0 are left out (they add exactly 0 to
    every sum), keeping at least one. Held-parameter args (:class:`._newton.FixedArgs`) are
    cut inside their wrapper."""
    if isinstance(args, FixedArgs):
        return _rewrap(args, ordinate_chunks(args.inner, skip_empty))
    f, s2, pw, wt = (np.asarray(z) for z in (args.f, args.s2, args.power, args.weight))
    m = f.shape[-1]
    size = ordinate_step(args)
    span = None
    if _spans_nodes(args):
        span = frequency_span(f, np)
        dt = np.asarray(args.meta.dt, float).reshape(-1, 1) * np.ones((f.shape[0], 1))
        span_s2 = np.sin(np.pi * span * dt) ** 2
    out = []
    for i in range(0, m, size):
        sl = slice(i, min(i + size, m))
        if skip_empty and out and not np.any(wt[..., sl] != 0):
            continue
        fc, s2c, pwc, wtc = (_pad_to(z[..., sl], size, mode) for z, mode in
                             ((f, "edge"), (s2, "edge"), (pw, "edge"), (wt, "constant")))
        if span is not None:
            fc, s2c = np.concatenate([fc, span], -1), np.concatenate([s2c, span_s2], -1)
            pwc = np.concatenate([pwc, pwc[..., -2:]], -1)
            wtc = np.concatenate([wtc, np.zeros_like(wtc[..., :2])], -1)
        out.append(_with_ordinates(args, fc, s2c, pwc, wtc))
    return out


def model_psd_in_chunks(kernel, p, args: SpectralArgs):
    """``kernel(p, chunk)`` (the model spectrum of a chunk) for every chunk of ``args``,
    put together: the spectrum on all of ``args``' ordinates, shape (R, M), numpy."""
    step = ordinate_step(args)
    parts = [np.asarray(kernel(p, c))[..., :step] for c in ordinate_chunks(args, False)]
    return np.concatenate(parts, axis=-1)[..., :args.f.shape[-1]]


def binned_ordinates(args: SpectralArgs, width: int) -> SpectralArgs:
    """Host (numpy) twin of :func:`._whittle_pass._binned_args`: ordinates averaged in groups
    of ``width`` (weighted; plain mean where a group has no weight; the tail that does not
    fill a group dropped), the group weight the sum of its weights."""
    f, s2, pw, wt = (np.asarray(z) for z in (args.f, args.s2, args.power, args.weight))
    n = (f.shape[-1] // width) * width

    def grp(z):
        return z[..., :n].reshape(z.shape[:-1] + (n // width, width))

    w = grp(wt)
    wsum = np.sum(w, axis=-1)
    safe = np.where(wsum > 0, wsum, 1.0)

    def mean(z):
        return np.where(wsum > 0, np.sum(w * grp(z), axis=-1) / safe, np.mean(grp(z), axis=-1))

    return _with_ordinates(args, mean(f), mean(s2), mean(pw), wsum)


def coarse_chunks(args) -> list | None:
    """The chunks of the coarse start-value objective (the grouping of
    :func:`._whittle_pass.spectral_newton_plan`), or None where it has none."""
    if isinstance(args, FixedArgs):
        return _rewrap(args, coarse_chunks(args.inner))
    width = min(_COARSE_MAX_WIDTH, args.power.shape[-1] // _COARSE_GROUPS)
    if width < 2 or not coarse_start_applies(args):
        return None
    return ordinate_chunks(binned_ordinates(args, width))


@eqx.filter_jit
def _chunk_pass(obj, x, scale, chunk, acc):
    """``acc`` plus the value, gradient and Hessian of the objective on one chunk."""
    v, g, h = obj.value_grad_hess(x, scale, chunk)
    return acc[0] + v, acc[1] + g, acc[2] + h


#: the result code of a non-finite iterate (``RESULTS.nonfinite`` is newer than the oldest
#: optimistix supported, 0.0.10, which reports it as a divergence)
_NONFINITE = getattr(optx.RESULTS, "nonfinite", optx.RESULTS.nonlinear_divergence)


@eqx.filter_jit
def _start(solver, x0):
    state = solver.init(None, x0, None, None, None, None, None)
    zero = (jnp.zeros((), x0.dtype), jnp.zeros_like(x0), jnp.zeros((x0.shape[0],) * 2, x0.dtype))
    return state, zero


@eqx.filter_jit
def _update(solver, y, state, t, v, g, h):
    """One Newton update after the pass at ``t``, as in ``optx.minimise``'s loop: the new
    iterate and state, the next trial point, whether to go on, and the result code."""
    new = solver.update(y, state, t, v, g, h)
    stop, result = solver.terminate(None, new.x, None, None, new, None)
    result = optx.RESULTS.where(jnp.all(jnp.isfinite(y)), result, _NONFINITE)
    go = ~stop & (result == optx.RESULTS.successful)
    return new.x, new, solver.trial(new.x, new), go, stop, result


def _solver(rtol, atol, flat_atol=0.0, value_atol=0.0):
    # tolerances as arrays: one compiled update for the coarse and the full fit alike
    return SafeguardedNewton(rtol=jnp.asarray(rtol, float), atol=jnp.asarray(atol, float),
                             flat_atol=jnp.asarray(flat_atol, float),
                             value_atol=jnp.asarray(value_atol, float))


def host_newton_minimise(nll, scale, chunks, x0, rtol, atol, max_steps, value_atol=0.0):
    """:func:`._newton.newton_minimise` of ``nll`` summed over ``chunks`` with the loop on the
    host: at most ``max_steps`` Newton steps (``value_atol``: :class:`._newton.
    SafeguardedNewton`). Returns ``(state, result)`` (the final
    :class:`._newton.NewtonState` and the ``optx.RESULTS`` of the loop)."""

    def pass_fn(t):
        acc = zero
        for c in chunks:
            acc = _chunk_pass(nll, t, scale, c, acc)
        return acc

    zero = _start(_solver(rtol, atol), x0)[1]
    return host_newton_loop(pass_fn, x0, rtol, atol, max_steps, value_atol=value_atol)


def host_newton_loop(pass_fn, x0, rtol, atol, max_steps, flat_atol=0.0, value_atol=0.0):
    """The safeguarded Newton iteration of :func:`._newton.newton_minimise` with the loop on
    the host and the pass ``pass_fn(x) -> (value, grad, hess)`` (any host function, e.g. a
    sum over chunks): at most ``max_steps`` Newton steps. Returns ``(state, result)``."""
    solver = _solver(rtol, atol, flat_atol, value_atol)
    state, _ = _start(solver, x0)
    y = t = x0
    stop = False
    result = optx.RESULTS.successful
    for _ in range(max_steps + 1):
        y, state, t, go, stop, result = _update(solver, y, state, t, *pass_fn(t))
        if not bool(go):
            break
    if not bool(stop) and bool(result == optx.RESULTS.successful):
        result = optx.RESULTS.nonlinear_max_steps_reached
    return state, result
