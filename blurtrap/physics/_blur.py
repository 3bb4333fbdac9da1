r"""The motion-blur function :math:`S(\alpha)`, its Pade form and their inversions.

References: Wong & Halvorsen, Opt. Express 14, 12517 (2006), eqs. (6), (7), (11) and
appendix D.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._checks import check_nonnegative, check_positive, is_concrete
from ._constants import BOLTZMANN, DEFAULT_TEMPERATURE

# Below this alpha the closed form loses digits to cancellation; the Taylor series
# S = sum_n 2 (-a)^n / (n+2)! is used instead. 10 terms at a = 0.1 truncate at ~1e-19, and the
# closed form loses at most ~20 ulp at a = 0.1. (Few terms keep the compiled Hessians small.)
_SERIES_CUT = 0.1
_N_TERMS = 10
_S_COEFFS = tuple(2.0 * (-1.0) ** n / math.factorial(n + 2) for n in range(_N_TERMS))
# phi1(a) = (1 - exp(-a)) / a = sum_n (-a)^n / (n+1)!
_PHI1_COEFFS = tuple((-1.0) ** n / math.factorial(n + 1) for n in range(_N_TERMS))
# (sinh(a) - a) / (a^3) = sum_{m>=0} a^(2m) / (2m+3)!  (B - S for a < 1; 9 terms: < 1e-19)
_BMS_CUT = 1.0
_SH_COEFFS = tuple(1.0 / math.factorial(2 * m + 3) for m in range(9))


def _horner(x, coeffs):
    acc = jnp.zeros_like(x) + coeffs[-1]
    for c in coeffs[-2::-1]:
        acc = acc * x + c
    return acc


def _split(a, cut=None):
    """Safe arguments for the series (small) and closed-form (large) branches, so that
    neither branch produces inf/NaN that could leak into gradients through ``jnp.where``.

    The cut is 0.1 in float64 and 1.0 in lower precision (where 10 terms still truncate
    below float32 resolution and the closed form would lose ~20 ulp at 0.1)."""
    if cut is None:
        a = jnp.asarray(a)
        cut = _SERIES_CUT if jnp.finfo(a.dtype).bits >= 64 else 1.0
    small = a < cut
    return small, jnp.where(small, a, 0.0), jnp.where(small, 1.0, a)


def _blur_factor(a):
    """S(a) without input checks (a >= 0)."""
    small, a_s, a_l = _split(a)
    s_series = _horner(a_s, _S_COEFFS)
    # S = (2/a) (1 - (1 - e^-a)/a) = (2/a) (1 + expm1(-a)/a): no overflow for huge a.
    s_closed = (2.0 / a_l) * (1.0 + jnp.expm1(-a_l) / a_l)
    return jnp.where(small, s_series, s_closed)


def _phi1(a):
    """(1 - exp(-a)) / a, stable at a -> 0 (value 1)."""
    small, a_s, a_l = _split(a)
    return jnp.where(small, _horner(a_s, _PHI1_COEFFS), -jnp.expm1(-a_l) / a_l)


def _b_minus_s_series(a):
    """B(a) - S(a) = 2 (sinh a - a)/a^2 = 2 a sum_m a^(2m)/(2m+3)!, for 0 <= a < 1."""
    return 2.0 * a * _horner(a * a, _SH_COEFFS)


def _rho_b(a, r):
    """rho * B(a) with rho = exp(-r), r = dt/tau >= a: overflow-free for large a.

    B(a) = (sinh(a/2)/(a/2))^2 = e^a phi1(a)^2, so rho B = phi1(a)^2 exp(a - r).
    """
    return _phi1(a) ** 2 * jnp.exp(a - r)


def _rho_b_minus_s(a, r, s=None, rho_b=None):
    """rho * (B(a) - S(a)), stable for small and large a.

    ``s = S(a)`` and ``rho_b = rho B(a)`` may be passed in when already computed.
    """
    small = a < _BMS_CUT
    direct = jnp.exp(-r) * _b_minus_s_series(jnp.where(small, a, 0.0))
    if s is None:
        s = _blur_factor(a)
    if rho_b is None:
        rho_b = _rho_b(a, r)
    # a >= 1: rho B - rho S has no cancellation trouble (B - S >= 0.33 B there)
    large = rho_b - jnp.exp(-r) * s
    return jnp.where(small, direct, large)


def blur_factor(alpha):
    r"""Motion-blur correction :math:`S(\alpha)` (Wong & Halvorsen 2006, eq. 6).

    $$S(\alpha) = \frac{2}{\alpha} - \frac{2}{\alpha^2}\left(1 - e^{-\alpha}\right)
      = \sum_{n\ge 0} \frac{2(-\alpha)^n}{(n+2)!}$$

    The ratio var(X_m)/var(X) for a rectangular exposure of length W = alpha * tau.
    Numerically stable for all alpha >= 0 in float32 and float64 (Taylor series below
    alpha = 0.1 in float64 and 1.0 in lower precision, ``expm1`` form above; relative error
    below ~1e-14 in float64, largest just above the cut, where the closed form loses ~40 ulp
    to cancellation), ``S(0) = 1``, ``S -> 2/alpha`` for large alpha;
    gradients are finite everywhere including alpha = 0 (``dS/dalpha(0) = -1/3``).

    **Arguments:**

    - `alpha`: dimensionless exposure ``W / tau`` (>= 0); scalar or array.

    **Returns:** ``S(alpha)``, same shape and float dtype as ``alpha``.

    **Raises:** ``ValueError`` if a concrete ``alpha`` is negative or not finite.
    """
    a = check_nonnegative("alpha", alpha, what="dimensionless exposure W/tau")
    return _blur_factor(a)


def blur_factor_pade(alpha):
    r"""Pade approximant of S (appendix D): ``(1 - 2a/15 + a^2/60) / (1 + a/5)``.

    Within 3 % of :func:`blur_factor` for alpha < 3.
    """
    a = check_nonnegative("alpha", alpha, what="dimensionless exposure W/tau")
    return (1.0 - 2.0 * a / 15.0 + a * a / 60.0) / (1.0 + a / 5.0)


def measured_variance(k, gamma, exposure, temperature=DEFAULT_TEMPERATURE, tracking_var=0.0):
    r"""Variance of the exposure-averaged position (eqs. 7 and 11).

    $$\mathrm{var}(X_m) = \frac{k_B T}{k} S\!\left(\frac{W k}{\gamma}\right) + \varepsilon^2$$

    **Arguments:** (SI units; all broadcast)

    - `k`: trap stiffness [N/m], > 0.
    - `gamma`: friction coefficient [N s/m], > 0.
    - `exposure`: exposure (integration) time W [s], > 0.
    - `temperature`: absolute temperature [K], > 0.
    - `tracking_var`: tracking-error variance eps^2 [m^2], >= 0.

    **Returns:** var(X_m) [m^2].
    """
    k = check_positive("k", k, "N/m", what="trap stiffness")
    gamma = check_positive("gamma", gamma, "N s/m", what="friction coefficient")
    w = check_positive("exposure", exposure, "s", what="exposure time W")
    t = check_positive("temperature", temperature, "K")
    eps2 = check_nonnegative("tracking_var", tracking_var, "m^2", what="tracking-error variance")
    return BOLTZMANN * t / k * _blur_factor(w * k / gamma) + eps2


@jax.jit
def _inverse_s_over_alpha(y):
    """Solve S(alpha)/alpha = y (y > 0) for alpha by Newton's method on log alpha.

    F(x) = log S(e^x) - x - log y has slope in [-2, -1], so Newton converges from the
    asymptotic start alpha0 = min(1/y, sqrt(2/y)) in a few steps.
    """
    log_y = jnp.log(y)

    def fn(x, args):
        a = jnp.exp(x)
        return jnp.log(_blur_factor(a)) - x - args

    def solve_one(ly):
        y1 = jnp.exp(ly)
        x0 = jnp.log(jnp.minimum(1.0 / y1, jnp.sqrt(2.0 / y1)))
        tol = 1e-13 if x0.dtype == jnp.float64 else 1e-6
        sol = optx.root_find(fn, optx.Newton(rtol=tol, atol=tol), x0, args=ly, max_steps=64)
        return jnp.exp(sol.value)

    flat = log_y.reshape(-1)
    return jax.vmap(solve_one)(flat).reshape(log_y.shape)


def stiffness_from_variance(
    measured_var,
    diffusion,
    exposure,
    temperature=DEFAULT_TEMPERATURE,
    tracking_var=0.0,
    method="exact",
):
    r"""Invert :func:`measured_variance` for the stiffness k, given D and W (section 6.1).

    ``method="exact"`` solves ``(kT/k) S(W D k / kT) = var - eps^2`` with an optimistix
    Newton root find (differentiable through the implicit-function theorem; relative accuracy
    ~1e-13 in float64). ``method="pade"`` uses the closed form of appendix D,

    $$k \approx \frac{30 k_B T}{2 D W + 15 v + \sqrt{225 v^2 + 240 D W v - 11 D^2 W^2}},$$

    with ``v = var - eps^2``; it is within ~3 % while alpha < 3 and is not defined when the
    square root's argument is negative (very strong blur).

    **Arguments:** `measured_var` [m^2]; `diffusion` D [m^2/s]; `exposure` W [s];
    `temperature` [K]; `tracking_var` eps^2 [m^2]; `method` "exact" or "pade".

    **Returns:** k [N/m].

    **Raises:** ``ValueError`` for non-positive inputs, ``measured_var <= tracking_var``,
    an unknown method, or (Pade) a negative discriminant.
    """
    if method not in ("exact", "pade"):
        raise ValueError(f"method must be 'exact' or 'pade'; got method = {method!r}")
    v = check_positive("measured_var", measured_var, "m^2", what="measured variance")
    d = check_positive("diffusion", diffusion, "m^2/s", what="diffusion coefficient D")
    w = check_positive("exposure", exposure, "s", what="exposure time W")
    t = check_positive("temperature", temperature, "K")
    eps2 = check_nonnegative("tracking_var", tracking_var, "m^2", what="tracking-error variance")
    u = v - eps2
    if is_concrete(u) and np.any(np.asarray(u) <= 0):
        raise ValueError(
            "measured_var must exceed tracking_var (the blurred Brownian variance "
            f"measured_var - tracking_var must be > 0); got measured_var - tracking_var = "
            f"{np.asarray(u).min():.6g} m^2"
        )
    kt = BOLTZMANN * t
    dw = d * w
    if method == "pade":
        disc = 225.0 * u * u + 240.0 * dw * u - 11.0 * dw * dw
        if is_concrete(disc) and np.any(np.asarray(disc) < 0):
            raise ValueError(
                "the Pade closed form has no solution here (blur too strong: "
                "225 v^2 + 240 D W v - 11 D^2 W^2 < 0); use method='exact'"
            )
        k = 30.0 * kt / (2.0 * dw + 15.0 * u + jnp.sqrt(jnp.maximum(disc, 0.0)))
        if is_concrete(k):
            alpha = np.asarray(dw * k / kt)
            if np.any(alpha > 3.0):
                warnings.warn(
                    f"Pade inversion used at alpha = W/tau = {alpha.max():.3g} > 3, outside its "
                    "3 % accuracy range; use method='exact'",
                    RuntimeWarning,
                    stacklevel=2,
                )
        return k
    u, dw = jnp.broadcast_arrays(u, dw)
    alpha = _inverse_s_over_alpha(u / dw)
    return alpha * kt / dw


# Unchecked kernels shared with the estimators (``blurtrap.inference``), whose optimisers need
# them without input checks (trial points may be extreme); public under these names.
blur_factor_unchecked = _blur_factor  # S(alpha) for alpha >= 0, no checks
rho_b_unchecked = _rho_b  # rho B(alpha) with rho = exp(-r), r = dt/tau >= alpha, no checks
