"""Batched calibration: many recordings of the same shape in one vmapped, jitted call.

For sweeps ("how wrong is the naive calibration over this grid?") and large data sets.
Every item gets its own status: one failing fit never aborts the batch.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope, warn_if_float32
from ..physics._constants import BOLTZMANN, DEFAULT_TEMPERATURE
from ._fit import _bfgs_jit, _finish, _newton
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
    #: bound or unidentifiable: errors are NaN) or "relaxation not resolved" (tau > T/3: the
    #: bead diffuses almost freely and k is not identified)
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


def _moment_starts(y, dt, w, temp):
    """Vectorised closed-form starts (same estimator as ``moment_start``)."""
    y = y - y.mean(axis=1, keepdims=True)
    c0 = np.mean(y * y, axis=1)
    c1 = np.mean(y[:, 1:] * y[:, :-1], axis=1)
    c2 = np.mean(y[:, 2:] * y[:, :-2], axis=1)
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


@eqx.filter_jit
def _batch_fit(scale, power, log_ref, shared: SpectralArgs, rtol=1e-9, atol=1e-9):
    """Newton only: under vmap a ``lax.cond`` fallback would run for every item, so items
    whose Newton fit fails are refitted one by one (BFGS) on the host side."""

    def one(s, pw, lr):
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw, lr))
        f, x, ok, n = _newton(spectral_nll, s, a, rtol, atol)
        return _finish(f, x, a, s, ok, n)

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
    blocks = y[:, : m * n_blocks].reshape(b, n_blocks, m)
    blocks = blocks - blocks.mean(axis=2, keepdims=True)
    spec = np.fft.rfft(blocks, axis=2)[:, :, 1:]
    power = (spec.real**2 + spec.imag**2).mean(axis=1) * dt / m  # (B, M)
    f = np.arange(1, m // 2 + 1) / (m * dt)
    weight = np.full(f.shape, float(n_blocks))
    if m % 2 == 0:
        weight[-1] *= 0.5
    layout = make_layout([_Rec(dt, w, t)], "shared", mdl.noise)
    shared = SpectralArgs(
        layout=layout, model=mdl,
        meta=RecMeta(dt=jnp.asarray([dt]), w=jnp.asarray([w]), temp=jnp.asarray([t])),
        f=jnp.asarray(f[None]), s2=jnp.asarray(np.sin(np.pi * f * dt)[None] ** 2),
        power=jnp.asarray(power[:1, None, :][0]), weight=jnp.asarray(weight[None]),
        log_ref=jnp.asarray(0.0),
        # the exact expected periodogram of M frames, as in calibrate
        block_len=(jnp.asarray([float(m)]) if mdl.alias and mdl.closed_form else None),
    )
    constant = np.ptp(y, axis=1) == 0  # no fluctuations: reported per item, not fitted
    if constant.any():
        rng = np.random.default_rng(0)  # harmless stand-in data for the vmapped fit only
        y = y.copy()
        y[constant] = rng.standard_normal((int(constant.sum()), n)) * 1e-8
        power[constant] = power[~constant].mean(axis=0) if (~constant).any() else 1e-20
    starts = _moment_starts(y, dt, w, t)
    if not mdl.noise:
        starts = starts[:, :2]
    log_ref = np.log(power.mean(axis=1))
    out = _batch_fit(jnp.asarray(starts), jnp.asarray(power[:, None, :]), jnp.asarray(log_ref),
                     shared)
    val = np.array(out.value)
    cov = np.array(out.cov)
    success = np.array(out.success)
    converged, pd = np.array(out.converged), np.array(out.hessian_pd)
    steps = np.array(out.n_steps)
    for i in np.flatnonzero(~success):  # rare: refit alone with the BFGS fallback
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared,
                        (jnp.asarray(power[i][None]), jnp.asarray(log_ref[i])))
        one = _bfgs_jit(spectral_nll, jnp.asarray(starts[i]), a, 1e-9, 1e-9, 400)
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
