r"""Brownian dynamics of a trapped bead with in-loop exposure averaging: :func:`simulate`.

:func:`simulate` checks its arguments (``_validate``), builds the dimensionless grid
(``_exposure``) and hands it to the method's sampler: the frame scan for ``"exact"``,
``"euler"`` and ``"exact_frames"`` (coefficients: ``_scan_coefs``; chunked run: ``_scan_run``;
the jitted scan: ``_core``), or the photodiode / spectral samplers (``_special``); then adds
the injections and shapes the output (``_finish``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax.numpy as jnp

from ..physics import DEFAULT_TEMPERATURE
from ._exposure import ExposureWindows, make_grid
from ._finish import add_injections, frame_times, shape_output
from ._injections import from_effects
from ._scan_coefs import SubstepBiasWarning as SubstepBiasWarning
from ._scan_coefs import scan_plan
from ._scan_run import run_scan
from ._special import run_special
from ._validate import (
    METHODS,
    as_keys,
    check_method_options,
    check_params,
    count,
    resolve_dtype,
    sort_injections,
)


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
    effects: Sequence = (),
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
    - `effects`: effect objects of :mod:`blurtrap.effects` with their values, e.g.
      ``[bt.effects.Drift(drift_diffusion=2e-16), bt.effects.TrackingNoise(tracking_var=...)]``:
      each becomes its injection (``effect.to_injection()``), appended after `injections` in
      order, so the same object can be simulated here and tested by ``diagnose``.
      ``ExposureKernel(rise_fraction=r)`` sets the exposure profile (``TrapezoidProfile(r)``;
      not together with `exposure_profile`); ``MotionBlur()`` and ``Aliasing()`` are accepted
      and change nothing (the frames always average over `exposure` and are sampled every
      `frame_interval`: they are the detector's properties). Effects that cannot be simulated
      (``power_offset``, ``laser_heating``, ``anharmonicity``) or whose value is ``None`` raise
      a ``ValueError`` naming the effect.
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
    - `progress`: a tqdm progress bar (stderr, or a widget in notebooks), one step per chunk.
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
    keys = as_keys(key)
    from_eff, exposure_profile = from_effects(effects, exposure_profile)
    injections = (*injections, *from_eff)
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got method = {method!r}")
    n_frames = count("n_frames", n_frames)
    n_traces = count("n_traces", n_traces)
    burn_in_frames = count("burn_in_frames", burn_in_frames, 0)
    unroll = count("unroll", unroll)
    dtype = resolve_dtype(dtype)
    windows = isinstance(exposure, ExposureWindows)
    p = check_params(k, gamma, exposure, frame_interval, temperature, tracking_std,
                     exposure.durations if windows else None)  # pyright: ignore
    inj = sort_injections(injections, force, exposure_profile)
    special = check_method_options(method, inj, windows, substeps, exposure_profile, force)

    g = make_grid(p)
    plan = None if special else scan_plan(method, g, inj.jitter, substeps, exposure_profile,
                                          bias_tol, dtype, stacklevel=2)
    keys = (jnp.broadcast_to(keys, p.shape).reshape(g.G) if keys.ndim
            else jnp.broadcast_to(keys, (g.G,)))
    dj = None
    if plan is None:
        pos, k_inj = run_special(method, g, keys, inj, n_traces, n_frames, burn_in_frames,
                                 dtype)
    else:
        pos, dj, k_inj = run_scan(
            method, plan, keys, p.shape, g.n_win, windows, n_traces, n_frames, burn_in_frames,
            dtype, force=force, force_params=force_params, jitter=inj.jitter is not None,
            shard=shard, unroll=unroll, chunk_frames=chunk_frames, progress=progress,
            normal_dtype=dtype if normal_dtype is None else resolve_dtype(normal_dtype))
    times = frame_times(g, dj, n_frames, dtype, return_times or bool(inj.additive))
    pos = add_injections(pos, times, k_inj, g, inj, p.windows, bool(p.tracking_std.any()),
                         n_traces, n_frames, dtype)
    return shape_output(pos, times, p, g.n_win, n_traces, n_frames, return_times, labelled)
