"""The scatter of the design's estimates with the bound eps^2 >= 0 of the fit (the
projected-Gaussian covariance; benchmarks/RESULTS_design.md, "The bound eps^2 >= 0 in the
prediction")."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp


def bounded_covariance(cov):
    """The covariance ``cov`` (..., n_par, n_par) of the estimates when eps^2 >= 0 is enforced.

    Near eps^2 = 0 the fit's eps^2 lands on its bound in a fraction ``Phi(-z)`` of the
    experiments (``z = 1 / relative SE of eps^2``), and there k and gamma move to the
    constrained optimum, which reduces their scatter below the unconstrained Cramer-Rao bound
    (design b of benchmarks/RESULTS_design.md: SD/CRB 0.87-0.88). In the quadratic
    approximation of the log-likelihood the unconstrained estimate is ``Z ~ N(theta, cov)``
    (eps^2 in natural units) and the constrained one its projection onto ``eps^2 >= 0`` in the
    metric ``inv(cov)``: ``theta_o = Z_o - (cov_oe / cov_ee) min(Z_e, 0)``, so
    ``Cov(theta_o) = cov_oo - (1 - v) cov_oe cov_eo / cov_ee`` with ``v`` the variance of the
    censored normal ``max(Z_e, 0)`` in units of ``cov_ee``. Without a noise parameter (2 x 2),
    or far from the bound (``v`` -> 1), ``cov`` is returned unchanged. Rows of log eps^2 become
    the relative scatter of eps^2 itself (the censored estimate can be 0)."""
    if cov.shape[-1] < 3:
        return cov
    s_ee = cov[..., 2, 2]
    z = 1.0 / jnp.sqrt(s_ee)  # mean / SD of eps^2's estimate (relative SE in log units)
    cdf = jax.scipy.special.ndtr(z)
    pdf = jnp.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
    m1 = z * cdf + pdf
    m2 = (z * z + 1.0) * cdf + z * pdf
    v = jnp.clip(m2 - m1 * m1, 0.0, 1.0)
    c = cov[..., :, 2]
    return cov - ((1.0 - v) / s_ee)[..., None, None] * c[..., :, None] * c[..., None, :]


def bound_probability(cov):
    """Probability that eps^2's estimate sits at its bound 0: ``Phi(-1 / relative SE)``
    (0 without a noise parameter)."""
    if cov.shape[-1] < 3:
        return jnp.zeros(cov.shape[:-2])
    return jax.scipy.special.ndtr(-1.0 / jnp.sqrt(cov[..., 2, 2]))
