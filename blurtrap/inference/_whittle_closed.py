r"""The full-record Whittle likelihood of closed-form aliased models in closed form: one
division per ordinate at most, no logarithms (:class:`_RationalWhittleArgs`), and the leakage
criterion that decides when it stands in for ``calibrate``'s expected-periodogram Whittle
likelihood (:func:`_leakage`, :data:`LEAKAGE_MAX`). Used by :func:`sample_posterior`."""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN
from ..physics import psd_coeffs_unchecked as _psd_coeffs


class _RationalWhittleArgs(eqx.Module):
    r"""Full-record Whittle likelihood of closed-form aliased models, evaluated without a pass
    over the periodogram.

    For these models the discrete PSD is a ratio of two polynomials of degree one in
    ``s = sin^2(pi f dt)`` (DESIGN item 5): ``P(f) = dt num(s) / den(s)`` with
    ``num = n0 + n1 s``, ``n0 = c_a + eps^2 (1 - rho)^2``, ``n1 = 4 rho eps^2 - c_b`` and
    ``den = (1 - rho)^2 + 4 rho s = |1 - rho e^(i w)|^2`` (``w = 2 pi f dt``). Writing
    ``num = kappa |1 + theta e^(i w)|^2`` (``|theta| < 1``; ``t = sqrt(num(1)/num(0))``,
    ``theta = (1 - t)/(1 + t)``, ``kappa (1 - theta^2) = n0 t``):

    - the sum of ``w_j log P_j`` over the Fourier frequencies ``j = 1 .. floor(N/2)`` (weight
      ``w_j`` 1/2 at Nyquist) is exact in closed form, from
      ``prod_(j=0)^(N-1) (1 - a e^(2 pi i j/N)) = 1 - a^N``:
      ``sum_j w_j log den_j = log((1 - rho^N)/(1 - rho))`` and
      ``sum_j w_j log num_j = (N-1)/2 log kappa + log(1 - (-theta)^N) - log(1 + theta)``;
    - ``sum_j w_j I_j / P_j`` is a lag sum: ``1/|1 + theta e^(i w)|^2 = sum_m (-theta)^|m|
      e^(i m w) / (1 - theta^2)``, so with the data's lag statistics ``R_m = sum_(j=0)^(N-1)
      I_j cos(m w_j)`` and ``D_m = sum_j I_j 4 s_j cos(m w_j)`` (computed once)
      ``sum_j w_j I_j / P_j = [(1 - rho)^2 S(R) + rho S(D)] / (2 dt n0 t)``,
      ``S(X) = X_0 + 2 sum_(m=1)^L (-theta)^m X_m``. Since ``|X_m| <= X_0`` the truncation
      error is below ``2 |theta|^(L+1) (1 + |theta|)/(1 - |theta|)^2`` relative; when that
      exceeds 1e-16 (``|theta| >~ 0.55``: strong white noise with ``dt << tau``) the sum runs
      over the ordinates instead (one division each, no logarithm).

    For camera data ``|theta| <~ 0.3`` and an evaluation costs O(L) instead of O(N). The value
    equals :func:`~blurtrap.inference._problems.spectral_nll` on the same ordinates to
    rounding (tested). Valid for ``n_blocks = 1``, all ordinates (no ``f_range``) and
    closed-form aliased models whose extra effects are relations across recordings only.
    """

    layout: Any
    model: Any
    meta: Any
    s2: jax.Array  # (R, M) sin^2(pi f dt)
    wpow: jax.Array  # (R, M) weight x periodogram / dt (0 on padding)
    lag_r: jax.Array  # (R, L+1) R_m / dt
    lag_d: jax.Array  # (R, L+1) D_m / dt
    n: jax.Array  # (R,) frames per recording
    parity: jax.Array  # (R,) (-1)^N
    log_ref: jax.Array


N_LAGS = 64  # lags of the truncated sum (|theta| <~ 0.55 at 1e-16)
_LAG_TOL = 1e-16


def _rational_ok(model, f_range) -> bool:
    return (f_range is None and model.alias and model.closed_form
            and all(e.kind == "relation" for e in model.extra))


