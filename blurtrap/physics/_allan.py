r"""Exact Allan variance of blurred, sampled, noisy frames (DESIGN section 2, item 5).

For a stationary frame sequence with autocovariance ``C(n)``, let ``Y_n`` be the sum of the
first n frames and ``V(n) = Var(Y_n) = n C(0) + 2 sum_{l=1}^{n-1} (n - l) C(l)``. The
overlapping Allan variance at cluster size m (averaging time ``m dt``) is half the mean square
difference of adjacent m-frame means, ``(Y_{2m} - 2 Y_m)^2 / (2 m^2)``, whose expectation is

$$\sigma^2_A(m) = \frac{4 V(m) - V(2m)}{2 m^2}.$$

With ``C(l) = c_1 \rho^{l-1}`` for l >= 1 (``c_1 = sigma2 rho B(alpha)``, the trap seen through
an exposure ``W <= dt``, plus white tracking noise in ``C(0)``) the sum is geometric:
``sum_{l=1}^{n-1} (n-l) rho^{l-1} = [n u - (1 - rho^n)] / u^2`` with ``u = 1 - rho``, so

$$\sigma^2_A(m) = \frac{m C(0) + c_1 (2 m u - 2 P - P^2)/u^2}{m^2}, \quad P = 1 - \rho^m,$$

evaluated with ``expm1`` (u and P never lose precision). No truncation, any ``W <= dt``.

Covariance of the estimator: the second differences ``d_k = Y_{k+2m} - 2 Y_{k+m} + Y_k`` are
linear in the ``Y``; for coefficient vectors a, b with zero sum,
``Cov(sum a_p Y_{s_p}, sum b_q Y_{t_q}) = -1/2 sum_{p,q} a_p b_q V(|s_p - t_q|)``, and for
Gaussian frames ``Cov(d^2, e^2) = 2 Cov(d, e)^2``; see
``blurtrap.inference._allan.allan_covariance``.
"""

from __future__ import annotations

import jax.numpy as jnp

from ._spectra import _autocovariance


def _geo(n, r):
    """``sum_{l=1}^{n-1} (n - l) rho^(l-1)`` with ``rho = exp(-r)``, exact for all n >= 0."""
    u = -jnp.expm1(-r)
    p = -jnp.expm1(-r * n)
    return (n * u - p) / u**2


def frame_moments(sigma2, tau, exposure, frame_interval, tracking_var):
    """``(C(0), c_1, r)`` of the frames: ``C(l) = c_1 exp(-r (l - 1))`` for l >= 1."""
    args = (sigma2, tau, exposure, frame_interval, tracking_var)
    return _autocovariance(0, *args), _autocovariance(1, *args), frame_interval / tau


def block_sum_variance(n, c0, c1, r):
    """``V(n)``: variance of the sum of n consecutive frames (``V(0) = 0``)."""
    n = jnp.asarray(n, dtype=jnp.result_type(c0, float))
    nz = jnp.maximum(n, 1.0)
    return jnp.where(n > 0, nz * c0 + 2.0 * c1 * _geo(nz, r), 0.0)


def allan_from_moments(m, c0, c1, r):
    """Expected overlapping Allan variance at cluster sizes ``m`` [m^2]."""
    m = jnp.asarray(m, dtype=jnp.result_type(c0, float))
    u = -jnp.expm1(-r)
    p = -jnp.expm1(-r * m)
    num = 2.0 * m * u - 2.0 * p - p * p  # 4 G(m) - G(2m) times u^2; G as in _geo
    return (m * c0 + c1 * num / u**2) / m**2


def allan_variance_model(m, sigma2, tau, exposure, frame_interval, tracking_var=0.0):
    r"""Exact expected overlapping Allan variance [m^2] of frames at cluster sizes ``m``
    (averaging times ``m * frame_interval``): trap variance `sigma2` [m^2], relaxation time
    `tau` [s], exposure W <= dt [s], frame interval dt [s], tracking-error variance [m^2]."""
    c0, c1, r = frame_moments(sigma2, tau, exposure, frame_interval, tracking_var)
    return allan_from_moments(m, c0, c1, r)
