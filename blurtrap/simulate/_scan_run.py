"""The chunked run of the frame scan (``"exact"``, ``"euler"``, ``"exact_frames"``): chunk
sizes, the initial state, sharding over devices, the progress bar, and the output buffer
filled chunk by chunk in place."""

from __future__ import annotations

import functools
import sys

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jax import lax
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from . import _core
from ._core import CoreConfig, buffer_traces, jitter_normals
from ._validate import count


def _make_mesh(shard, n_traces):
    devices = jax.devices()
    if shard is False or len(devices) < 2:
        return None
    if n_traces % len(devices):
        if shard is True:
            raise ValueError(
                f"shard=True needs n_traces to be a multiple of the {len(devices)} devices; "
                f"got n_traces = {n_traces}"
            )
        return None
    return Mesh(np.asarray(devices), ("traces",))


def _progress_bar(total: int, enabled: bool):
    """A tqdm bar over the chunks (stderr; a widget in notebooks), refreshed every chunk."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="simulate", unit="chunk", mininterval=0.0, file=sys.stderr)


_CHUNK_STEPS = 16


def balanced_chunk(total: int, max_chunk: int) -> int:
    """Frames per chunk for a run of `total` frames with chunks of at most `max_chunk`.

    The chunks are compiled once per size and a partial last chunk is computed in full, so:
    one chunk when the run fits; otherwise the fewest chunks, each rounded up to a multiple of
    ``max_chunk / 16`` (at most 16 compiled sizes per grid and trace count), which bounds the
    frames computed beyond the run by about 1/16 of it (a fixed ``max_chunk`` could waste up to
    half: ``total = max_chunk + 1`` ran two full chunks)."""
    if total <= max_chunk:
        return total
    n_chunks = -(-total // max_chunk)
    step = max(1, max_chunk // _CHUNK_STEPS)
    even = -(-total // n_chunks)
    return min(max_chunk, -(-even // step) * step)


@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def start_keys(keys, n_traces, dtype, buf_shape):
    """Per grid point: the keys of the initial state, the frames, the jitter and the injections,
    the stationary initial positions (units of sigma) and the zeroed output buffer (one
    compiled call: eager splits and zeros cost ~1 ms each)."""
    sub = jax.vmap(lambda kk: jr.split(kk, 4))(keys)
    x = jax.vmap(lambda kk: jr.normal(kk, (n_traces,), dtype))(sub[:, 0])
    buf = None if buf_shape is None else jnp.zeros(buf_shape, dtype)
    return sub[:, 0], sub[:, 1], sub[:, 2], sub[:, 3], x, buf


@functools.partial(jax.jit, donate_argnums=0)
def _place(buf, chunk, start):
    """``buf[..., start : start + n] = chunk`` in place (`buf` is donated)."""
    idx = (jnp.zeros((), jnp.int32),) * (buf.ndim - 1) + (jnp.asarray(start, jnp.int32),)
    return lax.dynamic_update_slice(buf, chunk, idx)


def _chunk_length(cfg, total, n_cells, method, progress, chunk_frames):
    """Frames per compiled chunk (`n_cells`: grid points times trajectories)."""
    if chunk_frames is None:
        # substeps: ~4 M substep-trajectories of random numbers per chunk. exact_frames
        # needs O(G T) working memory whatever the chunk, so its chunks are only there to
        # bound one call's output (32 M frame-trajectories) and to feed the progress bar
        per_frame = n_cells * max(cfg.n_rows, 2)  # innovations: the same 32 M
        budget = 1 << (26 if method == "exact_frames" and not progress else 22)
        chunk = balanced_chunk(total, max(1, budget // max(per_frame, 1)))
    else:
        chunk = min(count("chunk_frames", chunk_frames), total)
    return chunk + (chunk % 2 if cfg.innovations else 0)  # innovations: frames run in pairs


def _initial_state(cfg, plan, keys, n_traces, dtype, lead, buf_shape, mesh, n_chunks):
    """Keys, start positions, first jitter offsets and (several chunks) output buffers."""
    G = keys.shape[0]
    _, k_frames, k_jit, k_inj, x, buf = start_keys(keys, n_traces, dtype.name, buf_shape)
    if plan.innovations:  # the start is the stationary one-step predictor
        x = x * plan.coefs.ix[:, None]
    if cfg.jitter:
        delta = plan.coefs.jstd[:, None] * jitter_normals(k_jit, 0, n_traces, dtype)
    else:
        delta = jnp.zeros((G, 1), dtype)
    n_buf = buf_shape[-1] if buf_shape is not None else 0
    dbuf = jnp.zeros((G, n_traces, n_buf), dtype) if cfg.jitter and n_chunks > 1 else None
    if mesh is not None:
        x = jax.device_put(x, NamedSharding(mesh, PartitionSpec(None, "traces")))
        if n_chunks > 1:  # the output buffer is split over the devices like the traces
            spec = PartitionSpec(*((None,) * len(lead) + ("traces", None)))
            buf = jax.device_put(buf, NamedSharding(mesh, spec))
            if cfg.jitter:
                dbuf = jax.device_put(dbuf, NamedSharding(mesh, PartitionSpec(None, "traces")))
    return k_frames, k_jit, k_inj, x, delta, buf, dbuf


def run_scan(method, plan, keys, shape, n_win, windows, n_traces, n_frames, burn_in_frames,
             dtype, *, force, force_params, jitter, shard, unroll, normal_dtype, chunk_frames,
             progress):
    """Run the frame scan chunk by chunk. Returns the positions [m] ``(*lead, T, n_frames)``
    (``lead``: `shape`, plus the windows axis), the jitter offsets (G, T, n_frames) in units
    of tau (or None) and the grid points' keys for the injections."""
    G = keys.shape[0]
    mesh = _make_mesh(shard, n_traces)
    cfg = CoreConfig(method=method, n_exp=plan.n_exp, n_dead=plan.n_dead, n_seg=n_win,
                     n_win=n_win, jitter=jitter, force=force, dtype=dtype.name, mesh=mesh,
                     unroll=unroll, normal_dtype=normal_dtype.name,
                     innovations=plan.innovations)
    total = burn_in_frames + n_frames
    chunk = _chunk_length(cfg, total, G * n_traces, method, progress, chunk_frames)
    n_chunks = -(-total // chunk)
    # each chunk comes out in the user's shape (reshapes inside the jitted chunk are free,
    # eager ones copy); several chunks are placed into one donated buffer; a partial last
    # chunk is computed in full (the default chunk keeps that waste small)
    n_buf = n_chunks * chunk
    t_buf = buffer_traces(cfg, n_traces)
    lead = tuple(shape) + ((n_win,) if windows else ())
    k_frames, k_jit, k_inj, x, delta, buf, dbuf = _initial_state(
        cfg, plan, keys, n_traces, dtype, lead,
        lead + (t_buf, n_buf) if n_chunks > 1 else None, mesh, n_chunks)
    fp = force_params if force is not None else None
    bar = _progress_bar(n_chunks, progress)
    for c in range(n_chunks):
        x, delta, out, dout = _core.run_chunk_jit(
            cfg, chunk, lead, plan.coefs, fp, k_frames, k_jit, x, delta, jnp.int32(c * chunk)
        )
        if n_chunks == 1:
            buf, dbuf = out, dout
        else:
            buf = _place(buf, out, c * chunk)
            if jitter:
                dbuf = _place(dbuf, dout, c * chunk)
        if bar is not None:
            jax.block_until_ready(x)
            bar.update(1)
    if bar is not None:
        bar.close()
    exact_fit = t_buf == n_traces and burn_in_frames == 0 and n_buf == n_frames
    pos = buf if exact_fit else buf[..., :n_traces, burn_in_frames:total]  # pyright: ignore
    dj = None
    if jitter:
        dj = dbuf if exact_fit else dbuf[:, :n_traces, burn_in_frames:total]  # pyright: ignore
    return pos, dj, k_inj
