"""Batched calibration: many recordings of the same shape in one vmapped, jitted call.

For sweeps ("how wrong is the naive calibration over this grid?") and large data sets.
Every item gets its own status: one failing fit never aborts the batch.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._config import float64_scope, warn_if_float32
from .._constants import BOLTZMANN, DEFAULT_TEMPERATURE
from . import _batch_checks as checks
from ._batch_bound import release_bound_rows
from ._batch_host import _check_batch, _check_some_row_usable
from ._batch_host import _prepare as _prepare
from ._batch_result import GOF_THRESHOLD as GOF_THRESHOLD
from ._batch_result import BatchCalibration as BatchCalibration
from ._fit import _finish_from, _newton, fit_ml
from ._models import get_model
from ._problems import RecMeta, SpectralArgs, make_layout, spectral_model_psd, spectral_nll


class _Rec:
    def __init__(self, dt, w, t):
        self.frame_interval, self.exposure, self.temperature = dt, w, t
        self.laser_power = None
        self.name = None


#: rows per jitted call of calibrate_batch (larger batches are cut into chunks of this size)
_CHUNK = 64


#: Newton steps per item inside the vmapped fit. Under ``vmap`` a while loop runs until its
#: slowest item stops, so one hard item makes its whole chunk pay for its passes; from the
#: coarse start (records of >= 8192 frames) almost every item converges in 1-2 steps, from
#: the closed-form start of short records in 4-7. The rest (as a rule eps^2 running to its
#: bound) is continued together with the same program (``_CONTINUE_PASSES``); what still fails
#: is refitted alone on the host side (the same Newton-then-BFGS fit as ``calibrate``; that
#: compiles the single-record fit once, so it must stay rare).
_BATCH_NEWTON_STEPS = 16
#: further passes of ``_BATCH_NEWTON_STEPS`` for the items that did not converge in the
#: first, continued together from where they stopped (:func:`_continue_unfinished`)
_CONTINUE_PASSES = 4


def _gof(value, a: SpectralArgs, per: int, nbin: int):
    """Goodness-of-fit numbers (:func:`_batch_checks.gof_stats`) of one record's fit."""
    return checks.gof_stats(a.power[0] / spectral_model_psd(value, a)[0], a.weight[0], per,
                            nbin)


_gof_jit = eqx.filter_jit(_gof)  # for the items refitted alone


@eqx.filter_jit
def _batch_fit(scale, power, log_ref, shared: SpectralArgs, per: int, nbin: int, rtol=1e-9,
               atol=1e-9):
    """Newton only, at most ``_BATCH_NEWTON_STEPS`` steps: under vmap a ``lax.cond``
    fallback would run for every item, so items whose fit does not succeed are continued
    together (:func:`_continue_unfinished`) and then refitted one by one on the host side.
    Returns the fits and their goodness-of-fit numbers."""

    def one(s, pw, lr):
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw, lr))
        x_hat, x, v, g, h, ok, n = _newton(spectral_nll, s, a, rtol, atol, _BATCH_NEWTON_STEPS)
        out = _finish_from(x, v, g, h, s, ok, n, x_value=x_hat)
        return out, _gof(out.value, a, per, nbin)

    return jax.vmap(one)(scale, power, log_ref)


