"""Variance-based estimators (paper sections 6.1-6.3, appendix B).

- sample variance with the correlated-sample standard error (DESIGN item 10);
- naive and blur-corrected equipartition;
- variance vs exposure / variance vs power: weighted least squares (optimistix
  Levenberg-Marquardt in log parameters), weights from the model's own correlated-sample
  standard errors, iterated;
- drift: progressive ideal high-pass and extrapolation to 0 Hz (appendix B).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..physics._constants import BOLTZMANN
from ..physics._spectra import _sample_variance_var
from ._models import TrapModel
from ._problems import Layout, RecMeta


def empirical_variance_se(y, max_lag: int | None = None) -> tuple[float, float]:
    """Sample variance and a model-free standard error from the empirical autocovariance
    (``var(s^2) ~ (2/N) sum_n C(n)^2`` summed until C(n) first drops below zero)."""
    y = np.asarray(y, dtype=float)
    n = y.size
    yc = y - y.mean()
    v = float(np.mean(yc * yc))
    spec = np.fft.rfft(yc, 2 * n)
    acov = np.fft.irfft(np.abs(spec) ** 2)[:n] / n
    m = max_lag or min(n - 1, 10_000)
    c = acov[: m + 1]
    stop = np.argmax(c <= 0) if np.any(c <= 0) else len(c)
    c = c[: max(stop, 1)]
    var_s2 = 2.0 / n * (c[0] ** 2 + 2.0 * np.sum(c[1:] ** 2))
    return v, float(np.sqrt(var_s2))


def _expected_sample_variance(n, c0, c1, rho):
    """E[(1/N) sum (y - ybar)^2] = C0 - Var(ybar), Var(ybar) in closed form."""
    r = -jnp.log(rho)
    one_m = -jnp.expm1(-r)
    one_m_n = -jnp.expm1(-r * n)
    geo = (n * one_m - one_m_n) / one_m**2  # sum_{m=1}^{N-1} (N-m) rho^(m-1)
    geo = jnp.where(r * n < 1e-8, n * (n - 1.0) / 2.0, geo)
    var_mean = (n * c0 + 2.0 * c1 * geo) / n**2
    return c0 - var_mean


class VarianceArgs(eqx.Module):
    layout: Layout
    model: TrapModel
    meta: RecMeta
    v: jax.Array  # sample variances (ddof 0)
    n: jax.Array  # frames per recording
    se: jax.Array  # weights (standard errors) for this pass


def _predicted(p, a: VarianceArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    c0, c1, rho = a.model.moments(k_rec, gamma, eps2, a.meta.dt, a.meta.w, a.meta.temp)
    return _expected_sample_variance(a.n, c0, c1, rho)


def _predicted_se(p, a: VarianceArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    sigma2 = BOLTZMANN * a.meta.temp / k_rec
    tau = gamma / k_rec
    w = a.meta.w if a.model.blur else jnp.zeros_like(a.meta.w)
    return jnp.sqrt(_sample_variance_var(a.n, sigma2, tau, w, a.meta.dt, eps2))


def _residuals(x, a_scale):
    a, scale = a_scale
    p = scale * jnp.exp(x)
    return (a.v - _predicted(p, a)) / a.se


@eqx.filter_jit
def _lsq(a: VarianceArgs, scale, x0):
    sol = optx.least_squares(
        _residuals,
        optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10),
        x0,
        args=(a, scale),
        max_steps=500,
        throw=False,
    )
    p = scale * jnp.exp(sol.value)

    def r_u(u):
        return (a.v - _predicted(scale * u, a)) / a.se

    jac = jax.jacfwd(r_u)(jnp.exp(sol.value))
    fisher = jac.T @ jac
    evals = jnp.linalg.eigvalsh(fisher)
    pd = jnp.all(evals > 1e-12 * jnp.max(evals)) & jnp.all(jnp.isfinite(evals))
    cov = jnp.linalg.inv(fisher) * scale[:, None] * scale[None, :]
    res = r_u(jnp.exp(sol.value))
    return p, jnp.where(pd, cov, jnp.nan), jnp.sum(res**2), sol.result == optx.RESULTS.successful, pd


def fit_variances(args: VarianceArgs, scale, n_iter: int = 3):
    """Iteratively reweighted least squares: weights = model SE at the current estimate.

    The parametrisation ``p = scale * exp(x)`` keeps the start values as fixed scales (so the
    conditioning test does not depend on how close eps^2 came to 0); each pass warm-starts.
    """
    p = scale
    x = jnp.zeros_like(scale)
    for _ in range(n_iter):
        args = eqx.tree_at(lambda a: a.se, args, _predicted_se(p, args))
        p, cov, chi2, ok, pd = _lsq(args, scale, x)
        x = jnp.log(p / scale)
    return p, cov, chi2, ok, pd


def highpass_variance_curve(y, frame_interval, cutoffs):
    """Variance of ``y`` after an ideal (FFT) high-pass at each cut-off frequency [Hz]."""
    y = np.asarray(y, dtype=float)
    n = y.size
    spec = np.fft.rfft(y - y.mean())
    f = np.fft.rfftfreq(n, frame_interval)
    p = np.abs(spec) ** 2 / n**2
    p[1:] *= 2.0
    if n % 2 == 0:
        p[-1] /= 2.0
    # variance that survives a cut at f1 = sum of power at f >= f1
    order = np.cumsum(p[::-1])[::-1]
    idx = np.searchsorted(f, np.asarray(cutoffs), side="left")
    return order[np.minimum(idx, len(order) - 1)]


def drift_extrapolation(y, frame_interval, *, corner_frequency, fraction=(0.1, 0.5), n_cut=20):
    """Progressive high-pass + linear extrapolation of variance to 0 Hz (appendix B).

    Fits ``var(f1) = v0 + s f1`` for cut-offs in ``fraction * f_c`` (the linear region below
    the corner frequency), where drift no longer contributes but the slope is still that of
    the flat low-frequency PSD. Returns ``(v0, slope, cutoffs, variances)``; for an ideal
    high-pass the expected slope is ``-2 P_d(0)`` (DESIGN item 8).
    """
    lo, hi = fraction
    cut = np.linspace(lo * corner_frequency, hi * corner_frequency, n_cut)
    v = highpass_variance_curve(y, frame_interval, cut)
    a = np.vstack([np.ones_like(cut), cut]).T
    coef, *_ = np.linalg.lstsq(a, v, rcond=None)
    return float(coef[0]), float(coef[1]), cut, v