def _rational_args(recs, spec, n_lags: int = N_LAGS) -> _RationalWhittleArgs:
    """From the ordinary spectral arguments (same ordinates, weights and reference)."""
    n = np.array([r.n_frames for r in recs], dtype=np.int64)
    dts = np.asarray(spec.meta.dt)[:, None]
    wpow = np.asarray(spec.weight) * np.asarray(spec.power) / dts  # 0 on padding
    s2 = np.asarray(spec.s2)
    lag_r = np.empty((len(recs), n_lags + 1))
    lag_d = np.empty((len(recs), n_lags + 1))
    lags = np.arange(n_lags + 1)
    for i, r in enumerate(recs):
        # X_m = 2 sum_(j=1)^M c_j cos(2 pi j m / N) = 2 Re FFT_N(c)[m mod N]
        m_i = int(np.count_nonzero(np.asarray(spec.weight)[i]))
        c = np.zeros(int(n[i]))
        c[1 : m_i + 1] = wpow[i, :m_i]
        lag_r[i] = 2.0 * np.fft.fft(c).real[lags % n[i]]
        c[1 : m_i + 1] *= 4.0 * s2[i, :m_i]
        lag_d[i] = 2.0 * np.fft.fft(c).real[lags % n[i]]
    return _RationalWhittleArgs(
        layout=spec.layout, model=spec.model, meta=spec.meta, s2=spec.s2,
        wpow=jnp.asarray(wpow), lag_r=jnp.asarray(lag_r), lag_d=jnp.asarray(lag_d),
        n=jnp.asarray(n.astype(float)), parity=jnp.asarray(np.where(n % 2 == 0, 1.0, -1.0)),
        log_ref=spec.log_ref,
    )


def _rational_parts(p, a: _RationalWhittleArgs) -> dict:
    """Per-recording coefficients of the rational PSD, the closed-form log sums and whether
    the truncated lag sum is exact to 1e-16 for every recording (``lag_ok``)."""
    k_rec, gamma, eps2 = a.layout.unpack(p)
    temp = a.meta.temp
    if a.model.extra:
        k_rec, gamma, temp = a.model.relations(k_rec, gamma, temp, a.layout.power,
                                               a.layout.unpack_extras(p))
    sigma2 = BOLTZMANN * temp / k_rec
    tau = gamma / k_rec * jnp.ones_like(sigma2)
    e2 = (eps2 if a.model.noise else 0.0) * jnp.ones_like(sigma2)
    w = a.model._w(a.meta.w) * jnp.ones_like(sigma2)
    dt = a.meta.dt * jnp.ones_like(sigma2)
    _, omr, rho, c_a, c_b, _ = _psd_coeffs(sigma2, tau, w, dt, e2)
    n0 = c_a + e2 * omr * omr  # num(s = 0)
    n1 = 4.0 * rho * e2 - c_b
    t = jnp.sqrt((n0 + n1) / n0)  # (1 - theta)/(1 + theta) = sqrt(num(1)/num(0))
    theta = (1.0 - t) / (1.0 + t)
    abs_th = jnp.abs(theta)
    log_abs = jnp.log(jnp.where(abs_th > 0, abs_th, 1.0))
    # (-theta)^N
    pow_n = jnp.where(abs_th > 0, jnp.exp(a.n * log_abs), 0.0)
    pow_n = pow_n * jnp.where(theta < 0, 1.0, a.parity)
    n = a.n
    log_den = jnp.log(-jnp.expm1(-n * dt / tau)) - jnp.log(omr)
    log_kappa = jnp.log(n0) + 2.0 * jnp.log1p(t) - 2.0 * math.log(2.0)
    log_num = (0.5 * (n - 1.0) * log_kappa + jnp.log1p(-pow_n)
               + jnp.log1p(t) - math.log(2.0))  # -log(1 + theta) = log(1 + t) - log 2
    logs = jnp.sum(0.5 * (n - 1.0) * (jnp.log(dt) - a.log_ref) + log_num - log_den)
    n_lags = a.lag_r.shape[-1] - 1
    tail = 2.0 * jnp.exp((n_lags + 1) * log_abs) * (1.0 + abs_th) / (1.0 - abs_th) ** 2
    lag_ok = jnp.all((tail < _LAG_TOL) | (abs_th == 0))
    return dict(omr=omr, rho=rho, n0=n0, n1=n1, t=t, theta=theta, abs_th=abs_th,
                log_abs=log_abs, logs=logs, lag_ok=lag_ok)


