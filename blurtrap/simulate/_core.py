"""The jitted frame scan (dimensionless: positions in sigma, times in tau).

One call runs ``n`` frames for all grid points ``G`` and trajectories ``T`` at once:
``lax.scan`` over frames; inside a frame one block of standard normals (``n_rows`` rows of
``(G, T)``) is used, and an inner ``lax.scan`` over the substeps accumulates the exposure
averages (``method="exact_frames"`` draws the frame from its exact law instead: the joint law
of the exposure segments given the start, or, with one window and regular frames, the frames'
innovations form, one normal per frame, two frames per step of the scan).
Memory is O(G T n_rows) per frame plus the frame output, never O(substeps). A chunk's output
is built in the user's ``(..., T, frames)`` layout and filled in place: the scan's
``(frames, ..., T)`` output is transposed block by block (:func:`block_frames` frames at a
time, while in cache), so no full-size transpose or scaling copy follows the scan.

The random numbers are those of ``blurtrap.simulate._rng`` (counter-mode Threefry and
Box-Muller; why not ``jax.random.normal`` is said there); the body of one frame is
``blurtrap.simulate._frame``; the coefficients ``P`` are a
``blurtrap.simulate._scan_coefs.ScanCoefs`` (float arrays with a leading grid axis ``G``).

CPU performance
---------------
On CPU the scan is compiled with ``xla_cpu_prefer_vector_width=512`` (per jit, see
:func:`_jit_for_cpu`: ~1.5x faster normals), and on a single CPU device many trajectories run in
tiles of :func:`tile_size` so that a frame's random numbers stay in cache (2x at 16384
trajectories). Neither changes the numbers.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from ._frame import constrain, frame_step, innovation_pair

# the generator's pieces, also reachable here (``_core.threefry2x32`` etc.)
from ._rng import cos_sin_quarter as cos_sin_quarter
from ._rng import frame_keys as frame_keys
from ._rng import jitter_normals as jitter_normals
from ._rng import log_f64 as log_f64
from ._rng import pair_normals as pair_normals
from ._rng import pair_uniforms
from ._rng import threefry2x32 as threefry2x32


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
    # exact_frames with one window and regular frames: the frames' innovations form
    # (``_coeffs.innovations_law``), one normal per frame; frames run in pairs, one Box-Muller
    # pair per two frames (counter: the pair's first frame), so chunks have even lengths
    innovations: bool = False

    @property
    def n_rows(self) -> int:
        """Normals drawn per frame and trajectory."""
        if self.innovations:
            return 1
        if self.method == "exact_frames":
            return 2 * self.n_seg  # the dead time is merged into the last segment's draw
        return self.n_exp + self.n_dead



def _draws(cfg, kd, f, n_t, t_offset, n_total):
    """Frame `f`'s Box-Muller pairs ``(r, t)`` for trajectories ``[t_offset, t_offset + n_t)``."""
    r, t = pair_uniforms(kd, f, -(-cfg.n_rows // 2), n_t, cfg.normal_dtype, t_offset, n_total)
    spec = (None, None, "traces")
    if jnp.dtype(cfg.normal_dtype) == jnp.float32:  # one Threefry block gives r and t
        return (constrain(cfg, lax.complex(r, t), spec),)
    return constrain(cfg, r, spec), constrain(cfg, t, spec)


def _scan_frames(cfg, n, P, force_params, kd, keys_j, x, delta, rt, frame0, t_offset,
                 n_total):
    """The frame scan over frames ``frame0 .. frame0 + n`` for trajectories
    ``[t_offset, t_offset + T)`` of ``n_total``; `rt` are frame `frame0`'s Box-Muller pairs
    (innovations form: frames ``frame0`` and ``frame0 + 1``'s pair) and frame
    ``frame0 + n``'s are returned. Returns ``(x, delta, rt, frames (n, G, n_win, T), deltas)``."""
    n_t = x.shape[-1]

    def draws(f):
        return _draws(cfg, kd, f, n_t, t_offset, n_total)

    if cfg.innovations:  # two frames per step; n is even

        def pair(carry, f):
            x, delta, rt = carry
            nxt = draws(f + 2)
            x, acc = innovation_pair(cfg, P, rt, x)
            return (x, delta, nxt), acc

        frames = frame0 + 2 * jnp.arange(n // 2, dtype=jnp.int32)
        (x, delta, rt), acc = jax.lax.scan(pair, (x, delta, rt), frames)
        return x, delta, rt, acc.reshape((n,) + acc.shape[2:]), None

    def body(carry, f):
        x, delta, rt = carry
        nxt = draws(f + 1)  # one frame ahead: materialised once as loop state
        x, delta, out = frame_step(cfg, P, force_params, keys_j, rt, x, delta, f)
        return (x, delta, nxt), out

    frames = frame0 + jnp.arange(n, dtype=jnp.int32)
    (x, delta, rt), (acc, deltas) = jax.lax.scan(body, (x, delta, rt), frames)
    return x, delta, rt, acc, deltas


_BLOCK_BYTES = 1 << 16  # bytes of one output block of frames (transposed while in cache)


def block_frames(cfg: CoreConfig, n_traj: int, n: int) -> int:
    """Frames per output block: the scan's ``(frames, ..., T)`` output is transposed to the
    user's ``(..., T, frames)`` layout block by block, while the block (~64 kB) is in cache
    (a transpose of a whole chunk costs ~6 ns per value on CPU, of a block ~1 ns)."""
    per = max(n_traj * cfg.n_win * jnp.dtype(cfg.dtype).itemsize, 1)
    b = 1 << max(3, min(6, int(math.log2(max(_BLOCK_BYTES // per, 1)))))
    return min(b, n)


def _run_tile(cfg, n, P, force_params, kd, keys_j, x, delta, frame0, t_offset, n_total,
              buf, dbuf):
    """Frames ``frame0 + j`` (``j < n``) of trajectories ``[t_offset, t_offset + T)`` of
    ``n_total``, scaled by ``P.scale`` and written into ``buf[:, :, t_offset + i, j]`` (and
    the jitter offsets into ``dbuf``) block by block."""
    n_t = x.shape[-1]
    nbl = block_frames(cfg, n_t, n)
    n_full, rem = divmod(n, nbl)
    scale = P.scale[:, None, None, None]
    zero = jnp.zeros((), jnp.int32)
    t_off = jnp.asarray(t_offset, jnp.int32)

    def write(buf, dbuf, acc, deltas, f):
        blk = (jnp.moveaxis(acc, 0, -1) * scale).astype(buf.dtype)  # (G, n_win, T, nbl)
        buf = lax.dynamic_update_slice(buf, blk, (zero, zero, t_off, f))
        if cfg.jitter:
            dbuf = lax.dynamic_update_slice(dbuf, jnp.moveaxis(deltas, 0, -1), (zero, t_off, f))
        return buf, dbuf

    def block(carry, f, size):
        x, delta, rt, buf, dbuf = carry
        x, delta, rt, acc, deltas = _scan_frames(cfg, size, P, force_params, kd, keys_j, x,
                                                 delta, rt, f, t_offset, n_total)
        buf, dbuf = write(buf, dbuf, acc, deltas, f - frame0)
        return (x, delta, rt, buf, dbuf), None

    carry = (x, delta, _draws(cfg, kd, frame0, n_t, t_offset, n_total), buf, dbuf)
    # the partial block first: written after the loop, it made XLA copy the whole buffer
    if rem:
        carry, _ = block(carry, frame0, rem)
    if n_full:
        starts = frame0 + rem + nbl * jnp.arange(n_full, dtype=jnp.int32)
        carry, _ = lax.scan(lambda c, f: block(c, f, nbl), carry, starts)
    x, delta, _, buf, dbuf = carry
    return x, delta, buf, dbuf


_TILE_BYTES = 1 << 20  # a frame's (r, t) per tile of trajectories: stays in L2 cache
_TILE_MAX = 2048  # and the per-frame state (exact_frames: 16 bytes of (r, t) per trajectory)


def tile_size(cfg: CoreConfig, n_traj: int):
    """Trajectories per tile, or None. Tiles only on a single CPU device (GPUs want all
    trajectories at once), without timing jitter (its normals are drawn per whole frame), and
    only when there are more than two tiles' worth of trajectories."""
    if cfg.mesh is not None or cfg.jitter or jax.default_backend() != "cpu":
        return None
    per_traj = 2 * (-(-cfg.n_rows // 2)) * jnp.dtype(cfg.normal_dtype).itemsize
    tile = min(1 << max(8, int(math.log2(max(_TILE_BYTES // per_traj, 1)))), _TILE_MAX)
    return tile if n_traj > 2 * tile else None


def buffer_traces(cfg: CoreConfig, n_traj: int) -> int:
    """Trajectories in the output buffer of :func:`run_chunk`: `n_traj` padded to whole tiles."""
    tile = tile_size(cfg, n_traj)
    return n_traj if tile is None else n_traj + (-n_traj % tile)


def run_chunk(cfg: CoreConfig, n: int, lead: tuple, P, force_params, keys_f, keys_j, x, delta,
              frame0):
    """Run `n` frames from state ``(x, delta)`` starting at global frame index `frame0`.

    Returns ``(x, delta, frames, deltas)``: the frames times ``P.scale`` (sigma: positions
    in metres) in the user's layout ``lead + (buffer_traces, n)`` (`lead`: the grid shape,
    plus the windows axis, reshaped here where it is free), and the jitter offsets
    ``(G, T, n)`` (or None). The output is filled in place block by block (:func:`_run_tile`),
    so no transpose of the whole chunk follows the scan.

    On one device, many trajectories run in tiles of :func:`tile_size` (one after the other,
    each through all `n` frames), so that a frame's random numbers stay in cache; the numbers
    are the same as without tiles.
    """
    n_t = x.shape[-1]
    n_pairs = -(-cfg.n_rows // 2)
    if cfg.innovations and n % 2:
        raise ValueError(f"chunks of the innovations form have even lengths; got n = {n}")
    tile = tile_size(cfg, n_t)
    n_pad = 0 if tile is None else -n_t % tile
    if n_pairs * (n_t + n_pad) * 2 >= 2**32:
        raise ValueError(
            f"one frame needs {cfg.n_rows} x {n_t} normals, more than the 2^32 the "
            "counter-based generator supports per frame; use fewer substeps or n_traces"
        )
    kd = frame_keys(keys_f)
    dtype = jnp.dtype(cfg.dtype)
    g_n = x.shape[0]
    user_shape = tuple(lead) + (n_t + n_pad, n)
    buf = jnp.zeros((g_n, cfg.n_win, n_t + n_pad, n), dtype)
    dbuf = jnp.zeros((g_n, n_t, n), dtype) if cfg.jitter else None
    if tile is None:
        x, delta, buf, dbuf = _run_tile(cfg, n, P, force_params, kd, keys_j, x, delta, frame0,
                                        0, n_t, buf, dbuf)
        return x, delta, buf.reshape(user_shape), dbuf
    # padded trajectories reuse other counters; they are discarded
    n_b = (n_t + n_pad) // tile
    xb = jnp.moveaxis(jnp.pad(x, ((0, 0), (0, n_pad))).reshape(x.shape[0], n_b, tile), 1, 0)

    def one(buf, args):
        xt, off = args
        xt, _, buf, _ = _run_tile(cfg, n, P, force_params, kd, keys_j, xt, delta, frame0,
                                  off, n_t, buf, None)
        return buf, xt

    buf, xb = lax.scan(one, buf, (xb, jnp.arange(n_b, dtype=jnp.int32) * tile))
    x = jnp.moveaxis(xb, 0, 1).reshape(x.shape[0], n_b * tile)[:, :n_t]
    return x, delta, buf.reshape(user_shape), dbuf


def _jit_for_cpu():
    """``run_chunk`` jitted; on CPU with XLA's preferred vector width set to 512 bits, which
    makes the normals ~1.5x faster (measured on this project's AVX-512 machine, and also with
    ``xla_cpu_max_isa=AVX2``), and with XLA's default (MLIR) fusion emitters pinned, so that
    the CLI's and the tests' process flag ``--xla_cpu_use_fusion_emitters=false``
    (``blurtrap._config.faster_compilation``), which makes this scan ~35 % slower, does not
    reach it. An option XLA does not know (older jaxlib) is dropped: first the pin, then the
    vector width (plain jit)."""
    wide = {"xla_cpu_prefer_vector_width": 512}
    tiers = [jax.jit(run_chunk, static_argnums=(0, 1, 2), compiler_options=options)
             for options in ({**wide, "xla_cpu_use_fusion_emitters": True}, wide)]
    tiers.append(jax.jit(run_chunk, static_argnums=(0, 1, 2)))
    chosen: list[int | None] = [None]

    def call(*args):
        if chosen[0] is None:
            if jax.default_backend() != "cpu":
                chosen[0] = len(tiers) - 1
            else:
                for i, fn in enumerate(tiers[:-1]):
                    try:
                        out = fn(*args)
                    except jax.errors.JaxRuntimeError as err:
                        if "compile option" not in str(err):
                            raise
                        continue
                    chosen[0] = i
                    return out
                chosen[0] = len(tiers) - 1
        return tiers[chosen[0]](*args)

    return call


run_chunk_jit = _jit_for_cpu()
