r"""Simulation-and-calibration sweeps over a parameter grid: :func:`sweep`.

Work is cut into units (cell ``g``, chunk ``c``): ``chunk_traces`` trajectories of one grid cell
simulated with the key ``fold_in(fold_in(key, g), c)`` and calibrated with every model and
calibration method. A unit is computed the same way whatever runs it, and the per-unit
statistics are merged in chunk order, so the result is the same bit for bit on one device, on
several local devices and on several processes.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.random as jr
import numpy as np

from .._config import float64_scope
from ..inference import calibrate_batch
from ..simulate import simulate
from . import _stats as st
from ._grid import Grid, make_grid, truths
from ._methods import Method, parse_methods
from ._result import SweepResult

_MAX_AUTO_CHUNK = 64  # calibrate_batch fits 64 rows per compiled call


def _as_key(key):
    if key is None:
        raise ValueError("key must be a JAX PRNG key, e.g. key=jax.random.key(0); got key=None")
    arr = jax.numpy.asarray(key)
    if jax.numpy.issubdtype(arr.dtype, jax.dtypes.prng_key) and arr.ndim == 0:
        return arr
    if arr.dtype == jax.numpy.uint32 and arr.shape == (2,):
        return jr.wrap_key_data(arr)
    raise ValueError("key must be a single JAX PRNG key (jax.random.key(seed)); got an array "
                     f"of dtype {arr.dtype} and shape {arr.shape}")


def _count(name, value, minimum=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {name} = {value!r}")
    return int(value)


def _chunk(n_traces, chunk_traces):
    if chunk_traces is None:  # the largest divisor of n_traces up to 64
        return max(d for d in range(1, min(n_traces, _MAX_AUTO_CHUNK) + 1) if n_traces % d == 0)
    chunk = _count("chunk_traces", chunk_traces)
    if n_traces % chunk:
        raise ValueError(f"n_traces must be a multiple of chunk_traces (every chunk has the same "
                         f"size); got n_traces = {n_traces}, chunk_traces = {chunk}")
    return chunk


def _model_names(models):
    if isinstance(models, str) or not isinstance(models, Sequence) or not models:
        raise ValueError(f"models must be a non-empty sequence of model names or TrapModels, "
                         f"e.g. ('naive', 'standard'); got models = {models!r}")
    names = [m if isinstance(m, str) else getattr(m, "name", repr(m)) for m in models]
    if len(set(names)) != len(names):
        raise ValueError(f"models must be distinct; got {names}")
    return names


def _fingerprint(grid: Grid, **config) -> str:
    text = json.dumps([grid.fingerprint(), config], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _load_state(out, fingerprint, n_cells, n_fits):
    """(accumulators, chunks done) from ``out``, or a fresh start when it does not exist."""
    if out is None or not os.path.exists(out):
        return st.empty(n_cells, n_fits), 0
    with np.load(out, allow_pickle=False) as z:
        if str(z["fingerprint"]) != fingerprint:
            raise ValueError(
                f"out = {out!r} holds the state of a different sweep (grid, n_frames, n_traces, "
                "chunk_traces, models, methods, simulation method, gof_threshold or key "
                "differ); pass another out path or delete the file to start again")
        acc = {f: np.array(z["acc_" + f]) for f in st.PARAM_FIELDS + st.CELL_FIELDS}
        return acc, int(z["chunks_done"])


def _save_state(out, acc, chunks_done, fingerprint):
    tmp = out + ".partial"
    with open(tmp, "wb") as fh:  # a file handle: np.savez appends no second suffix
        np.savez(fh, fingerprint=np.asarray(fingerprint), chunks_done=np.asarray(chunks_done),
                 **{"acc_" + f: v for f, v in acc.items()})
    os.replace(tmp, out)  # atomic: an interruption never leaves a torn state file


def _unit(grid, g, c, key, models, methods: Sequence[Method], truth, cfg):
    """Statistics (fields of ``_stats.empty`` for one cell, shape (models x methods, ...),
    model-major) of chunk ``c`` of cell ``g``."""
    p = grid.cell(g)
    x = simulate(p["k"], p["gamma"], p["exposure"], p["frame_interval"], cfg["n_frames"],
                 key=jr.fold_in(jr.fold_in(key, g), c), temperature=p["temperature"],
                 n_traces=cfg["chunk"], method=cfg["method"], tracking_std=p["tracking_std"],
                 injections=p["injections"], dtype=np.float64, shard=cfg["shard"])
    y = np.asarray(x, dtype=np.float64).reshape(cfg["chunk"], cfg["n_frames"])
    extra = {} if cfg["gof_threshold"] is None else {"gof_threshold": cfg["gof_threshold"]}
    rows = []
    for model in models:
        for m in methods:
            b = calibrate_batch(y, frame_interval=p["frame_interval"], exposure=p["exposure"],
                                temperature=p["temperature"], model=model,
                                n_blocks=m.blocks(p, cfg["n_frames"]), **extra)
            rows.append(st.chunk_stats(b, {n: truth[n][g] for n in st.FITTED}))
    return {f: np.stack([r[f] for r in rows]) for f in rows[0]}


def _gather(local, n_cells, n_proc):
    """Per-cell statistics of every process, in cell order (cell ``g`` ran on process
    ``g % n_proc`` as its local item ``g // n_proc``)."""
    if n_proc == 1:
        return {f: v[:n_cells] for f, v in local.items()}
    from jax.experimental import multihost_utils

    full = multihost_utils.process_allgather(local)  # (processes, local cells, ...)
    out = {}
    for f, v in full.items():
        v = np.asarray(v)
        out[f] = np.swapaxes(v, 0, 1).reshape((-1,) + v.shape[2:])[:n_cells]
    return out


def _check_same_start(chunks_done, n_proc):
    if n_proc == 1:
        return
    from jax.experimental import multihost_utils

    done = np.asarray(multihost_utils.process_allgather(np.asarray(chunks_done)))
    if np.any(done != done.flat[0]):
        raise RuntimeError(f"the processes found different sweep states in out ({done.tolist()} "
                           "chunks done): out must be one file on a filesystem every process sees")


@float64_scope
def sweep(
    grid: Mapping,
    *,
    n_frames: int,
    n_traces: int,
    key,
    models: Sequence = ("standard",),
    methods: Sequence[str] | None = None,
    n_blocks: int | None = None,
    method: str = "exact_frames",
    chunk_traces: int | None = None,
    gof_threshold: float | None = None,
    out: str | os.PathLike | None = None,
    progress: bool = True,
    callback: Callable[[int, int], None] | None = None,
) -> SweepResult:
    r"""Simulate and calibrate over a parameter grid; labelled bias, SD, SE and coverage.

    For every cell of `grid`, `n_traces` recordings of `n_frames` frames are simulated with
    :func:`blurtrap.simulate` and calibrated with :func:`blurtrap.calibrate_batch` for each
    model in `models` and each calibration method in `methods` (every model and method fits
    the same recordings). Per cell, model and method the result holds, over the items with
    status ``"ok"``: the mean of k, gamma and eps^2, the bias [%] from the true value, the SD,
    the mean SE, SD/SE, the coverage of the 95 % Wald interval ``|x - x_true| <= 1.96 SE``,
    and the count of items by status.

    **Bounded memory, progress and resumption.** Trajectories are processed in chunks of
    `chunk_traces` per cell and reduced on the fly (numerically stable pairwise update of the
    mean and sum of squares); memory is O(chunk_traces x n_frames), whatever `n_traces`.
    A tqdm bar shows the progress. With `out` (an ``.npz`` path) the reduced state is written
    (atomically) after every chunk; calling ``sweep`` again with the same arguments resumes
    from it, and the result equals an uninterrupted run bit for bit.

    **Devices and processes.** Chunk ``c`` of cell ``g`` always uses the key
    ``fold_in(fold_in(key, g), c)``, and statistics are merged in chunk order, so the result
    does not depend on where the units ran. In one process, ``simulate`` shards the
    trajectories of a chunk over the local devices (when `chunk_traces` is a multiple of
    their number). After ``jax.distributed.initialize(...)``, every process runs the same
    ``sweep`` call on its share of the cells (cell ``g`` on process ``g % process_count``);
    the reduced statistics of each chunk are gathered with
    ``jax.experimental.multihost_utils.process_allgather``, every process returns the whole
    result, and process 0 writes `out` (which must then be on a shared filesystem).

    **Arguments:**

    - `grid`: mapping of parameter name -> a number (fixed) or a 1-D sequence (an axis of
      the grid, in the mapping's order). Names (SI units): ``k`` [N/m]; ``gamma`` [N s/m]
      or ``radius`` [m] (Stokes friction ``6 pi eta r``, eta from ``viscosity`` [Pa s] or
      water at the temperature); ``exposure`` W [s]; ``frame_interval`` dt [s];
      ``tracking_std`` eps [m] (default 0); ``temperature`` [K] (default 295). Optionally
      ``injections``: a mapping label -> tuple of simulate injections (an axis of effects,
      e.g. ``{"none": (), "drift": (RandomWalkDrift(1e-9),)}``).
    - `n_frames`: frames per recording (int >= 16).
    - `n_traces`: recordings per cell (int >= 1, a multiple of `chunk_traces`).
    - `key`: JAX PRNG key (keyword-only, required).
    - `models`: sequence of models for :func:`calibrate_batch` (names such as ``"naive"``,
      ``"blur"``, ``"standard"`` or TrapModels); a ``model`` axis is appended to the grid.
    - `methods`: sequence of calibration methods (default ``("whittle",)``); a ``method``
      axis is appended after ``model``. ``"whittle"``: the Whittle likelihood of the whole
      record (``calibrate_batch(..., n_blocks=1)``); ``"psd"``: the blocked-PSD likelihood
      with the default block count of ``calibrate(method="psd")`` evaluated at the cell's
      true tau = gamma/k (``min(128, N // 64, N dt / (100 tau))`` blocks, at least 1, rounded
      down to a power of two; the count used is the statistic ``n_blocks``); ``"psd:B"``:
      the blocked PSD with B >= 2 blocks (at least 8 frames each) in every cell.
    - `n_blocks`: the older way to choose one method: 1 means ``methods=("whittle",)``,
      B > 1 ``methods=("psd:B",)``; give `methods` or `n_blocks`, not both.
    - `method`: simulation method (default ``"exact_frames"``: exact, O(1) per frame).
    - `chunk_traces`: recordings per chunk; default the largest divisor of `n_traces` <= 64.
    - `gof_threshold`: passed to :func:`calibrate_batch` (``None``: its default). Items whose
      goodness of fit falls below it are ``"inadequate"`` and not in the statistics; pass
      ``0.0`` to keep every converged fit (to measure how wrong a too-simple model is).
    - `out`: path of the ``.npz`` state file (written after each chunk; resumed from).
    - `progress`: show a tqdm progress bar (process 0 only).
    - `callback`: called as ``callback(chunks_done, n_chunks)`` after each chunk (after
      `out` was written); an exception raised there stops the sweep, which can be resumed.

    **Returns:** :class:`SweepResult` with axes the grid's, then ``model``, then ``method``
    (``.coords``, ``.data``, ``to_dataframe()``, ``to_xarray()``, ``summary()``, ``plot()``).
    """
    g = make_grid(grid)
    n_frames = _count("n_frames", n_frames, 16)
    n_traces = _count("n_traces", n_traces)
    chunk = _chunk(n_traces, chunk_traces)
    names = _model_names(models)
    meths = parse_methods(methods, n_blocks, n_frames)
    key = _as_key(key)
    if out is not None:
        out = os.fspath(out)
        if not out.endswith(".npz"):
            raise ValueError(f"out must be a path ending in .npz; got out = {out!r}")
    n_chunks = n_traces // chunk
    n_proc, me = jax.process_count(), jax.process_index()
    cfg = {"n_frames": n_frames, "chunk": chunk, "method": method,
           "gof_threshold": gof_threshold, "shard": "auto" if n_proc == 1 else False}
    fp = _fingerprint(g, n_frames=n_frames, n_traces=n_traces, chunk=chunk, models=names,
                      methods=[m.name for m in meths], method=method,
                      gof_threshold=gof_threshold, key=np.asarray(jr.key_data(key)).tolist())
    acc, done = _load_state(out, fp, g.n_cells, len(names) * len(meths))
    _check_same_start(done, n_proc)
    truth = truths(g)
    mine = list(range(me, g.n_cells, n_proc))
    n_local = -(-g.n_cells // n_proc)
    bar = _bar(progress and me == 0, n_chunks * g.n_cells, done * g.n_cells)
    try:
        for c in range(done, n_chunks):
            local = {f: np.zeros((n_local,) + v.shape[1:]) for f, v in acc.items()}
            for i, cell in enumerate(mine):
                for f, v in _unit(g, cell, c, key, models, meths, truth, cfg).items():
                    local[f][i] = v
                if bar is not None:  # the cells of this round on all processes
                    bar.update(min(n_proc, g.n_cells - i * n_proc))
            acc = st.merge(acc, _gather(local, g.n_cells, n_proc))
            done = c + 1
            if out is not None and me == 0:
                _save_state(out, acc, done, fp)
            if callback is not None:
                callback(done, n_chunks)
    finally:
        if bar is not None:
            bar.close()
    data = st.summarise(acc, truth)
    blocks = np.array([[m.blocks(g.cell(i), n_frames) for m in meths] for i in range(g.n_cells)])
    data["n_blocks"] = np.repeat(blocks[:, None, :], len(names), axis=1).reshape(g.n_cells, -1)
    return SweepResult.from_stats(g, names, [m.name for m in meths], data, attrs={
        "n_frames": n_frames, "n_traces": n_traces, "chunk_traces": chunk,
        "chunks_done": done, "n_chunks": n_chunks, "simulate_method": method,
        "processes": n_proc})


def _bar(show, total, initial):
    if not show:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc="sweep", unit="cell-chunk")