@float64_scope
def calibrate_batch(
    positions,
    *,
    frame_interval: float,
    exposure: float,
    temperature: float = DEFAULT_TEMPERATURE,
    model=None,
    n_blocks: int = 1,
    check_units: bool = True,
    gof_threshold: float = GOF_THRESHOLD,
    progress: bool = False,
    shard: bool | str = "auto",
) -> BatchCalibration:
    """Calibrate each row of ``positions`` (shape (B, N), metres) in one vmapped call.

    Items are independent: each has its own ``status`` and a failing item never aborts
    the batch (its errors are NaN). Uses the Whittle likelihood (``n_blocks=1``, the
    default of :func:`calibrate` for long records) or the blocked-PSD Gamma likelihood
    (``n_blocks > 1``) with the given core model (one with effects is refused with a
    ``ValueError``: use :func:`calibrate`). It stays Whittle where ``calibrate``'s default
    would switch to the exact likelihood (records of <= 2^14 frames, or tau not short
    compared with the record).
    All rows share ``frame_interval`` [s], ``exposure`` [s] and ``temperature`` [K].

    Every item gets the checks of :func:`calibrate`, without aborting the others:

    - the checks of a ``Recording``: NaN/inf frames (``"invalid: NaN at frame 17"``), a
      constant trace (``"constant trace"``) and, with ``check_units`` (default), positions
      whose standard deviation exceeds 10 um (``"invalid: positions look like nm ..."``) or
      lies below 0.02 nm, and after the fit a k or gamma outside any trapped bead's range
      (``"implausible: ..."``, values kept);
      frame interval or exposure above 1 s or a temperature below 100 K concern every row
      and raise ``ValueError``;
    - the refusal of frames without temporal information (lag-1 correlation below 5
      standard errors: dt >> tau, or tracking noise swamping the motion, where gamma is not
      identifiable from one exposure): ``"refused: no temporal information ..."``; after
      the fit, a relaxation time longer than a third of the record (block) is
      ``"relaxation not resolved"``, or ``"refused: dt >> tau ..."`` when the frames are
      far less correlated than a freely diffusing bead's;
    - the binned spectral goodness-of-fit test of ``calibrate`` (``result.gof``): its
      p-value is ``gof_p``, and items below ``gof_threshold`` are ``"inadequate: goodness of
      fit p = ... (line at 50 Hz? ...)"`` (a missing effect: line noise, drift, a detector
      filter; diagnose such a row with :func:`blurtrap.diagnose`). False-alarm rate at the
      default 1e-4, measured on honest items: 3 of 7400 flagged (0.04 %; nominal 0.01 %,
      consistent with a tail a little heavier than chi^2's: each bin's term has variance
      2 + 6/64, not 2), namely 3/5000 exact
      AR(1) records of 16 384 frames (W ~ 0, dt/tau = 0.5, 2 nm white noise; 125 dof),
      0/1000 of 4096 frames, and 0/1400 simulated camera records (W = dt) of 4096 and
      65 536 frames; below p = 0.05 lie 4.9 % of the first 5000 (nominal 5 %).

    Items not fitted ("invalid", "constant trace", "refused" before the fit) and items
    "inadequate" or refused after it have NaN values and errors; other failed items keep
    their fitted values with NaN errors. A batch with no finite, fluctuating row at all
    (empty, every row NaN/inf or constant) raises ``ValueError``: there is nothing to
    calibrate.

    - `progress`: a tqdm bar over the chunks of 64 rows (per device) as their fits finish.
    - `shard`: ``"auto"`` (default) splits each chunk's rows over all local devices when
      there are several (``jax.sharding``, one compiled program; estimates and errors are
      those of one device bit for bit, goodness-of-fit p-values to rounding), ``True``
      the same, ``False`` one device.

    **Returns:** :class:`BatchCalibration` with per-item values, errors, ``status``,
    ``success`` (status ``"ok"``), ``gof_p``, ``lag1_z`` and ``at_bound`` (an "ok" item
    with eps^2 at its bound 0: its error is NaN and the others' are, as ``calibrate``'s, the
    unconstrained Cramer-Rao bound at the estimate, the bound parameter counted as free;
    ``bound_conditional`` marks the rare item where that full information is not positive
    definite and the errors stay conditional on the bound, too small).
    """
    warn_if_float32("positions", positions)
    mesh = _batch_mesh(shard)
    y, m, gof_threshold = _check_batch(positions, n_blocks, check_units, gof_threshold)
    b, n = y.shape
    mdl = get_model(model)
    if mdl.extra:
        raise ValueError(
            f"calibrate_batch fits the core models (naive, naive_aliased, blur, standard, "
            f"photodiode_aa); model = {mdl.name!r} adds the effect(s) "
            f"{', '.join(e.name for e in mdl.extra)}. Fit such rows with calibrate (one "
            "Recording each, or a RecordingSet for a joint fit), or diagnose them first.")
    dt, w, t = float(frame_interval), float(exposure), float(temperature)
    checks.check_shared(dt, w, t, bool(check_units))
    _check_some_row_usable(y)
    f, per, nbin, shared = _shared_args(mdl, dt, w, t, m, n_blocks)
    n_par = len(shared.layout.names)
    acq = (dt, w, t)
    pending, stats, pre = _fit_chunks(y, shared, acq, n_blocks, m, bool(check_units), per, nbin,
                                      mesh)
    skip = pre != ""
    fits = _collect(pending, b, n_par, progress)
    _continue_unfinished(y, shared, acq, n_blocks, m, bool(check_units), per, nbin, fits, skip,
                         mesh)
    val, cov, success, converged, pd, steps, gof = fits
    for i in np.flatnonzero(~success & ~skip):  # rare: refit alone (Newton, then BFGS)
        _refit_alone(i, y, shared, acq, n_blocks, m, bool(check_units), per, nbin, fits)
    # a parameter at its bound (NaN variance): the others' errors unconstrained, as calibrate's
    fit_var = np.diagonal(cov, axis1=1, axis2=2)
    fit_bound = np.isnan(fit_var).any(axis=1) & np.isfinite(fit_var).any(axis=1) & success
    conditional = release_bound_rows(np.flatnonzero(fit_bound), y, val, cov, shared, acq,
                                     n_blocks, m, bool(check_units), _CHUNK)
    gof_dof = max(nbin - n_par, 1)
    z = stats[:, 5]
    status, gof_p = _statuses(val, converged, pd, gof, skip, pre, z, gof_dof, gof_threshold,
                              f, m, n, dt, per, nbin, n_blocks)
    for i in np.flatnonzero(status == "ok") if check_units else ():
        status[i] = checks.implausible_status(val[i, 0], val[i, 1]) or "ok"
    refused = np.array([s.startswith(("invalid", "refused", "inadequate", "constant"))
                        for s in status])
    val[refused] = np.nan
    success = status == "ok"
    var = np.diagonal(cov, axis1=1, axis2=2)
    at_bound = np.isnan(var).any(axis=1) & np.isfinite(var).any(axis=1)
    if mdl.noise:  # calibrate's rule (_assemble): eps^2 below 1e-6 of the frame variance
        with np.errstate(invalid="ignore"):
            at_bound |= val[:, 2] < 1e-6 * stats[:, 4] ** 2
    at_bound &= success
    conditional &= success
    cov[~success] = np.nan  # never a confident error bar on a failed item
    err = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None))
    kt = BOLTZMANN * t
    zeros = np.zeros(b)
    return BatchCalibration(
        k=val[:, 0], k_err=err[:, 0], gamma=val[:, 1], gamma_err=err[:, 1],
        tracking_var=val[:, 2] if mdl.noise else zeros,
        tracking_var_err=err[:, 2] if mdl.noise else zeros,
        diffusion=kt / val[:, 1],
        success=success, n_steps=steps, status=status.astype(str),
        method="likelihood" if n_blocks == 1 else "psd", model=mdl.name,
        gof_p=gof_p, gof_statistic=gof[:, 0], gof_dof=int(gof_dof),
        gof_threshold=gof_threshold, lag1_z=z, at_bound=at_bound,
        bound_conditional=conditional,
    )


