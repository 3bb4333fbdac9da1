r"""Brownian dynamics of a trapped bead with in-loop exposure averaging: :func:`simulate`."""

from __future__ import annotations

import functools
import math
import sys
import time
import warnings
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jax import lax
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ..physics import BOLTZMANN, DEFAULT_TEMPERATURE
from . import _coeffs as co
from ._core import CoreConfig, buffer_traces, jitter_normals, run_chunk_jit
from ._injections import (
    AbstractInjection,
    HydrodynamicFriction,
    PhotodiodeFilter,
    TimingJitter,
)
from ._instruments import Sensitivity, StageDrive, check_drives, drive_frames
from ._labelled import label_frames
from ._linear import simulate_photodiode
from ._spectral import simulate_spectral

_METHODS = ("exact", "euler", "exact_frames", "spectral")
_AUTO_BIAS = 1e-3  # target relative variance bias when substeps=None


class SubstepBiasWarning(RuntimeWarning):
    """The substep size is too coarse for the requested accuracy (``bias_tol``)."""


class ExposureWindows:
    """Several exposure windows recorded from one trajectory in one run.

    All windows start at the frame start; window ``j`` averages over ``[0, durations[j]]``.
    Passing ``exposure=ExposureWindows([W1, W2, ...])`` to :func:`simulate` adds a windows axis
    (in the given order) just before the traces axis. This is how the variance-vs-exposure curve
    of Wong & Halvorsen (2006), Fig. 1a, is obtained from a single simulation.

    - `durations`: 1-D sequence of distinct exposure times [s], each > 0.
    """

    def __init__(self, durations: Sequence[float]):
        d = np.asarray(durations, dtype=np.float64)
        if d.ndim != 1 or d.size < 1:
            raise ValueError(
                f"ExposureWindows needs a non-empty 1-D sequence of durations; got shape {d.shape}"
            )
        if not (np.all(np.isfinite(d)) and np.all(d > 0)):
            raise ValueError(f"exposure window durations must be finite and > 0 s; got {d!r} s")
        if np.unique(d).size != d.size:
            raise ValueError(f"exposure window durations must be distinct; got {d!r} s")
        self.durations = d

    def __repr__(self):
        return f"ExposureWindows({self.durations.tolist()!r})"


def _concrete(name, value, unit):
    if isinstance(value, jax.core.Tracer):  # pyright: ignore[reportAttributeAccessIssue]
        raise ValueError(
            f"simulate needs concrete parameter values (it sets loop lengths from them); "
            f"{name} [{unit}] is traced. Call simulate outside jit/vmap/grad; it is vectorised "
            "over parameter grids by broadcasting instead."
        )
    arr = np.asarray(value, dtype=np.float64)
    return arr


def _positive(name, value, unit, what):
    arr = _concrete(name, value, unit)
    bad = ~(np.isfinite(arr) & (arr > 0))
    if bad.any():
        raise ValueError(
            f"{name} ({what}) must be finite and > 0 {unit}; got {name} = "
            f"{arr[bad].ravel()[0]:.6g} {unit}"
        )
    return arr


def _nonnegative(name, value, unit, what):
    arr = _concrete(name, value, unit)
    bad = ~(np.isfinite(arr) & (arr >= 0))
    if bad.any():
        raise ValueError(
            f"{name} ({what}) must be finite and >= 0 {unit}; got {name} = "
            f"{arr[bad].ravel()[0]:.6g} {unit}"
        )
    return arr


def _count(name, value, minimum=1):
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {name} = {value!r}")
    return int(value)


def _as_keys(key):
    if key is None:
        raise ValueError(
            "key must be a JAX PRNG key, e.g. key=jax.random.key(0); got key=None "
            "(simulate never falls back to a hidden global seed)"
        )
    key = jnp.asarray(key)
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key
    if key.dtype == jnp.uint32 and key.ndim >= 1 and key.shape[-1] == 2:
        return jr.wrap_key_data(key)
    raise ValueError(
        f"key must be a JAX PRNG key (jax.random.key(seed)); got an array of dtype {key.dtype} "
        f"and shape {key.shape}"
    )


def _resolve_dtype(dtype):
    if dtype is None:
        dtype = jnp.result_type(float)
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be float32 or float64; got dtype = {dt.name}")
    if dt == np.float64 and not jax.config.jax_enable_x64:  # pyright: ignore[reportAttributeAccessIssue]
        raise ValueError(
            "dtype = float64 needs 64-bit JAX: call blurtrap.enable_x64() first, or pass "
            "dtype=jnp.float32"
        )
    return dt


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


