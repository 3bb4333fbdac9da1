"""The exact (innovations) likelihood's Newton pass in fixed-size frame chunks, so that a
recording of a new length compiles nothing once a first one was fitted.

The finite-difference Newton fit of the exact likelihood (:func:`._fit.fit_ml_fd_newton`)
needs, per step, the value and gradient of ``exact_nll`` at ``x`` and ``x +- h e_i``
(:func:`._newton.fd_hessian_pass`). Compiled on the whole (bucket-padded) frame array, that
pass was one XLA program per power-of-two bucket (1.5-4 s each, benchmarks/RESULTS.md "Shape
buckets"). Here the recursion of :func:`._likelihood.arma_loglik` runs over consecutive
chunks of exactly :data:`FRAME_CHUNK` frames with its state carried from chunk to chunk (the
previous innovation of the frame series and of the constant series, and the running sums
``sum log v``, ``y'S^-1 y``, ``1'S^-1 y``, ``1'S^-1 1``); the innovation variances are the
same closed form at the chunk's global frame indices, and the differencing
``w_t = y_t - rho y_(t-1)`` reads the frame before the chunk. Derivatives are forward mode:
per recording the log-likelihood depends on the parameters only through its three moments
``(C(0), C(1), rho)``, so the chunk program propagates three tangent directions of the carry
(:func:`jax.jvp`), and one small program turns the sums into the log-likelihood, its
gradient in ``(C(0), C(1), rho)`` and, by the chain rule through the moments, the value,
gradient and difference Hessian of the objective in ``x``, exactly as
:func:`._newton.fd_hessian_pass` assembles them. Only the chunk program touches the frames,
and it runs one recording at a time, shapes (points, 1, ``FRAME_CHUNK + 1``): a new record
length or number of recordings reuses it. Chunks past a recording's last frame are not run;
a partly filled last chunk has mask 0 on its padding, which adds exactly 0 (the recursion is
causal).

The irregular-time likelihood (:mod:`._irregular`, frames at recorded times) runs the same
way (:class:`IrregularChunk`): its Kalman filter continues from the carried state mean and
variance, each chunk carries its frames' intervals, and its per-recording parameters are
``(sigma^2, tau, eps^2)``.

Applies to ``exact_nll`` on :class:`._problems.ExactArgs` and ``irregular_nll`` on
:class:`._irregular.IrregularArgs`, and to their reduced objectives with held parameters
(``calibrate(..., fixed=...)``); anything else keeps the compiled pass.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _irregular
from ._irregular import IrregularArgs, frame_params, irregular_nll
from ._likelihood import _affine_scan, gls_loglik, innovation_variances_at
from ._newton import FixedArgs, ReducedObjective
from ._problems import ExactArgs, exact_nll

#: frames per chunk (a power of two); ``None`` turns the chunked pass off (one compiled pass
#: per bucket-padded length, the previous behaviour)
FRAME_CHUNK: int | None = 1 << 12
#: the carried state per point and recording: previous innovation of the frames and of the
#: constant series, sum of log v, y'S^-1 y, 1'S^-1 y, 1'S^-1 1 (sums over real frames)
_N_CARRY = 6


class FrameChunk(eqx.Module):
    """One chunk of frames of R recordings: the frame before it, then its frames."""

    y: jax.Array  # (R, FRAME_CHUNK + 1): centred frames (mean != "zero"), 0 on padding
    m: jax.Array  # (R, FRAME_CHUNK + 1): 1 on real frames, 0 before the first and on padding
    t0: jax.Array  # frames before the chunk (float scalar: one program for every chunk)

    def records(self):
        """The per-recording data (leading axis R)."""
        return self.y, self.m

    def step(self, theta, carry, rec, mean):
        return _step(theta, carry, rec[0], rec[1], self.t0, mean)


class IrregularChunk(eqx.Module):
    """One chunk of frames at irregular times of R recordings (no frame before it: the
    filter's carried state is the prediction for its first frame)."""

    y: jax.Array  # (R, FRAME_CHUNK): centred frames (mean != "zero"), 0 on padding
    m: jax.Array  # (R, FRAME_CHUNK): 1 on real frames, 0 on padding
    d: jax.Array  # (R, FRAME_CHUNK): interval to the next frame [s]
    w: jax.Array  # (R,): exposure [s] (0 without blur)

    def records(self):
        return self.y, self.m, self.d, self.w

    def step(self, theta, carry, rec, mean):
        y, m, d, w = rec
        return _irregular.chunk_step(theta, carry, y, m, d, w, mean)


def frame_chunks(a: ExactArgs, size: int) -> list[FrameChunk]:
    """The frames of ``a`` cut into consecutive chunks of ``size`` (the last padded with
    mask 0; the bucket padding after every recording's last frame left out). For the
    profiled and restricted means the frames are centred on their mean first (on the host, as
    :func:`._likelihood.arma_loglik` does in the graph: both are shift-invariant)."""
    ys, mask, n_used = _centred(a)
    n_chunks = -(-n_used // size)
    width = n_chunks * size + 1  # a zero column first: "the frame before" the first chunk
    y = np.zeros((ys.shape[0], width))
    m = np.zeros((ys.shape[0], width))
    y[:, 1:n_used + 1], m[:, 1:n_used + 1] = ys[:, :n_used], mask[:, :n_used]
    return [FrameChunk(y=jnp.asarray(y[:, i * size:(i + 1) * size + 1]),
                       m=jnp.asarray(m[:, i * size:(i + 1) * size + 1]),
                       t0=jnp.asarray(float(i * size)))
            for i in range(n_chunks)]


def _centred(a):
    """Frames (centred on their mean unless ``a.mean`` is "zero", as the likelihoods do in
    the graph: both are shift-invariant), mask, and frames up to the last real one."""
    ys, mask = np.asarray(a.ys, dtype=float), np.asarray(a.mask, dtype=float)
    if a.mean != "zero":
        n = np.sum(mask, axis=-1, keepdims=True)
        ys = (ys - np.sum(mask * ys, axis=-1, keepdims=True) / n) * mask
    real = np.flatnonzero(np.any(mask != 0, axis=0))
    return ys, mask, int(real[-1]) + 1 if real.size else 1


def irregular_chunks(a: IrregularArgs, size: int, w) -> list[IrregularChunk]:
    """The frames and intervals of ``a`` in consecutive chunks of ``size`` (as
    :func:`frame_chunks`), ``w`` the exposure per recording."""
    ys, mask, n_used = _centred(a)
    n_chunks = -(-n_used // size)
    width = n_chunks * size
    y, m, d = np.zeros((ys.shape[0], width)), np.zeros((ys.shape[0], width)), np.ones(
        (ys.shape[0], width))
    y[:, :n_used], m[:, :n_used] = ys[:, :n_used], mask[:, :n_used]
    d[:, :n_used] = np.asarray(a.intervals, dtype=float)[:, :n_used]
    w = jnp.asarray(w)
    return [IrregularChunk(*(jnp.asarray(z[:, i * size:(i + 1) * size]) for z in (y, m, d)), w=w)
            for i in range(n_chunks)]


def _step(theta, carry, y, m, t0, mean):
    """The carry after one chunk (frames ``y``, mask ``m``, the frame before first) of one
    recording with moments ``theta = (C(0), C(1), rho)``: the recursion of
    :func:`._likelihood._whiten` continued from the carried innovations."""
    c0, c1, rho = theta[0], theta[1], theta[2]
    size = y.shape[-1] - 1
    d = c0 * (1.0 + rho * rho) - 2.0 * rho * c1
    e = c1 - rho * c0
    t = t0 + jnp.arange(0, size + 1, dtype=c0.dtype)  # the frame before, then the chunk's
    v_all = innovation_variances_at(c0, d, e, jnp.maximum(t, 1.0))
    v = v_all[1:]
    theta_t = jnp.where(t[1:] == 1.0, 0.0, e / v_all[:-1])
    zero = mean == "zero"
    series = y[None] if zero else jnp.stack([y, m])
    w = series[:, 1:] - rho * series[:, :-1]
    n_s = series.shape[0]
    w = w.at[:, 0].add(-theta_t[0] * carry[:n_s])  # x_0 = the carried innovation
    eps = _affine_scan(jnp.broadcast_to(-theta_t, w.shape), w)
    mk = m[1:]
    wv = mk / v
    ey = eps[0]
    e1_last, s1y, s11 = carry[1], carry[4], carry[5]
    if not zero:
        e1 = eps[1]
        e1_last = e1[-1]
        s1y = s1y + jnp.sum(e1 * ey * wv)
        s11 = s11 + jnp.sum(e1 * e1 * wv)
    return jnp.stack([ey[-1], e1_last, carry[2] + jnp.sum(mk * jnp.log(v)),
                      carry[3] + jnp.sum(ey * ey * wv), s1y, s11])


def _loglik(carry, n, mean):
    """The log-likelihood from a final carry (its last four entries are the sums of
    :func:`._likelihood.gls_loglik`; ``n`` real frames)."""
    return gls_loglik(n, carry[-4], carry[-3], carry[-2], carry[-1], mean)


def _with_tangents(fn, theta, carry, dcarry):
    """``fn(theta, carry)`` and its derivative along each of the three directions of
    ``theta`` (the carry's own tangents ``dcarry`` (3, ...) along with them)."""
    eye = jnp.eye(theta.shape[-1], dtype=theta.dtype)
    out, dout = jax.vmap(lambda dt, dc: jax.jvp(fn, (theta, carry), (dt, dc)))(eye, dcarry)
    return out[0], dout


@eqx.filter_jit
def _chunk_jvp(theta, carry, dcarry, chunk, mean: str):
    """Carries and their tangents after ``chunk`` (a :class:`FrameChunk` or
    :class:`IrregularChunk`): ``theta`` (P, R, 3) at P points, ``carry`` (P, R, C),
    ``dcarry`` (P, R, 3, C)."""

    def one(th, ca, dca, rec):
        return _with_tangents(lambda a, b: chunk.step(a, b, rec, mean), th, ca, dca)

    per_rec = jax.vmap(one, in_axes=(0, 0, 0, 0))
    return jax.vmap(per_rec, in_axes=(0, 0, 0, None))(theta, carry, dcarry, chunk.records())


def _held_p(x, scale, held):
    p = x if scale is None else scale * jnp.exp(x)  # scale None: x is the parameters
    if held is not None:
        full, free = held
        p = full.at[jnp.asarray(free)].set(p)
    return p


def _moments(x, scale, small: ExactArgs, held):
    """``(C(0), C(1), rho)`` per recording, shape (R, 3), at ``p = scale exp(x)`` (the held
    parameters inserted where ``held = (full, free)``), as in ``exact_nll``."""
    k_rec, gamma, eps2 = small.layout.unpack(_held_p(x, scale, held))
    c0, c1, rho = small.model.moments(k_rec, gamma, eps2, small.meta.dt, small.meta.w,
                                      small.meta.temp)
    return jnp.stack(jnp.broadcast_arrays(c0, c1, rho), axis=-1)


def _irregular_theta(x, scale, small: IrregularArgs, held):
    """``(sigma^2, tau, eps^2)`` per recording, shape (R, 3), as in ``irregular_nll``."""
    sigma2, tau, _, e2 = frame_params(_held_p(x, scale, held), small.layout, small.model,
                                      small.meta)
    return jnp.stack([sigma2, tau, e2], axis=-1)


def _theta_fn(small):
    return _irregular_theta if isinstance(small, IrregularArgs) else _moments


def _points(x, h):
    """``x`` and ``x +- h e_i`` (the points of :func:`._newton.fd_hessian_pass`)."""
    eye = jnp.eye(x.shape[0], dtype=x.dtype) * h
    return jnp.concatenate([x[None], x[None] + eye, x[None] - eye])


def _start_at(pts, scale, small, held):
    """The per-recording parameters at the points ``pts`` (P, n) and the initial carries
    (zero tangents)."""
    theta = jax.vmap(_theta_fn(small), in_axes=(0, None, None, None))(pts, scale, small, held)
    p, r = theta.shape[:2]
    if isinstance(small, IrregularArgs):
        c0 = _irregular.initial_carry(pts.dtype)
    else:
        c0 = jnp.zeros(_N_CARRY, pts.dtype)
    n_c = c0.shape[0]
    return theta, jnp.broadcast_to(c0, (p, r, n_c)), jnp.zeros((p, r, 3, n_c), pts.dtype)


def _finish_at(pts, scale, small, held, carry, dcarry, n_frames):
    """Values and gradients in ``x`` of the objective at the points ``pts`` from the final
    carries."""
    mean = small.mean
    theta_fn = _theta_fn(small)

    def ll_rec(ca, dca, n):
        ll, dll = _with_tangents(lambda th, c: _loglik(c, n, mean), jnp.zeros(3, ca.dtype),
                                 ca, dca)
        return ll, dll

    ll, dll = jax.vmap(jax.vmap(ll_rec, in_axes=(0, 0, 0)), in_axes=(0, 0, None))(
        carry, dcarry, n_frames)  # (P, R), (P, R, 3)

    def value_grad(pt, ll_p, dll_p):
        _, vjp = jax.vjp(lambda z: theta_fn(z, scale, small, held), pt)
        return -jnp.sum(ll_p), vjp(-dll_p)[0]

    return jax.vmap(value_grad)(pts, ll, dll)


@eqx.filter_jit
def _start(x, scale, small, held, h):
    """:func:`_start_at` the points of the difference Hessian at ``x``."""
    return _start_at(_points(x, h), scale, small, held)


@eqx.filter_jit
def _finish(x, scale, small, held, h, carry, dcarry, n_frames):
    """Value, gradient and difference Hessian of the objective at ``scale exp(x)`` from the
    final carries (as :func:`._newton.fd_hessian_pass` assembles them)."""
    vals, grads = _finish_at(_points(x, h), scale, small, held, carry, dcarry, n_frames)
    n = x.shape[0]
    hess = (grads[1:1 + n] - grads[1 + n:]) / (2 * h)
    return vals[0], grads[0], 0.5 * (hess + hess.T)


_start_at_jit = eqx.filter_jit(_start_at)
_finish_at_jit = eqx.filter_jit(_finish_at)


_LIKELIHOODS = ((exact_nll, ExactArgs), (irregular_nll, IrregularArgs))


def _split(nll, args):
    """``(args of the likelihood, held)`` where the chunked pass applies to ``nll`` and
    ``args``, else None."""
    for base, kind in _LIKELIHOODS:
        if nll is base and isinstance(args, kind):
            return args, None
    if isinstance(nll, ReducedObjective) and isinstance(args, FixedArgs):
        for base, kind in _LIKELIHOODS:
            if isinstance(args.inner, kind) and nll.inner is base:
                return args.inner, (args.full, args.free)
    return None


def _row(ex, r):
    """Recording ``r`` of ``ex`` alone (its frame arrays' row ``r``, kept 2-D)."""
    names = ("ys", "mask", "intervals") if isinstance(ex, IrregularArgs) else ("ys", "mask")
    return eqx.tree_at(lambda a: tuple(getattr(a, f) for f in names), ex,
                       tuple(getattr(ex, f)[r:r + 1] for f in names))


class _FrameChunks:
    """The frames of one objective in chunks: ``run(start, finish)`` carries them through.

    Each recording runs through its own chunks (programs of one recording: the same for any
    set), up to its own last frame: a set of recordings of different lengths no longer runs
    every recording to the longest one's end, and a chunk of one recording at the 2n + 1
    points of a difference Hessian (13 at n = 6) stays small enough to run ~3.5x faster per
    recording than the four of a joint fit in one program (measured 0.53 vs 1.87 ms per
    point and recording and chunk of 4096 frames, benchmarks/RESULTS.md "Profile
    intervals"). The carries are the same recursion per recording as before."""

    def __init__(self, ex, held, size):
        self.ex, self.held = ex, held
        self.n_frames = jnp.asarray(np.sum(np.asarray(ex.mask, dtype=float), axis=-1))
        n_rec = ex.ys.shape[0]
        empty = jnp.zeros((n_rec, 0), ex.ys.dtype)
        if isinstance(ex, IrregularArgs):
            w = np.broadcast_to(np.asarray(_irregular.exposures(ex.model, ex.meta), float),
                                (n_rec,))
            self.rows = [irregular_chunks(_row(ex, r), size, w[r:r + 1]) for r in range(n_rec)]
            self.small = eqx.tree_at(lambda a: (a.ys, a.mask, a.intervals), ex,
                                     (empty, empty, empty))
        else:
            self.rows = [frame_chunks(_row(ex, r), size) for r in range(n_rec)]
            # no frames: no shape
            self.small = eqx.tree_at(lambda a: (a.ys, a.mask), ex, (empty, empty))

    def run(self, start, finish, x, scale, *extra):
        theta, carry, dcarry = start(x, scale, self.small, self.held, *extra)
        ends = []
        for r, chunks in enumerate(self.rows):
            th, c, dc = theta[:, r:r + 1], carry[:, r:r + 1], dcarry[:, r:r + 1]
            for ch in chunks:
                c, dc = _chunk_jvp(th, c, dc, ch, self.ex.mean)
            ends.append((c, dc))
        if len(ends) > 1:
            carry = jnp.concatenate([e[0] for e in ends], axis=1)
            dcarry = jnp.concatenate([e[1] for e in ends], axis=1)
        else:
            carry, dcarry = ends[0]
        return finish(x, scale, self.small, self.held, *extra, carry, dcarry, self.n_frames)


def _frame_chunks_of(nll, args):
    size = FRAME_CHUNK
    split = None if size is None else _split(nll, args)
    if split is None or size is None:
        return None
    return _FrameChunks(*split, size)


def exact_chunk_pass(nll, args, h):
    """The finite-difference Newton pass ``(x, scale) -> (value, grad, hess)`` of ``nll``
    (``exact_nll`` or ``irregular_nll``, or their reduced objectives with held parameters)
    in frame chunks, or None where it does not apply (other objectives, or
    :data:`FRAME_CHUNK` None)."""
    ch = _frame_chunks_of(nll, args)
    if ch is None:
        return None

    def pass_fn(x, scale):
        return ch.run(_start, _finish, x, scale, h)

    return pass_fn


def exact_chunk_grads(nll, args):
    """``(xs, scale) -> (values (P,), gradients (P, n))`` of ``nll(scale exp(x))`` at the
    points ``xs`` (P, n) in frame chunks (the same programs for every record length), or None
    where the chunked pass does not apply (as :func:`exact_chunk_pass`). ``scale=None``:
    of ``nll(x)``, the gradients in the parameters themselves (any of them may be 0)."""
    ch = _frame_chunks_of(nll, args)
    if ch is None:
        return None

    def grads(xs, scale):
        return ch.run(_start_at_jit, _finish_at_jit, xs, scale)

    return grads