def _shared_args(mdl, dt, w, t, m, n_blocks):
    """The ordinates, goodness-of-fit bins and the :class:`SpectralArgs` every row shares
    (its power and reference level are filled in per row)."""
    f = np.arange(1, m // 2 + 1) / (m * dt)
    weight = np.full(f.shape, float(n_blocks))
    if m % 2 == 0:
        weight[-1] *= 0.5
    per, nbin = checks.gof_bins(weight)
    layout = make_layout([_Rec(dt, w, t)], "shared", mdl.noise)
    shared = SpectralArgs(
        layout=layout, model=mdl,
        meta=RecMeta(dt=jnp.asarray([dt]), w=jnp.asarray([w]), temp=jnp.asarray([t])),
        f=jnp.asarray(f[None]), s2=jnp.asarray(np.sin(np.pi * f * dt)[None] ** 2),
        power=jnp.zeros((1, f.size)), weight=jnp.asarray(weight[None]),
        log_ref=jnp.asarray(0.0),
        # the exact expected periodogram of M frames, as in calibrate
        block_len=(jnp.asarray([float(m)]) if mdl.alias and mdl.closed_form else None),
    )
    return f, per, nbin, shared


def _batch_mesh(shard):
    """A one-axis mesh over the local devices (``shard`` "auto"/True with several), or None."""
    if not (isinstance(shard, (bool, np.bool_)) or (isinstance(shard, str) and shard == "auto")):
        raise ValueError(f"shard must be 'auto', True or False; got shard = {shard!r}")
    devices = jax.local_devices()
    if (isinstance(shard, (bool, np.bool_)) and not shard) or len(devices) < 2:
        return None
    return Mesh(np.asarray(devices), ("batch",))


def _rows_on(mesh):
    """Put a chunk's (rows, ...) array on the device(s): rows split over the mesh, if any."""
    if mesh is None:
        return jnp.asarray
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return lambda z: jax.device_put(np.asarray(z), sharding)


def _fit_chunks(y, shared: SpectralArgs, acq, n_blocks, m, check_units: bool, per, nbin,
                mesh=None):
    """Dispatch the vmapped fits chunk by chunk (``acq = (dt, W, T)``): ``(pending fits,
    per-row checks (B, 6), status of rows not fitted)``."""
    b = y.shape[0]
    (dt, w, t), noise = acq, shared.model.noise
    # Chunks of at most _CHUNK rows per device: one compiled shape for every large batch,
    # host memory bounded by the chunk, and the host-side periodograms of the next chunk
    # overlap with the (asynchronously dispatched) jitted fit of the previous one. With a
    # mesh, a chunk is a multiple of the device count and its rows are split over them.
    n_dev = 1 if mesh is None else mesh.size
    chunk = -(-min(b, _CHUNK * n_dev) // n_dev) * n_dev
    put = _rows_on(mesh)
    pending = []
    stats = np.empty((b, 6))
    pre = np.empty(b, dtype=object)
    for i0 in range(0, b, chunk):
        i1 = min(i0 + chunk, b)
        power, starts, log_ref, stats[i0:i1], pre[i0:i1] = _prepare(
            y[i0:i1], n_blocks, m, dt, w, t, noise, check_units, i0)
        if np.all(pre[i0:i1] != ""):  # nothing to fit in this chunk
            pending.append((i0, i1, None))
            continue
        # the last chunk repeats its first row: same compiled shape
        power, starts, log_ref = _pad_rows(chunk, power, starts, log_ref)
        pending.append((i0, i1, _batch_fit(put(starts), put(power[:, None, :]), put(log_ref),
                                           shared, per, nbin)))
    return pending, stats, pre


def _pad_rows(chunk, *arrays):
    """Each array padded to ``chunk`` rows with copies of its first row (one compiled shape
    for every chunk; the copies' results are dropped)."""
    pad = chunk - arrays[0].shape[0]
    return tuple(np.concatenate([z, np.repeat(z[:1], pad, axis=0)]) if pad else z
                 for z in arrays)


def _collect(pending, b: int, n_par: int, progress: bool = False):
    """The chunks' fits on the host: ``(value, cov, success, converged, hessian_pd,
    n_steps, goodness-of-fit numbers)``, one row per item; a tqdm bar with `progress`."""
    if progress:
        from tqdm.auto import tqdm

        pending = tqdm(pending, desc="calibrate_batch", unit="chunk", mininterval=0.0)
    val, cov = np.empty((b, n_par)), np.empty((b, n_par, n_par))
    success, converged, pd = (np.empty(b, dtype=bool) for _ in range(3))
    steps = np.empty(b, dtype=int)
    gof = np.empty((b, 5))
    for i0, i1, res in pending:
        if res is None:
            val[i0:i1], cov[i0:i1], gof[i0:i1] = np.nan, np.nan, np.nan
            success[i0:i1], converged[i0:i1], pd[i0:i1], steps[i0:i1] = False, True, True, 0
            continue
        out, g = res
        n_i = i1 - i0
        val[i0:i1], cov[i0:i1] = np.asarray(out.value)[:n_i], np.asarray(out.cov)[:n_i]
        success[i0:i1] = np.asarray(out.success)[:n_i]
        steps[i0:i1] = np.asarray(out.n_steps)[:n_i]
        converged[i0:i1] = np.asarray(out.converged)[:n_i]
        pd[i0:i1] = np.asarray(out.hessian_pd)[:n_i]
        gof[i0:i1] = np.stack([np.asarray(z, dtype=float)[:n_i] for z in g], axis=1)
    return val, cov, success, converged, pd, steps, gof


def _continue_unfinished(y, shared: SpectralArgs, acq, n_blocks, m, check_units: bool, per,
                         nbin, fits, skip, mesh=None):
    """Items whose vmapped Newton fit stopped at ``_BATCH_NEWTON_STEPS`` without converging
    (as a rule eps^2 running to its bound 0, which the log parametrisation reaches only
    slowly) are continued together from where they stopped, in chunks of the same shape and
    with the same compiled fit, for up to ``_CONTINUE_PASSES`` more passes; their fits are
    replaced in place where they now succeed. Before, each such item (about 1 in 10 at 4096
    frames, W = 0.1 dt, eps = 2 nm) was refitted alone with a host-driven loop, ~0.1 s each
    on a CPU and more on an accelerator, where it dominated a large batch's time."""
    val, cov, success, converged, pd, steps, gof = fits
    dt, w, t = acq
    n_dev = 1 if mesh is None else mesh.size
    put = _rows_on(mesh)
    for _ in range(_CONTINUE_PASSES):
        rows = np.flatnonzero(~success & ~skip & np.all(np.isfinite(val) & (val > 0), axis=1))
        if rows.size == 0:
            return
        # the first pass's chunk shape: its compiled program serves again, and each device
        # sees the same shape as with one device (results bit for bit those of one device)
        chunk = -(-min(y.shape[0], _CHUNK * n_dev) // n_dev) * n_dev
        for j0 in range(0, rows.size, chunk):
            idx = rows[j0:j0 + chunk]
            power, _, log_ref, _, _ = _prepare(y[idx], n_blocks, m, dt, w, t,
                                               shared.model.noise, check_units)
            power, starts, log_ref = _pad_rows(chunk, power, val[idx], log_ref)
            out, g = _batch_fit(put(starts), put(power[:, None, :]), put(log_ref), shared,
                                per, nbin)
            n_i = idx.size
            val[idx], cov[idx] = np.asarray(out.value)[:n_i], np.asarray(out.cov)[:n_i]
            success[idx], converged[idx] = (np.asarray(out.success)[:n_i],
                                            np.asarray(out.converged)[:n_i])
            pd[idx] = np.asarray(out.hessian_pd)[:n_i]
            steps[idx] += np.asarray(out.n_steps)[:n_i]
            gof[idx] = np.stack([np.asarray(z, dtype=float)[:n_i] for z in g], axis=1)


def _refit_alone(i, y, shared: SpectralArgs, acq, n_blocks, m, check_units: bool, per, nbin,
                 fits):
    """Refit item ``i`` alone (the Newton-then-BFGS fit of ``calibrate``), in place."""
    val, cov, success, converged, pd, steps, gof = fits
    dt, w, t = acq
    power, starts, log_ref, _, _ = _prepare(y[i:i + 1], n_blocks, m, dt, w, t,
                                            shared.model.noise, check_units)
    a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared,
                    (jnp.asarray(power), jnp.asarray(log_ref[0])))
    one = fit_ml(spectral_nll, jnp.asarray(starts[0]), a)
    val[i], cov[i] = np.asarray(one.value), np.asarray(one.cov)
    success[i], steps[i] = bool(one.success), int(one.n_steps)
    converged[i], pd[i] = bool(one.converged), bool(one.hessian_pd)
    gof[i] = [float(z) for z in _gof_jit(one.value, a, per, nbin)]


def _statuses(val, converged, pd, gof, skip, pre, z, gof_dof, gof_threshold, f, m, n, dt, per,
              nbin, n_blocks):
    """Each item's status (see :class:`BatchCalibration`) and goodness-of-fit p-value."""
    b = val.shape[0]
    status = np.full(b, "ok", dtype=object)
    # a singular information is the symptom; an unresolved relaxation (below) its cause
    status[~pd] = "singular Fisher information"
    with np.errstate(divide="ignore", invalid="ignore"):
        unresolved = ~(val[:, 1] / val[:, 0] < m * dt / 3.0)
    status[unresolved] = "relaxation not resolved"
    # as calibrate: frames far less correlated than a freely diffusing bead's (r1 ~ 1) mean
    # that the fit ran tau up for want of temporal information, not free diffusion
    no_info = unresolved & (z < 0.5 * math.sqrt(n))
    for i in np.flatnonzero(no_info):
        status[i] = checks.no_information_status(z[i])
    status[~converged] = "not converged"
    gof[skip, 0] = np.nan  # not fitted: no test
    gof_p = checks.gof_p_values(gof[:, 0], gof_dof) if nbin > 0 else np.full(b, np.nan)
    for i in np.flatnonzero((status == "ok") & ~skip & (gof_p < gof_threshold)):
        status[i] = checks.inadequate_status(gof_p[i], gof[i, 1], gof[i, 2], gof[i, 3], gof[i, 4],
                                             f, per, n_blocks)
    status[skip] = pre[skip]
    return status, gof_p
