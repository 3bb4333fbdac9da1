r"""Host-side (NumPy, float64) coefficients of the simulator, in units of sigma and tau.

Everything here is dimensionless: positions in units of ``sigma = sqrt(kT/k)``, times in
units of ``tau = gamma/k``. The coefficients are computed once per call in float64 and only
then cast to the simulation dtype, so a float32 simulation keeps float32-relative accuracy.

Exact joint law of one exposure segment (used by ``method="exact_frames"``)
---------------------------------------------------------------------------
For a unit OU process ``dx = -x dt + sqrt(2) dB`` started at ``x0`` and a segment of
dimensionless length ``L``, the end point ``x_L`` and the segment average
``m = (1/L) int_0^L x dt`` are jointly Gaussian given ``x0`` with

$$E[x_L|x_0] = e^{-L} x_0,\qquad E[m|x_0] = x_0\,\varphi_1(L),\quad
  \varphi_1(L) = \frac{1-e^{-L}}{L},$$
$$\mathrm{var}(x_L|x_0) = 1-e^{-2L},\qquad
  \mathrm{var}(m|x_0) = S(L) - \varphi_1(L)^2,\qquad
  \mathrm{cov}(x_L, m|x_0) = \frac{(1-e^{-L})^2}{L} = L\,\varphi_1(L)^2 .$$

(``cov(x_s, x_t|x0) = e^{-|t-s|} - e^{-(s+t)}``; integrate once or twice over the segment.)
The unconditional check: ``var(m) = phi1^2 + (S - phi1^2) = S(L)`` as it must.
``g(L) = S - phi1^2`` cancels for small L, so it is summed as the series
``g = sum_{n>=1} (-1)^n (4 - 2^{n+2}) L^n / (n+2)!`` (``= 2L/3 - L^2/2 + ...``) below 0.5.

Innovations form of the frames (one exposure window, regular frames)
--------------------------------------------------------------------
With ``a = W/tau`` and ``c = e^{-r}`` (``r = dt/tau``) the frames have ``C(0) = S(a)`` and
``C(n) = c^n q(a)`` for ``n >= 1``, ``q = (sinh(a/2)/(a/2))^2`` (integrate
``e^{-|t-s|}`` over two exposures ``n dt`` apart). So ``Y_m = X_m - c X_{m-1}`` is MA(1):

$$\gamma_Y(0) = (1-c^2)\,S - 2c^2 D,\qquad \gamma_Y(1) = c\,D,\qquad
  D = q - S = \frac{2(\sinh a - a)}{a^2} = \frac{a}{3} + \frac{a^3}{60} + \dots$$

(no cancellation: ``2 c^2 D <= (1 - c^2) S / 3``, measured over ``a <= r``). Its invertible
MA(1) form ``Y_m = e_m + b e_{m-1}``, ``e_m ~ N(0, s^2)``, has
``b = 2 rho/(1 + sqrt(1 - 4 rho^2))`` (``rho = gamma_Y(1)/gamma_Y(0)``: ``|rho| < 1/2`` as the
spectrum is positive; measured ``0 <= rho <= 1/4``) and
``s^2 = gamma_Y(0)/(1 + b^2)``. The frames are then exactly the stationary ARMA(1,1)

$$X_m = \hat x_m + e_m,\qquad \hat x_{m+1} = c\,\hat x_m + (c + b)\,e_m,\qquad
  \hat x_0 \sim N\big(0,\ v\big),\ v = \frac{(c+b)^2 s^2}{1-c^2},$$

``x_hat_m = E[X_m | X_{m-1}, X_{m-2}, ...]`` the one-step predictor (``v = S - s^2``): one
normal per frame instead of the two of the segment law.

Decay by increments
-------------------
Every scan updates ``x' = x + (m x + noise)`` with ``m = e^{-h} - 1 = expm1(-h)`` rather than
``x' = e^{-h} x + noise``: rounded to float32, ``e^{-h}`` moves ``1 - e^{-h}`` by up to
~3e-8/h relative, which biases the stationary variance (-2e-4 at h = 1e-4 tau, -1e-2 at
1e-6), while ``m`` keeps float32-relative accuracy at any h (tests/simulate/
test_core_float32.py).
"""

from __future__ import annotations

import math

import numpy as np

_CUT = 0.5
_NT = 20
_S_C = np.array([2.0 * (-1.0) ** n / math.factorial(n + 2) for n in range(_NT)])
_PHI1_C = np.array([(-1.0) ** n / math.factorial(n + 1) for n in range(_NT)])
_G_C = np.array([(-1.0) ** n * (4.0 - 2.0 ** (n + 2)) / math.factorial(n + 2) for n in range(_NT)])