def _progress(done, total, t0, stream):
    width = 30
    filled = int(width * done / total)
    elapsed = time.perf_counter() - t0
    stream.write(
        f"\rsimulate [{'#' * filled}{'.' * (width - filled)}] chunk {done}/{total} "
        f"{elapsed:7.1f} s"
    )
    if done == total:
        stream.write("\n")
    stream.flush()


_CHUNK_STEPS = 16


def _balanced_chunk(total: int, max_chunk: int) -> int:
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
def _start(keys, n_traces, dtype, buf_shape):
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


def _special_frames(method, photodiode, hydro, kf, gf, dtf, tf, wf, tau, n, n_traces, dtype,
                    k_init, k_frames):
    """Frames (G, T, n) in units of sigma from the exact photodiode system or the spectral
    sampler (dimensionless: times in tau, frequencies in 1/tau)."""
    from ..physics import water_density, water_viscosity

    g_n = kf.shape[0]
    if method == "exact_frames":  # photodiode filter, exact joint linear system
        lam = np.full(g_n, 2.0 * np.pi * photodiode.f3db) * tau
        alpha = np.full(g_n, photodiode.alpha)
        return simulate_photodiode(lam, alpha, wf / tau, np.maximum(dtf - wf, 0.0) / tau, n,
                                   n_traces, dtype, k_init, k_frames)
    p = {"w": wf / tau}
    if photodiode is not None:
        p["f3db"] = np.full(g_n, photodiode.f3db) * tau
        p["alpha"] = np.full(g_n, photodiode.alpha)
    if hydro is not None:
        eta = (np.asarray(water_viscosity(tf), dtype=np.float64) if hydro.viscosity is None
               else np.full(g_n, hydro.viscosity))
        rho = (np.asarray(water_density(tf), dtype=np.float64) if hydro.fluid_density is None
               else np.full(g_n, hydro.fluid_density))
        r = hydro.radius
        m_star = 4.0 / 3.0 * np.pi * r**3 * (hydro.bead_density + 0.5 * rho)
        p["f_nu"] = eta / (rho * np.pi * r**2) * tau
        p["f_m"] = gf / (2.0 * np.pi * m_star) * tau
        if hydro.distance is not None:
            p["x_wall"] = np.full(g_n, r / hydro.distance)
    return simulate_spectral(p, dtf / tau, n, n_traces, dtype, k_frames)


