r"""Exact moments of blurred, sampled frames of a bead in a quartic trap (no simulation).

Dimensionless units: positions in ``sigma0 = sqrt(kT/k)``, times in ``tau = gamma/k``. The
bead diffuses (D = 1) in ``u(x) = x^2/2 + beta x^4/4`` with ``beta = k4 kT/k^2``; a frame is
the average of ``x`` over its exposure ``[0, w]`` (``w = W/tau``), frames start every
``d = dt/tau``.

**Generator.** The Fokker-Planck generator is replaced by the reversible birth-death chain on
a uniform grid ``x_i`` (spacing ``h``) with hopping rates ``h^-2 exp(-(u_j - u_i)/2)``
between neighbours (Scharfetter-Gummel / Boltzmann-weighted finite volumes). Its stationary
law is *exactly* ``exp(-u(x_i))`` on the grid and its spectrum converges as ``O(h^2)`` to the
diffusion's; symmetrised by ``sqrt(pi)`` it is the tridiagonal matrix ``H`` below. With
``H = V diag(lam) V^T`` and the position operator ``X = V^T diag(x) V``:

- ``E[x(0) x(t)] = sum_a X_0a^2 exp(-lam_a t)``, so every mode is an Ornstein-Uhlenbeck-like
  exponential and the exposure average is the closed form of the harmonic case per mode:
  ``var = sum_a X_0a^2 S(lam_a w)``, ``C(l) = sum_a X_0a^2 ((1 - e^{-z_a})/z_a)^2
  e^{-lam_a (l d - w)}`` (``z_a = lam_a w``, ``l >= 1``);
- ``E[m^4]`` of a frame ``m`` is ``24/w^4`` times the integral over ordered times of the
  four-point function ``sum_abc X_0a X_ab X_bc X_c0 e^{-lam_a s1 - lam_b s2 - lam_c s3}``;
  the integral over the 4-simplex is the (0, 4) entry of ``expm`` of the 5x5 bidiagonal
  matrix with diagonal ``(0, -z_a, -z_b, -z_c, 0)`` and unit superdiagonal (Hermite-Genocchi
  / Opitz: a divided difference of ``exp``); at ``w = 0`` it is ``1/24`` and ``E[m^4]`` is the
  Boltzmann ``<x^4>``. Parity (``X_ab = 0`` unless ``a + b`` is odd) leaves ``a, c`` odd and
  ``b`` even.

Approximations: the grid (``n_grid`` points spanning ``u(x) <= 20``, error ``O(h^2)``: relative
error of the moments ~1e-4 for the variance and kurtosis and ~5e-3 for C(l) at l d ~ 3 with
121 points, ~4x less with 241, against statistical errors of several per cent (C at 3 tau:
tens of per cent); checked against the closed-form
harmonic S, B and Boltzmann quadrature in tests/inference/test_anharmonic.py) and the
truncation to the lowest ``n_modes`` modes (neglected part < 1e-9 at 16 modes for
-0.08 <= beta <= 20). For ``beta < 0`` a quartic potential does not confine; the moments are
continued by ``u = x^2/2 + beta x^4/4 + beta^2 x^6/20`` (confining for every beta < 0, equal
to the quartic with its first derivative in beta at beta = 0; the kurtosis stays monotone in
beta down to beta ~ -0.1), so that ``beta = 0`` is an interior point of a fit and a harmonic
trap gives ``k4`` scattered about 0 (fits are bounded to ``beta >= -0.08``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

U_MAX = 20.0  # the grid spans u(x) <= U_MAX (density >= e^-20)
SEXTIC = 0.05  # beta < 0 continuation: + SEXTIC beta^2 x^6 (confining for SEXTIC > 1/24)


def _phi1(z):
    """(1 - e^{-z})/z, stable at z -> 0."""
    zs = jnp.where(z < 1e-4, 1.0, z)
    return jnp.where(z < 1e-4, 1.0 - z / 2.0 + z * z / 6.0, -jnp.expm1(-zs) / zs)


def _s_blur(z):
    """S(z) = 2 (z - 1 + e^{-z}) / z^2 (the blurred/unblurred variance of one exponential)."""
    zs = jnp.where(z < 1e-3, 1.0, z)
    big = 2.0 * (zs + jnp.expm1(-zs)) / (zs * zs)
    return jnp.where(z < 1e-3, 1.0 - z / 3.0 + z * z / 12.0 - z**3 / 60.0, big)


def spectrum(beta, n_grid=121, n_modes=16):
    """Eigenvalues ``lam`` (ascending, ``lam_0 = 0``) and position matrix elements ``X``
    (``n_modes x n_modes``) of the grid generator at ``beta``."""
    bp = jnp.maximum(beta, 0.0)
    x_max = jnp.sqrt(4.0 * U_MAX / (jnp.sqrt(1.0 + 4.0 * bp * U_MAX) + 1.0))  # u(x_max) = U_MAX
    x = jnp.linspace(-1.0, 1.0, n_grid) * x_max
    h = x[1] - x[0]
    u = 0.5 * x * x + 0.25 * beta * x**4 + SEXTIC * jnp.minimum(beta, 0.0) ** 2 * x**6
    du = jnp.clip(jnp.diff(u), -200.0, 200.0)
    right = jnp.concatenate([jnp.exp(-du / 2.0), jnp.zeros(1)])  # i -> i+1
    left = jnp.concatenate([jnp.zeros(1), jnp.exp(du / 2.0)])  # i -> i-1
    off = -jnp.ones(n_grid - 1)
    hmat = (jnp.diag(right + left) + jnp.diag(off, 1) + jnp.diag(off, -1)) / (h * h)
    lam, v = jnp.linalg.eigh(hmat)
    v = v[:, :n_modes]
    xm = (v * x[:, None]).T @ v
    return jnp.maximum(lam[:n_modes], 0.0), xm


def _simplex4(za, zb, zc):
    """Integral over the unit 4-simplex of exp(-za s1 - zb s2 - zc s3) (s0..s4 >= 0, sum 1)."""
    zero = jnp.zeros_like(za)
    diag = jnp.stack([zero, -za, -zb, -zc, zero], axis=-1)
    a = jax.vmap(jnp.diag)(diag) + jnp.diag(jnp.ones(4), 1)[None]
    return jax.vmap(jsl.expm)(a)[:, 0, 4]


def frame_moments(beta, w, d, lags, n_grid=121, n_modes=16):
    """Dimensionless blurred-frame moments ``(var, C(lags), E[m^4])`` without noise.

    `w` = W/tau, `d` = dt/tau, `lags` a 1-D integer array (>= 1)."""
    lam, xm = spectrum(beta, n_grid, n_modes)
    c0a = xm[0] ** 2
    z = lam * w
    var = jnp.sum(c0a * _s_blur(z))
    lags = jnp.asarray(lags)
    decay = jnp.exp(-lam[None, :] * (lags[:, None] * d - w))
    cov = jnp.sum(c0a[None, :] * _phi1(z)[None, :] ** 2 * decay, axis=1)
    odd = jnp.arange(1, n_modes, 2)
    even = jnp.arange(0, n_modes, 2)
    ia, ib, ic = (g.ravel() for g in jnp.meshgrid(odd, even, odd, indexing="ij"))
    weight = xm[0, ia] * xm[ia, ib] * xm[ib, ic] * xm[ic, 0]
    m4 = 24.0 * jnp.sum(weight * _simplex4(z[ia], z[ib], z[ic]))
    return var, cov, m4


def _simplex2(za, zb):
    """Integral over the unit 2-simplex of exp(-za s1 - zb s2) (s0, s1, s2 >= 0, sum 1)."""
    zero = jnp.zeros_like(za)
    diag = jnp.stack([zero, -za, -zb], axis=-1)
    a = jax.vmap(jnp.diag)(diag) + jnp.diag(jnp.ones(2), 1)[None]
    return jax.vmap(jsl.expm)(a)[:, 0, 2]


def square_covariance(beta, w, d, sq_lags, n_grid=121, n_modes=16):
    """Dimensionless ``E[m_0^2 m_l^2]`` of blurred frames at lags ``l >= 1`` (no noise).

    The two exposures are disjoint (``l d >= w``), so for ordered times the four-point function
    factorises: ``E[m_0^2 m_l^2] = 4 sum_b v_b^2 exp(-lam_b (l d - w))`` with
    ``v_b = sum_a X_0a X_ab A(z_a, z_b)`` and ``A`` the integral of
    ``exp(-z_a s1 - z_b s2)`` over the unit 2-simplex (``A(z, 0) = S(z)/2``: the ``b = 0``
    term is ``var^2``; for a Gaussian frame process it equals ``var^2 + 2 C(l)^2``)."""
    lam, xm = spectrum(beta, n_grid, n_modes)
    z = lam * w
    odd = jnp.arange(1, n_modes, 2)
    even = jnp.arange(0, n_modes, 2)
    ia, ib = (g.ravel() for g in jnp.meshgrid(odd, even, indexing="ij"))
    amat = _simplex2(z[ia], z[ib]).reshape(odd.size, even.size)
    v = jnp.sum(xm[0, odd][:, None] * xm[odd][:, even] * amat, axis=0)
    sq_lags = jnp.asarray(sq_lags)
    decay = jnp.exp(-lam[even][None, :] * (sq_lags[:, None] * d - w))
    return 4.0 * jnp.sum(v[None, :] ** 2 * decay, axis=1)
