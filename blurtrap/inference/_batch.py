"""Batched calibration: many recordings of the same shape in one vmapped, jitted call.

For sweeps ("how wrong is the naive calibration over this grid?") and large data sets.
Every item gets its own status: one failing fit never aborts the batch.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope, warn_if_float32
from ..physics._constants import BOLTZMANN, DEFAULT_TEMPERATURE
from ._fit import _finish_from, _newton, fit_ml
from ._models import get_model
from ._problems import RecMeta, SpectralArgs, make_layout, spectral_nll


@dataclasses.dataclass(frozen=True)
class BatchCalibration:
    """Per-item results (numpy arrays of shape ``batch``; SI units)."""

    k: np.ndarray
    k_err: np.ndarray
    gamma: np.ndarray
    gamma_err: np.ndarray
    tracking_var: np.ndarray
    tracking_var_err: np.ndarray
    diffusion: np.ndarray
    success: np.ndarray  # bool: status == "ok"
    n_steps: np.ndarray
    #: per item: "ok", "not converged", "singular Fisher information" (a parameter at its
    #: bound or unidentifiable: errors are NaN), "relaxation not resolved" (tau > T/3: the
    #: bead diffuses almost freely and k is not identified) or "constant trace" (no
    #: fluctuations; values NaN)
    status: np.ndarray
    method: str
    model: str

    def __len__(self):
        return len(self.k)

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in out.items()}


class _Rec:
    def __init__(self, dt, w, t):
        self.frame_interval, self.exposure, self.temperature = dt, w, t
        self.laser_power = None
        self.name = None


def _lag_moments(power, m, dt):
    """Circular autocovariances at lags 0, 1, 2 of the (mean-removed) blocks, from their
    periodograms ``power`` (B, M//2) at j = 1..M//2: ``c_k = 1/(M dt) sum_j w_j I_j
    cos(2 pi j k / M)`` over the full circle (w_j = 2, 1 at the Nyquist ordinate of an even M;
    j = 0 is 0 after mean removal). They differ from the lag products of ``moment_start``
    by O(1/M), immaterial for start values, for a small matrix product instead of three
    passes over the frames."""
    return (power @ _lag_basis(m, dt)).T


@functools.lru_cache(maxsize=8)
def _lag_basis(m, dt):
    j = np.arange(1, m // 2 + 1)
    wt = np.full(j.shape, 2.0)
    if m % 2 == 0:
        wt[-1] = 1.0
    return wt[:, None] * np.cos(2.0 * np.pi * np.outer(j, np.arange(3)) / m) / (m * dt)


def _moment_starts(c0, c1, c2, dt, w, temp):
    """Vectorised closed-form starts from lag moments (same estimator as ``moment_start``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(c1 > 0, c2 / c1, np.exp(-1.0))
    rho = np.clip(np.nan_to_num(rho, nan=np.exp(-1.0)), 0.05, 0.99999)
    tau = -dt / np.log(rho)
    a, r = w / tau, dt / tau
    phi1 = np.where(a < 1e-6, 1.0 - a / 2, -np.expm1(-a) / np.maximum(a, 1e-300))
    rho_b = phi1**2 * np.exp(a - r)
    s = np.where(a < 1e-3, 1 - a / 3 + a * a / 12, 2 / np.maximum(a, 1e-300)
                 * (1 + np.expm1(-a) / np.maximum(a, 1e-300)))
    sigma2 = np.where(c1 > 0, c1 / rho_b, c0)
    sigma2 = np.clip(sigma2, 0.3 * c0 / s, 3.0 * c0 / s)
    eps2 = np.maximum(c0 - sigma2 * s, 0.02 * c0)
    k = BOLTZMANN * temp / sigma2
    return np.stack([k, k * tau, eps2], axis=1)


#: rows per block of the host-side preparation (periodograms, start values): the same
#: per-row arithmetic as whole-array numpy calls, without GB-sized temporaries, whose fresh
#: pages cost more than the FFTs (1000 x 65 536 frames: 2.2 s -> 0.4 s for the start values)
_HOST_ROWS = 16


def _periodograms(y, n_blocks, m, dt):
    """Block-averaged periodograms (B, M//2) of every row: mean removed per block, ordinates
    j = 1..M/2, ``dt/M |FFT|^2`` averaged over the blocks; with the lag moments of
    :func:`_lag_moments` (3, B) and the mean ordinate (B,), both taken while a block of rows
    is still in cache."""
    out = np.empty((y.shape[0], m // 2))
    mom = np.empty((3, y.shape[0]))
    avg = np.empty(y.shape[0])
    for i in range(0, y.shape[0], _HOST_ROWS):
        blocks = y[i:i + _HOST_ROWS, : m * n_blocks].reshape(-1, n_blocks, m)
        blocks = blocks - blocks.mean(axis=2, keepdims=True)
        spec = np.fft.rfft(blocks, axis=2)[:, :, 1:]
        rows = out[i:i + _HOST_ROWS]
        rows[:] = (spec.real**2 + spec.imag**2).mean(axis=1) * dt / m
        mom[:, i:i + _HOST_ROWS] = _lag_moments(rows, m, dt)
        avg[i:i + _HOST_ROWS] = rows.mean(axis=1)
    return out, mom, avg


#: rows per jitted call of calibrate_batch (larger batches are cut into chunks of this size)
_CHUNK = 64


def _prepare(y, constant, n_blocks, m, dt, w, temp, noise):
    """Host-side inputs of the fit for rows ``y``: periodograms (B, M//2), start values and
    log reference levels. Constant rows get a stand-in spectrum (they are not reported)."""
    power, mom, avg = _periodograms(y, n_blocks, m, dt)
    if constant.any():  # harmless stand-in data for the vmapped fit only
        power[constant] = power[~constant].mean(axis=0) if (~constant).any() else 1e-20
        mom[:, constant] = _lag_moments(power[constant], m, dt)
        avg[constant] = power[constant].mean(axis=1)
    starts = _moment_starts(*mom, dt, w, temp)  # pyright: ignore[reportCallIssue]  # mom: 3 rows
    if not noise:
        starts = starts[:, :2]
    return power, starts, np.log(avg)


#: Newton steps per item inside the vmapped fit. Under ``vmap`` a while loop runs until its
#: slowest item stops, so one hard item makes its whole chunk pay for its passes; from the
#: coarse start (records of >= 8192 frames) almost every item converges in 1-2 steps, from
#: the closed-form start of short records in 4-7. The rare rest is refitted alone on the host
#: side (the same Newton-then-BFGS fit as ``calibrate``; that compiles the single-record fit
#: once, so it must stay rare: 4 steps sent half of the 4096-frame items there).
_BATCH_NEWTON_STEPS = 16


@eqx.filter_jit
def _batch_fit(scale, power, log_ref, shared: SpectralArgs, rtol=1e-9, atol=1e-9):
    """Newton only, at most ``_BATCH_NEWTON_STEPS`` steps: under vmap a ``lax.cond``
    fallback would run for every item, so items whose fit does not succeed are refitted one
    by one on the host side."""

    def one(s, pw, lr):
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw, lr))
        x_hat, x, v, g, h, ok, n = _newton(spectral_nll, s, a, rtol, atol, _BATCH_NEWTON_STEPS)
        return _finish_from(x, v, g, h, s, ok, n, x_value=x_hat)

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
) -> BatchCalibration:
    """Calibrate each row of ``positions`` (shape (B, N), metres) in one vmapped call.

    Items are independent: each has its own ``status`` and a failing item never aborts
    the batch (its errors are NaN). Uses the Whittle likelihood (``n_blocks=1``, the
    default of :func:`calibrate` for long records) or the blocked-PSD Gamma likelihood
    (``n_blocks > 1``) with the given model.
    All rows share ``frame_interval`` [s], ``exposure`` [s] and ``temperature`` [K].

    **Returns:** :class:`BatchCalibration` with per-item values, errors and ``success``.
    """
    warn_if_float32("positions", positions)
    y = np.asarray(positions, dtype=float)
    if y.ndim != 2:
        raise ValueError(f"positions must have shape (batch, frames); got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        bad = np.argwhere(~np.isfinite(y))[0]
        raise ValueError(f"positions contain NaN/inf (first at row {bad[0]}, frame {bad[1]})")
    b, n = y.shape
    if isinstance(n_blocks, bool) or not isinstance(n_blocks, (int, np.integer)) or n_blocks < 1:
        raise ValueError(f"n_blocks must be an integer >= 1; got n_blocks = {n_blocks!r}")
    m = n // n_blocks
    if m < 8:
        raise ValueError(f"n_blocks = {n_blocks} leaves {m} frames per block; need >= 8")
    mdl = get_model(model)
    dt, w, t = float(frame_interval), float(exposure), float(temperature)
    if not (dt > 0 and 0 < w <= dt * (1 + 1e-12) and t > 0):
        raise ValueError(
            f"need frame_interval > 0, 0 < exposure <= frame_interval, temperature > 0; got "
            f"frame_interval = {dt} s, exposure = {w} s, temperature = {t} K"
        )
    f = np.arange(1, m // 2 + 1) / (m * dt)
    weight = np.full(f.shape, float(n_blocks))
    if m % 2 == 0:
        weight[-1] *= 0.5
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
    constant = np.ptp(y, axis=1) == 0  # no fluctuations: reported per item, not fitted
    # Chunks of at most _CHUNK rows: one compiled shape for every large batch, host memory
    # bounded by the chunk, and the host-side periodograms of the next chunk overlap with
    # the (asynchronously dispatched) jitted fit of the previous one.
    chunk = min(b, _CHUNK)
    pending = []
    for i0 in range(0, b, chunk):
        i1 = min(i0 + chunk, b)
        power, starts, log_ref = _prepare(y[i0:i1], constant[i0:i1], n_blocks, m, dt, w, t,
                                          mdl.noise)
        pad = chunk - (i1 - i0)  # the last chunk repeats its first row: same compiled shape
        if pad:
            power, starts, log_ref = (np.concatenate([z, np.repeat(z[:1], pad, axis=0)])
                                      for z in (power, starts, log_ref))
        pending.append((i0, i1, _batch_fit(jnp.asarray(starts), jnp.asarray(power[:, None, :]),
                                           jnp.asarray(log_ref), shared)))
    n_par = len(layout.names)
    val, cov = np.empty((b, n_par)), np.empty((b, n_par, n_par))
    success, converged, pd = (np.empty(b, dtype=bool) for _ in range(3))
    steps = np.empty(b, dtype=int)
    for i0, i1, out in pending:
        n_i = i1 - i0
        val[i0:i1], cov[i0:i1] = np.asarray(out.value)[:n_i], np.asarray(out.cov)[:n_i]
        success[i0:i1] = np.asarray(out.success)[:n_i]
        steps[i0:i1] = np.asarray(out.n_steps)[:n_i]
        converged[i0:i1] = np.asarray(out.converged)[:n_i]
        pd[i0:i1] = np.asarray(out.hessian_pd)[:n_i]
    for i in np.flatnonzero(~success & ~constant):  # rare: refit alone (Newton, then BFGS)
        power, starts, log_ref = _prepare(y[i:i + 1], constant[i:i + 1], n_blocks, m, dt, w, t,
                                          mdl.noise)
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared,
                        (jnp.asarray(power), jnp.asarray(log_ref[0])))
        one = fit_ml(spectral_nll, jnp.asarray(starts[0]), a)
        val[i], cov[i] = np.asarray(one.value), np.asarray(one.cov)
        success[i], steps[i] = bool(one.success), int(one.n_steps)
        converged[i], pd[i] = bool(one.converged), bool(one.hessian_pd)
    status = np.full(b, "ok", dtype=object)
    with np.errstate(divide="ignore", invalid="ignore"):
        unresolved = ~(val[:, 1] / val[:, 0] < m * dt / 3.0)
    status[unresolved] = "relaxation not resolved"
    status[~pd] = "singular Fisher information"
    status[~converged] = "not converged"
    status[constant] = "constant trace"
    val[constant] = np.nan
    success = status == "ok"
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
    )