def _quad_by_lags(a: _RationalWhittleArgs, q: dict):
    n_lags = a.lag_r.shape[-1] - 1
    m = jnp.arange(n_lags + 1, dtype=q["theta"].dtype)
    mag = jnp.where(q["abs_th"][:, None] > 0, jnp.exp(m[None, :] * q["log_abs"][:, None]),
                    (m == 0)[None, :] * 1.0)
    sign = jnp.where(q["theta"][:, None] < 0, 1.0, jnp.where(m % 2 == 0, 1.0, -1.0)[None, :])
    wts = mag * sign * jnp.where(m == 0, 1.0, 2.0)[None, :]  # (-theta)^|m| over m = -L..L
    s_r = jnp.sum(wts * a.lag_r, axis=-1)
    s_d = jnp.sum(wts * a.lag_d, axis=-1)
    return jnp.sum((q["omr"] ** 2 * s_r + q["rho"] * s_d) / (2.0 * q["n0"] * q["t"]))


def _quad_by_ordinates(a: _RationalWhittleArgs, q: dict):
    col = lambda x: x[:, None]  # noqa: E731
    den = col(q["omr"] ** 2) + col(4.0 * q["rho"]) * a.s2
    num = col(q["n0"]) + col(q["n1"]) * a.s2
    return jnp.sum(a.wpow * den / num)


def _rational_whittle_nll(p, a: _RationalWhittleArgs, path: str = "auto"):
    """Equals ``spectral_nll`` on the same ordinates. ``path``: ``"auto"`` (lag sum when it
    is exact to 1e-16, else the ordinates), ``"lags"`` or ``"ordinates"`` (for tests)."""
    q = _rational_parts(p, a)
    if path == "lags":
        return q["logs"] + _quad_by_lags(a, q)
    if path == "ordinates":
        return q["logs"] + _quad_by_ordinates(a, q)
    return q["logs"] + jax.lax.cond(q["lag_ok"], lambda: _quad_by_lags(a, q),
                                    lambda: _quad_by_ordinates(a, q))


# Largest Fejer-kernel leakage (relative, times sqrt(N)) for which the closed-form Whittle
# evaluation (P_d) stands in for calibrate's expected-periodogram Whittle likelihood: the two
# maxima then differ by <~ 0.04 standard errors (measured: ~0.4 u0 sqrt(N) SE for camera
# data, soft to stiff traps).
LEAKAGE_MAX = 0.1


def _leakage(p, a: _RationalWhittleArgs) -> float:
    """``max_r u0_r sqrt(N_r)`` at ``p``: ``u0 = 2 C(1) / (N num(0))`` is the relative
    leakage term ``E[I_j]/P_d(f_j) - 1`` of the expected periodogram at low frequency
    (``~ rho tau / T``)."""
    from ..physics import rho_b_unchecked as _rho_b

    q = _rational_parts(jnp.asarray(p), a)
    k_rec, gamma, _ = a.layout.unpack(jnp.asarray(p))
    temp = a.meta.temp
    if a.model.extra:
        k_rec, gamma, temp = a.model.relations(k_rec, gamma, temp, a.layout.power,
                                               a.layout.unpack_extras(jnp.asarray(p)))
    tau = gamma / k_rec
    c1 = BOLTZMANN * temp / k_rec * _rho_b(a.model._w(a.meta.w) / tau, a.meta.dt / tau)
    u0 = 2.0 * c1 / (a.n * q["n0"])
    return float(jnp.max(jnp.abs(u0) * jnp.sqrt(a.n)))