def simulate(
    k,
    gamma,
    exposure,
    frame_interval,
    n_frames: int,
    *,
    key,
    temperature=DEFAULT_TEMPERATURE,
    n_traces: int = 1,
    method: str = "exact",
    substeps: int | None = None,
    tracking_std=0.0,
    injections: Sequence = (),
    exposure_profile: Callable | None = None,
    force: Callable | None = None,
    force_params=None,
    burn_in_frames: int = 0,
    dtype=None,
    bias_tol: float = 0.05,
    chunk_frames: int | None = None,
    progress: bool = False,
    shard: bool | str = "auto",
    return_times: bool = False,
    unroll: int = 1,
    normal_dtype=None,
    labelled: bool = False,
):
    r"""Simulate blurred, sampled positions of a bead in an optical trap (Brownian dynamics).

    Frame ``n`` starts at ``n * frame_interval`` and reports the average of the position over
    ``[n dt, n dt + W]`` (``W = exposure <= frame_interval``); the trajectory starts in the
    stationary state. The statistics are those of DESIGN section 2: ``var = sigma2 S(alpha)``,
    ``C(n) = sigma2 B(alpha) rho^n`` with ``sigma2 = kT/k``, ``tau = gamma/k``,
    ``alpha = W/tau``, ``rho = exp(-dt/tau)``.

    Internally everything runs in units of ``sigma`` and ``tau`` (coefficients computed in
    float64 on the host) and the scans decay by increments, ``x' = x + (e^{-h} - 1) x + ...``,
    so ``dtype=float32`` keeps float32-relative accuracy even for steps ``h << tau``.

    **Methods:**

    - ``"exact"``: exact Ornstein-Uhlenbeck substeps ``x' = c x + sigma sqrt(1-c^2) z`` with
      ``c = exp(-h/tau)``; the exposure average is accumulated inside the substep loop with
      trapezoid weights (times an optional `exposure_profile`). The only error is the quadrature
      of the average, a relative variance bias of about ``-alpha/(6 n^2 S(alpha))``
      (``n`` = substeps per exposure); the dead time ``dt - W`` is one exact step.
    - ``"euler"``: Ermak-McCammon / Euler-Maruyama, ``x' = x + F(x) h/gamma + sqrt(2 D h) z``,
      for a general `force` ``F = force(x, force_params)`` [N] (default ``-k x``; see
      :func:`blurtrap.simulate.quartic_force`). Relative variance bias ``~ h/(2 tau)``. With a
      non-harmonic force use `burn_in_frames` (the start is drawn from the harmonic law).
    - ``"exact_frames"``: no substeps. Given the position ``x0`` at the frame start (units of
      sigma, tau; ``a = W/tau``), the end-of-exposure position ``x_a`` and the exposure
      average ``m`` are drawn from their exact joint Gaussian law,

      $$E[m|x_0] = x_0 \frac{\tau(1-e^{-a})}{W},\quad E[x_a|x_0] = e^{-a}x_0,$$
      $$\mathrm{var}(m|x_0) = S(a) - \Big(\tfrac{1-e^{-a}}{a}\Big)^2,\quad
        \mathrm{var}(x_a|x_0) = 1-e^{-2a},\quad
        \mathrm{cov}(x_a, m|x_0) = \frac{(1-e^{-a})^2}{a},$$

      followed by an exact OU step over the dead time ``dt - W``. Several windows are drawn
      segment by segment (between consecutive window ends) with the same law. Exact at any
      ``dt``, ``W``; cost O(1) per frame. With a scalar exposure (not
      :class:`ExposureWindows`) and regular frames (no :class:`TimingJitter`) the same law is
      drawn with one normal per frame instead of two, from the frames' exact ARMA(1,1)
      innovations form: with ``c = exp(-dt/tau)``, ``X_m = xh_m + e_m``,
      ``xh_{m+1} = c xh_m + (c + b) e_m``, ``e_m ~ N(0, s^2)``, and ``xh_0`` drawn from its
      stationary law; ``b`` and ``s^2`` follow from ``C(0)`` and ``C(1)``
      (``blurtrap.simulate._coeffs``, derivation there). Chunks then have even
      lengths (`chunk_frames` is rounded up). With a :class:`PhotodiodeFilter` injection the
      position and the detector's filter state are advanced together as one exact linear
      Gaussian system (``blurtrap.simulate._linear``).
    - ``"spectral"``: stationary Gaussian frames drawn from their exact discrete PSD (folded
      continuous PSD times ``sinc^2(f W)`` and an optional photodiode ``|H|^2``) by circulant
      embedding on ``2 n_frames`` points (``blurtrap.simulate._spectral``: assumptions and
      accuracy there). Needed for :class:`HydrodynamicFriction` (frequency-dependent
      friction has no Markovian form in x); harmonic trap, one exposure window, no
      timing jitter. Cost O(n log n) per trace.

    **Arguments:** (SI units; `k`, `gamma`, `exposure`, `frame_interval`, `temperature` and
    `tracking_std` broadcast together to a grid shape ``G``)

    - `k`: trap stiffness [N/m] (> 0).
    - `gamma`: friction coefficient [N s/m] (> 0), e.g. ``6 pi eta r``.
    - `exposure`: exposure time W [s] (``0 < W <= frame_interval``), or
      :class:`ExposureWindows` for several windows on one trajectory (extra output axis).
    - `frame_interval`: time between frame starts dt [s] (> 0).
    - `n_frames`: number of frames per trace (int >= 1).
    - `key`: JAX PRNG key (keyword-only, required). A single key gives every grid point the
      same underlying random numbers (common random numbers: a grid call equals the individual
      calls with that key, except that loop lengths are static and shared by the grid: euler's
      dead-time substep count and ``substeps=None`` follow the most demanding grid point);
      an array of keys broadcastable to ``G`` gives each grid point its own stream.
    - `temperature`: T [K] (> 0).
    - `n_traces`: independent trajectories per grid point (int >= 1).
    - `method`: ``"exact"``, ``"euler"``, ``"exact_frames"`` or ``"spectral"``.
    - `substeps`: substeps per exposure (per longest window with :class:`ExposureWindows`);
      ``None`` picks the smallest count with estimated relative variance bias <= 1e-3,
      rounded up to the next power of two (at least 4): the count is a static scan length,
      so rounding lets parameter values within a factor ~2 (exact: ~4 in alpha, the count
      grows like sqrt(alpha)) share one compiled kernel; the bias only gets smaller.
      Not used by ``"exact_frames"`` and ``"spectral"``.
    - `tracking_std`: white tracking noise std eps [m] (>= 0); same as
      ``injections=(TrackingNoise(eps),)`` but broadcast over the grid.
    - `injections`: tuple of :class:`AbstractInjection` (applied after the scan, in order, each
      with its own key), at most one :class:`TimingJitter` (applied in the loop), at most one
      :class:`PhotodiodeFilter` (``"exact_frames"`` or ``"spectral"``), at most one
      :class:`HydrodynamicFriction` (``"spectral"``), any number of :class:`StageDrive`
      (sinusoidal stage drive: its exact response, blurred over the exposure, is added to the
      frames; ``mode="fluid"`` or ``"additive"``, see ``blurtrap.simulate._instruments``) and
      at most one :class:`Sensitivity` (applied last: the output is then in volts).
    - `exposure_profile`: callable ``p(u)``, ``u = t/W`` in [0, 1], weighting the exposure
      (e.g. :class:`TrapezoidProfile`, :class:`ExponentialProfile`); substep methods and a
      single window only.
    - `force`, `force_params`: see ``"euler"``. `force` must be elementwise in `x`.
    - `burn_in_frames`: frames simulated and discarded before the first returned frame
      (unnecessary for the exact samplers, which start in the stationary state).
    - `dtype`: ``float32`` or ``float64`` (default: JAX's default float).
    - `bias_tol`: warn (:class:`SubstepBiasWarning`) when the estimated relative variance bias
      of the substep scheme exceeds this (default 0.05, i.e. ``h/tau > 0.1`` for euler).
    - `chunk_frames`: frames per compiled chunk (default: about 4 M substep-trajectories per
      chunk; ``"exact_frames"``: 32 M frame-trajectories, or 2 M with `progress`). Long runs
      (1e9 substeps) run chunk by chunk in bounded memory: the chunks are placed into one
      output buffer in place, so memory is the output plus one chunk.
    - `progress`: print a text progress bar to stderr, updated once per chunk.
    - `shard`: ``"auto"`` (default) shards the traces axis across all local devices when there
      are several and ``n_traces`` is a multiple of their number; ``True`` requires it;
      ``False`` never shards.
    - `return_times`: also return the frame start times [s] (jittered with
      :class:`TimingJitter`), broadcastable to the positions.
    - `unroll`: unroll factor of the inner substep scan (performance only).
    - `normal_dtype`: dtype in which the thermal normals are drawn (default: `dtype`).
      ``jnp.float32`` with ``dtype=float64`` is ~2.4x faster on CPU (threefry float64 normals
      cost ~20 ns each); the normals then have float32 resolution (tails truncated near
      5.3 sigma, a ~1e-6 relative effect on variances) while the dynamics stay float64.
    - `labelled`: return a :class:`~blurtrap.simulate.LabelledFrames` instead: the same
      positions (``.values``) with named axes (each grid axis named after the parameter that
      varies along it alone, e.g. ``("k", "exposure", "trace", "frame")``), the parameters
      as coordinates (``.coords``), the times (``.times``, with `return_times`) and
      ``to_xarray()``.

    **Returns:** positions [m] of shape ``(*G, n_traces, n_frames)``, or
    ``(*G, n_windows, n_traces, n_frames)`` with :class:`ExposureWindows`; with
    ``return_times=True`` a tuple ``(positions, times)``; with ``labelled=True`` a
    :class:`~blurtrap.simulate.LabelledFrames`.

    **Raises:** ``ValueError`` naming the parameter for non-positive or non-finite parameters,
    ``exposure > frame_interval``, ``n_frames < 1``, ``key=None``, an unknown method, or
    options that do not apply to the method. Warns :class:`SubstepBiasWarning` for too coarse
    substeps.

    **Devices and multi-host runs:** the traces axis is sharded with ``jax.sharding`` over the
    local devices (GPUs, or CPU devices forced with
    ``XLA_FLAGS=--xla_force_host_platform_device_count=N``). On several hosts, call
    ``jax.distributed.initialize()`` (coordinator address, number of processes and process id,
    or auto-detected on SLURM/TPU) on every host before anything else and give each process
    its own key, e.g. ``jax.random.fold_in(key, jax.process_index())``; each process then
    simulates its own traces on its local devices and writes its own output (the trajectories
    are independent, so no cross-host communication is needed).

    **References:** Wong & Halvorsen, Opt. Express 14, 12517 (2006), eqs. (6)-(7) and
    Ermak-McCammon scheme (section 5); Norrelykke & Flyvbjerg, Phys. Rev. E 83, 041103 (2011)
    for the exact OU update.
    """
    keys = _as_keys(key)
    if method not in _METHODS:
        raise ValueError(f"method must be one of {_METHODS}; got method = {method!r}")
    n_frames = _count("n_frames", n_frames)
    n_traces = _count("n_traces", n_traces)
    burn_in_frames = _count("burn_in_frames", burn_in_frames, 0)
    unroll = _count("unroll", unroll)
    dtype = _resolve_dtype(dtype)

    k_ = _positive("k", k, "N/m", "trap stiffness")
    g_ = _positive("gamma", gamma, "N s/m", "friction coefficient")
    dt_ = _positive("frame_interval", frame_interval, "s", "frame interval dt")
    t_ = _positive("temperature", temperature, "K", "absolute temperature")
    eps_ = _nonnegative("tracking_std", tracking_std, "m", "tracking-error std")
    windows = isinstance(exposure, ExposureWindows)
    if windows:
        wins = exposure.durations
        w_ = np.asarray(wins.max())
    else:
        w_ = _positive("exposure", exposure, "s", "exposure time W")
    shape = np.broadcast_shapes(k_.shape, g_.shape, dt_.shape, t_.shape, eps_.shape, w_.shape)
    bad = np.broadcast_to(w_, shape) > np.broadcast_to(dt_, shape) * (1 + 1e-12)
    if bad.any():
        ww = np.broadcast_to(w_, shape)[bad].ravel()[0]
        dd = np.broadcast_to(dt_, shape)[bad].ravel()[0]
        raise ValueError(
            f"exposure must be <= frame_interval; got exposure = {ww:.6g} s with "
            f"frame_interval = {dd:.6g} s (is the exposure in ms instead of s?)"
        )

    # --- injections --------------------------------------------------------------------
    jitters = [inj for inj in injections if isinstance(inj, TimingJitter)]
    diodes = [inj for inj in injections if isinstance(inj, PhotodiodeFilter)]
    hydros = [inj for inj in injections if isinstance(inj, HydrodynamicFriction)]
    drives = [inj for inj in injections if isinstance(inj, StageDrive)]
    sens = [inj for inj in injections if isinstance(inj, Sensitivity)]
    additive = [inj for inj in injections
                if not isinstance(inj, (TimingJitter, PhotodiodeFilter, HydrodynamicFriction,
                                        StageDrive, Sensitivity))]
    for inj in additive:
        if not isinstance(inj, AbstractInjection):
            raise ValueError(
                "injections must be AbstractInjection, TimingJitter, PhotodiodeFilter, "
                f"HydrodynamicFriction, StageDrive or Sensitivity objects; got {inj!r}"
            )
    check_drives(drives, sens, hydros[0] if hydros else None, force, exposure_profile)
    for name, found in (("TimingJitter", jitters), ("PhotodiodeFilter", diodes),
                        ("HydrodynamicFriction", hydros)):
        if len(found) > 1:
            raise ValueError(f"at most one {name} may be given in injections")
    jitter = bool(jitters) and float(np.max(np.asarray(jitters[0].std))) > 0
    photodiode = diodes[0] if diodes else None
    hydro = hydros[0] if hydros else None
    special = method == "spectral" or photodiode is not None
    if hydro is not None and method != "spectral":
        raise ValueError(
            "HydrodynamicFriction (frequency-dependent friction) has no Markovian simulation in "
            f"the position alone: use method='spectral'; got method = {method!r}"
        )
    if photodiode is not None and method not in ("exact_frames", "spectral"):
        raise ValueError(
            "PhotodiodeFilter needs method='exact_frames' (exact joint linear system) or "
            f"'spectral'; got method = {method!r}"
        )
    if special:
        what = f"method={method!r}" if method == "spectral" else "PhotodiodeFilter"
        if windows:
            raise ValueError(f"{what} supports a single exposure window, not ExposureWindows")
        if jitter:
            raise ValueError(f"{what} does not support TimingJitter (regular frames only)")
        if method == "spectral" and substeps is not None:
            raise ValueError("substeps is not used by method='spectral' (it has none); got "
                             f"substeps = {substeps!r}")
        if method == "spectral" and exposure_profile is not None:
            raise ValueError("exposure_profile needs a substep method ('exact' or 'euler')")

    if method == "exact_frames":
        if substeps is not None:
            raise ValueError(
                f"substeps is not used by method='exact_frames' (it has none); got "
                f"substeps = {substeps!r}"
            )
        if exposure_profile is not None:
            raise ValueError("exposure_profile needs a substep method ('exact' or 'euler')")
    if force is not None and method != "euler":
        raise ValueError(f"force needs method='euler'; got method = {method!r}")
    if exposure_profile is not None and windows:
        raise ValueError("exposure_profile supports a single exposure window only")

    # --- dimensionless grid -------------------------------------------------------------
    G = int(np.prod(shape, dtype=np.int64))
    flat = lambda a: np.broadcast_to(a, shape).reshape(G).astype(np.float64)  # noqa: E731
    kf, gf, dtf, tf, epsf = flat(k_), flat(g_), flat(dt_), flat(t_), flat(eps_)
    sigma = np.sqrt(BOLTZMANN * tf / kf)
    tau = gf / kf
    if windows:
        order = np.argsort(wins)
        ends = wins[order]
        seg_len_s = np.diff(np.concatenate([[0.0], ends]))  # [s], (m,)
        L = seg_len_s[None, :] / tau[:, None]  # (G, m)
        n_seg = n_win = wins.size
        a_win = ends[None, :] / tau[:, None]  # sorted windows, dimensionless
        w_max = np.full(G, ends[-1])
    else:
        order = np.zeros(1, dtype=np.int64)
        wf = flat(w_)
        L = (wf / tau)[:, None]
        n_seg = n_win = 1
        a_win = L.copy()
        w_max = wf
    rdead = (dtf - w_max) / tau
    rdead = np.maximum(rdead, 0.0)

    if not special:
        P = {"rdead": rdead}
        innovations = method == "exact_frames" and not windows and not jitter
        if innovations:  # one normal per frame (see _coeffs.innovations_law)
            P["icm1"], P["icb"], P["is"], P["ix"] = co.innovations_law(
                L[:, 0], np.maximum(dtf / tau, L[:, 0]))
            n_exp, n_dead = 0, 1
        elif method == "exact_frames":
            em1, p, sm, cx, sx = co.segment_law(L)
            P.update(em1=em1, p=p, sm=sm, cx=cx, sx=sx)
            # window j (sorted) = sum_{s <= j} L_s m_s / a_j
            M = np.where(
                np.arange(n_seg)[:, None] <= np.arange(n_win)[None, :],
                L[:, :, None] / a_win[:, None, :],
                0.0,
            )
            P["M"] = M[:, :, np.argsort(order)]  # back to the user's window order
            n_exp, n_dead = 0, 1
        else:
            if substeps is None:
                a_max = float(a_win[:, -1].max())
                if method == "exact":
                    n_tot = math.ceil(math.sqrt(a_max / (6 * _AUTO_BIAS * float(co.s_blur(a_max)))))
                else:
                    n_tot = math.ceil(a_max / (2 * _AUTO_BIAS))
                # next power of two (the bias only gets smaller): nearby parameter values
                # share the static scan length, so new values seldom recompile
                n_tot = 1 << (max(n_tot, 4) - 1).bit_length()
            else:
                n_tot = _count("substeps", substeps)
            if windows:
                seg_n = [max(1, round(n_tot * s / ends[-1])) for s in seg_len_s]
            else:
                seg_n = [n_tot]
            n_exp = int(sum(seg_n))
            h = np.concatenate([np.repeat(L[:, j : j + 1] / seg_n[j], seg_n[j], axis=1) for j in range(n_seg)], axis=1)
            # trapezoid weights of each window over the grid points 0..n_exp
            cum = np.cumsum(seg_n)
            Wt = np.zeros((G, n_exp + 1, n_win))
            for j in range(n_win):
                hj = h[:, : cum[j]]
                Wt[:, : cum[j], j] += hj / 2
                Wt[:, 1 : cum[j] + 1, j] += hj / 2
            if exposure_profile is not None:
                u = np.concatenate([np.zeros((G, 1)), np.cumsum(h, axis=1)], axis=1) / L[:, :1]
                prof = np.asarray(exposure_profile(u), dtype=np.float64)
                if prof.shape != u.shape or not np.all(np.isfinite(prof)) or np.any(prof < 0):
                    raise ValueError(
                        "exposure_profile(u) must return finite weights >= 0 of u's shape"
                    )
                Wt = Wt * prof[:, :, None]
            norm = Wt.sum(axis=1, keepdims=True)
            if np.any(norm <= 0):
                raise ValueError("exposure_profile has zero total weight over the exposure")
            Wt = Wt / norm
            P["Wt"] = Wt[:, :, np.argsort(order)]
            if method == "exact":
                P["A"], P["B"] = co.ou_step(h)  # A = exp(-h) - 1: updates by increments
                n_dead = 1
                bias = co.trapezoid_bias(a_win, cum[None, :])
            else:
                P["A"], P["B"] = h, np.sqrt(2.0 * h)
                hmax = h.max(axis=1)
                n_dead = max(1, math.ceil(float(np.max(rdead / hmax)) - 1e-9)) if rdead.max() > 0 else 1
                bias = co.euler_bias(hmax)[:, None] + co.trapezoid_bias(a_win, cum[None, :])
                P["k"] = kf  # (sigma is P["scale"], set below)
            worst = float(np.max(bias))
            if worst > bias_tol:
                i = np.unravel_index(np.argmax(bias), bias.shape)
                hrel = float(np.max(h, axis=1)[i[0]])
                warnings.warn(
                    f"substeps = {n_tot} is too coarse for method={method!r}: h/tau = {hrel:.3g}, "
                    f"estimated relative bias of var(X_m) ~ {worst:.3g} > bias_tol = {bias_tol:g}; "
                    "increase substeps (or use method='exact_frames' for a harmonic trap)",
                    SubstepBiasWarning,
                    stacklevel=2,
                )
        if jitter:
            P["jstd"] = np.broadcast_to(np.asarray(jitters[0].std, np.float64), (G,)) / tau
        P["scale"] = sigma  # the frames are written in metres
        P = jax.device_put({name: np.asarray(v, dtype=dtype) for name, v in P.items()})

    # --- keys ----------------------------------------------------------------------------
    keys = jnp.broadcast_to(keys, shape).reshape(G) if keys.ndim else jnp.broadcast_to(keys, (G,))
    if special:
        k_init, k_frames, k_jit, k_inj, x, _ = _start(keys, n_traces, dtype.name, None)
        frames = _special_frames(method, photodiode, hydro, kf, gf, dtf, tf, wf, tau,
                                 burn_in_frames + n_frames, n_traces, dtype, k_init,
                                 k_frames)[..., burn_in_frames:][:, None]
        pos = frames * jnp.asarray(sigma, dtype)[:, None, None, None]
    else:
        mesh = _make_mesh(shard, n_traces)
        cfg = CoreConfig(
            method=method,
            n_exp=n_exp,
            n_dead=n_dead,
            n_seg=n_seg,
            n_win=n_win,
            jitter=jitter,
            force=force,
            dtype=dtype.name,
            mesh=mesh,
            unroll=unroll,
            normal_dtype=(dtype if normal_dtype is None else _resolve_dtype(normal_dtype)).name,
            innovations=innovations,
        )
        total = burn_in_frames + n_frames
        if chunk_frames is None:
            # substeps: ~4 M substep-trajectories of random numbers per chunk. exact_frames
            # needs O(G T) working memory whatever the chunk, so its chunks are only there to
            # bound one call's output (32 M frame-trajectories) and to feed the progress bar
            per_frame = G * n_traces * max(cfg.n_rows, 2)  # innovations: the same 32 M
            budget = 1 << (26 if method == "exact_frames" and not progress else 22)
            chunk = _balanced_chunk(total, max(1, budget // max(per_frame, 1)))
        else:
            chunk = min(_count("chunk_frames", chunk_frames), total)
        chunk += chunk % 2 if innovations else 0  # frames run in pairs
        n_chunks = -(-total // chunk)
        # each chunk comes out in the user's shape (reshapes inside the jitted chunk are free,
        # eager ones copy); several chunks are placed into one donated buffer; a partial last
        # chunk is computed in full (the default chunk keeps that waste small)
        n_buf = n_chunks * chunk
        t_buf = buffer_traces(cfg, n_traces)
        lead = tuple(shape) + ((n_win,) if windows else ())
        k_init, k_frames, k_jit, k_inj, x, buf = _start(
            keys, n_traces, dtype.name, lead + (t_buf, n_buf) if n_chunks > 1 else None)
        if innovations:  # the start is the stationary one-step predictor
            x = x * P["ix"][:, None]
        if jitter:
            delta = P["jstd"][:, None] * jitter_normals(k_jit, 0, n_traces, dtype)
        else:
            delta = jnp.zeros((G, 1), dtype)
        fp = force_params if force is not None else None
        dbuf = jnp.zeros((G, n_traces, n_buf), dtype) if jitter and n_chunks > 1 else None
        if mesh is not None:
            x = jax.device_put(x, NamedSharding(mesh, PartitionSpec(None, "traces")))
            if n_chunks > 1:  # the output buffer is split over the devices like the traces
                spec = PartitionSpec(*((None,) * len(lead) + ("traces", None)))
                buf = jax.device_put(buf, NamedSharding(mesh, spec))
                if jitter:
                    dbuf = jax.device_put(dbuf,
                                          NamedSharding(mesh, PartitionSpec(None, "traces")))
        t0 = time.perf_counter()
        for c in range(n_chunks):
            x, delta, out, dout = run_chunk_jit(
                cfg, chunk, lead, P, fp, k_frames, k_jit, x, delta, jnp.int32(c * chunk)
            )
            if n_chunks == 1:
                buf, dbuf = out, dout
            else:
                buf = _place(buf, out, c * chunk)
                if jitter:
                    dbuf = _place(dbuf, dout, c * chunk)
            if progress:
                jax.block_until_ready(x)
                _progress(c + 1, n_chunks, t0, sys.stderr)
        exact_fit = t_buf == n_traces and burn_in_frames == 0 and n_buf == n_frames
        pos = buf if exact_fit else buf[..., :n_traces, burn_in_frames:total]
        if jitter:
            dj = dbuf if exact_fit else dbuf[:, :n_traces, burn_in_frames:total]  # pyright: ignore
    out_shape = tuple(shape) + ((n_win,) if windows else ()) + (n_traces, n_frames)
    if jitter:
        n_idx = jnp.arange(n_frames, dtype=dtype)
        times = (n_idx * jnp.asarray(dtf, dtype)[:, None, None]
                 + dj * jnp.asarray(tau, dtype)[:, None, None])  # pyright: ignore[reportOptionalOperand]
    elif return_times or additive:
        times = jnp.broadcast_to(jnp.asarray(np.arange(n_frames) * dtf[:, None, None], dtype),
                                 (G, 1, n_frames))
    else:
        times = None  # not needed

    # --- additive injections (per grid point, each with its own key) ----------------------
    if additive or eps_.any():
        epsj = jnp.asarray(epsf, dtype)
        pos = pos.reshape(G, n_win, n_traces, n_frames)

        def inject(xg, tg, kg, eg):
            ks = jr.split(kg, len(additive) + 1)
            xg = xg + eg * jr.normal(ks[0], xg.shape, dtype)
            for i, inj in enumerate(additive):
                xg = inj.apply(xg, tg, ks[i + 1])
            return xg

        pos = jax.vmap(inject)(pos, times, k_inj, epsj)

    if drives:  # exact steady-state response, blurred over each exposure (_instruments)
        widths = np.broadcast_to(wins[None, :], (G, n_win)) if windows else wf[:, None]
        pos = pos.reshape(G, n_win, n_traces, n_frames) + drive_frames(
            drives, kf, gf, widths, dtf, n_frames, times if jitter else None, photodiode,
            dtype)  # pyright: ignore[reportOperatorIssue]
    if sens:
        pos = pos / sens[0].rd.astype(dtype)
    if pos.shape != out_shape:
        pos = pos.reshape(out_shape)
    if return_times:
        tshape = tuple(shape) + ((1,) if windows else ()) + (times.shape[-2], n_frames)  # pyright: ignore
        times = times.reshape(tshape)  # pyright: ignore[reportOptionalMemberAccess]
    if labelled:
        return label_frames(pos, {"k": k_, "gamma": g_, "exposure": w_, "frame_interval": dt_,
                                  "temperature": t_, "tracking_std": eps_}, shape,
                            wins if windows else None, times if return_times else None)
    return (pos, times) if return_times else pos