def _series(a, coeffs):
    acc = np.zeros_like(a) + coeffs[-1]
    for c in coeffs[-2::-1]:
        acc = acc * a + c
    return acc


def s_blur(a):
    """S(a) in float64 NumPy (series below 0.5)."""
    a = np.asarray(a, dtype=np.float64)
    al = np.where(a < _CUT, 1.0, a)
    closed = (2.0 / al) * (1.0 + np.expm1(-al) / al)
    return np.where(a < _CUT, _series(a, _S_C), closed)


def phi1(a):
    """(1 - e^-a)/a in float64 NumPy."""
    a = np.asarray(a, dtype=np.float64)
    al = np.where(a < _CUT, 1.0, a)
    return np.where(a < _CUT, _series(a, _PHI1_C), -np.expm1(-al) / al)


def cond_avg_var(a):
    """var(m | x0) = S(a) - phi1(a)^2, without cancellation."""
    a = np.asarray(a, dtype=np.float64)
    al = np.where(a < _CUT, 1.0, a)
    return np.where(a < _CUT, _series(a, _G_C), s_blur(al) - phi1(al) ** 2)


def segment_law(length):
    """Coefficients of the exact segment draw (all float64 arrays of ``length``'s shape).

    Returns ``(e - 1, p, s_m, c_x, s_x)`` (``e = e^{-L}``; ``e - 1 = expm1(-L)`` for the
    update by increments) such that, with independent standard normals z1, z2,

        m   = p x0 + s_m z1
        x_L = e x0 + c_x z1 + s_x z2

    reproduces the joint Gaussian law in the module docstring.
    """
    L = np.asarray(length, dtype=np.float64)
    p = phi1(L)
    g = cond_avg_var(L)
    vx = -np.expm1(-2.0 * L)
    cxm = L * p * p
    s_m = np.sqrt(g)
    safe = np.where(g > 0, s_m, 1.0)
    c_x = np.where(g > 0, cxm / safe, 0.0)
    s_x = np.sqrt(np.maximum(vx - c_x * c_x, 0.0))
    return np.expm1(-L), p, s_m, c_x, s_x


_D_C = np.array([2.0 / math.factorial(2 * k + 3) for k in range(_NT)])  # D/a in powers of a^2


def innovations_law(a, r):
    """Coefficients ``(c - 1, c + b, s, sqrt(v))`` of the frames' innovations form (module
    docstring; ``c - 1 = expm1(-r)`` for the update by increments) for exposure ``a = W/tau``
    and frame interval ``r = dt/tau >= a`` (float64)."""
    a = np.asarray(a, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    c = np.exp(-r)
    one_c2 = -np.expm1(-2.0 * r)
    al = np.where(a < _CUT, 1.0, a)
    # c D, without overflow of sinh for long exposures (r >= a)
    cd_closed = (np.exp(al - r) - np.exp(-al - r) - 2.0 * al * c) / (al * al)
    cd = np.where(a < _CUT, c * a * _series(a * a, _D_C), cd_closed)
    g0 = one_c2 * s_blur(a) - 2.0 * c * cd
    rho = cd / g0
    b = 2.0 * rho / (1.0 + np.sqrt(np.maximum(1.0 - 4.0 * rho * rho, 0.0)))
    s2 = g0 / (1.0 + b * b)
    v = (c + b) ** 2 * s2 / one_c2
    return np.expm1(-r), c + b, np.sqrt(s2), np.sqrt(v)


def ou_step(h):
    """Exact OU substep by increments: ``x' = x + (m x + s z)`` with ``m = e^-h - 1`` (computed
    as ``expm1(-h)``) and ``s = sqrt(1 - e^-2h)``; see "Decay by increments" above."""
    h = np.asarray(h, dtype=np.float64)
    return np.expm1(-h), np.sqrt(-np.expm1(-2.0 * h))


def trapezoid_bias(a, n):
    """Estimated relative bias of var(X_m) from the trapezoid average of n exact substeps.

    Given the substep end points, the exact integral differs from the trapezoid by a
    Brownian-bridge term of variance ``h^3/6`` per substep (h = a/n), independent of the end
    points to leading order, so ``var`` is underestimated by ``a/(6 n^2)`` (in sigma^2),
    i.e. relatively by ``a / (6 n^2 S(a))``.
    """
    a = np.asarray(a, dtype=np.float64)
    return a / (6.0 * n * n * s_blur(a))


def euler_bias(h):
    """Relative bias of the stationary variance of Euler-Maruyama OU: ``1/(1-h/2) - 1``."""
    h = np.asarray(h, dtype=np.float64)
    return np.where(h < 2.0, (h / 2.0) / np.maximum(1.0 - h / 2.0, 1e-300), np.inf)
