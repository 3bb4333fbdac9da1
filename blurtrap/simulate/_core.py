"""The jitted frame scan (dimensionless: positions in sigma, times in tau).

One call runs ``n`` frames for all grid points ``G`` and trajectories ``T`` at once:
``lax.scan`` over frames; inside a frame one block of standard normals
``(n_rows, G, T)`` is drawn from ``fold_in(key_g, frame_index)`` (so results do not depend on
the chunking), then an inner ``lax.scan`` over the substeps accumulates the exposure averages.
Memory is O(G T n_rows) per frame plus the O(n G T) frame output, never O(substeps).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import jax.random as jr
from jax.sharding import NamedSharding, PartitionSpec


class CoreConfig(NamedTuple):
    method: str  # "exact" | "euler" | "exact_frames"
    n_exp: int  # substeps inside the exposure windows (0 for exact_frames)
    n_dead: int  # substeps in the dead time (1 for exact / exact_frames)
    n_seg: int  # exposure segments (windows sorted by length)
    n_win: int  # windows reported
    jitter: bool
    force: Any  # callable or None (harmonic)
    dtype: str
    mesh: Any  # jax.sharding.Mesh or None
    unroll: int
    normal_dtype: str

    @property
    def n_rows(self) -> int:
        if self.method == "exact_frames":
            return 2 * self.n_seg + 1
        return self.n_exp + self.n_dead


def _constrain(cfg, x, spec):
    if cfg.mesh is None:
        return x
    return jax.lax.with_sharding_constraint(x, NamedSharding(cfg.mesh, PartitionSpec(*spec)))


def _normals(keys, frame, shape, dtype):
    """Standard normals ``(shape[0], G, *shape[1:])`` from each grid key folded with `frame`."""
    return jax.vmap(lambda k: jr.normal(jr.fold_in(k, frame), shape, dtype), out_axes=1)(keys)


def _drift(cfg, x, P, force_params):
    if cfg.force is None:
        return -x
    sig = P["sigma"][:, None]
    f_si = cfg.force(x * sig, force_params)
    return (f_si / (P["k"][:, None] * sig)).astype(x.dtype)


def _frame(cfg, P, force_params, keys_f, keys_j, carry, frame):
    x, delta = carry
    dtype = jnp.dtype(cfg.dtype)
    z = _normals(keys_f, frame, (cfg.n_rows, x.shape[-1]), jnp.dtype(cfg.normal_dtype))
    z = z.astype(dtype)
    z = _constrain(cfg, z, (None, None, "traces"))
    if cfg.method == "exact_frames":
        acc = jnp.zeros((x.shape[0], cfg.n_win, x.shape[1]), dtype)
        for s in range(cfg.n_seg):
            z1, z2 = z[2 * s], z[2 * s + 1]
            m = P["p"][:, s, None] * x + P["sm"][:, s, None] * z1
            x = P["e"][:, s, None] * x + P["cx"][:, s, None] * z1 + P["sx"][:, s, None] * z2
            acc = acc + P["M"][:, s, :, None] * m[:, None, :]
    else:
        acc0 = P["Wt"][:, 0, :, None] * x[:, None, :]
        xs = (
            z[: cfg.n_exp],
            jnp.swapaxes(P["A"], 0, 1)[..., None],
            jnp.swapaxes(P["B"], 0, 1)[..., None],
            jnp.swapaxes(P["Wt"][:, 1:, :], 0, 1)[..., None],
        )
        if cfg.method == "exact":

            def sub(c, inp):
                xx, ac = c
                zi, a, b, w = inp
                xx = a * xx + b * zi
                return (xx, ac + w * xx[:, None, :]), None

        else:

            def sub(c, inp):
                xx, ac = c
                zi, a, b, w = inp
                xx = xx + a * _drift(cfg, xx, P, force_params) + b * zi
                return (xx, ac + w * xx[:, None, :]), None

        (x, acc), _ = jax.lax.scan(sub, (x, acc0), xs, unroll=cfg.unroll)
    # dead time up to the next frame start (absorbs the timing jitter)
    rdead = P["rdead"][:, None]
    if cfg.jitter:
        d_next = P["jstd"][:, None] * jitter_normals(keys_j, frame + 1, x.shape[-1], dtype)
        d = jnp.maximum(rdead + d_next - delta, 0.0)
    else:
        d_next = delta
        d = jnp.broadcast_to(rdead, x.shape)
    zd = z[cfg.n_rows - cfg.n_dead :]
    if cfg.method == "euler":
        h = d / cfg.n_dead
        sq = jnp.sqrt(2.0 * h)

        def dead(xx, zi):
            return xx + h * _drift(cfg, xx, P, force_params) + sq * zi, None

        x, _ = jax.lax.scan(dead, x, zd)
    else:
        x = jnp.exp(-d) * x + jnp.sqrt(-jnp.expm1(-2.0 * d)) * zd[0]
    x = _constrain(cfg, x, (None, "traces"))
    out = (acc, delta) if cfg.jitter else (acc, None)
    return (x, d_next), out


def run_chunk(cfg: CoreConfig, n: int, P, force_params, keys_f, keys_j, x, delta, frame0):
    """Run `n` frames from state ``(x, delta)`` starting at global frame index `frame0`.

    Returns ``(x, delta, frames (n, G, n_win, T), deltas (n, G, T) or None)``.
    """
    frames = frame0 + jnp.arange(n, dtype=jnp.int32)

    def body(carry, f):
        return _frame(cfg, P, force_params, keys_f, keys_j, carry, f)

    (x, delta), (acc, deltas) = jax.lax.scan(body, (x, delta), frames)
    return x, delta, acc, deltas


run_chunk_jit = jax.jit(run_chunk, static_argnums=(0, 1))


def jitter_normals(keys, frame, n_traj, dtype):
    """(G, T) normals for the jitter offset of `frame` (same stream as inside the scan)."""
    return jax.vmap(lambda k: jr.normal(jr.fold_in(k, frame), (n_traj,), dtype))(keys)
