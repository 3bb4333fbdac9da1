"""Fast second-order pass for the closed-form expected periodogram (the default fit): value,
gradient and exact Hessian of the Whittle/Gamma negative log-likelihood of
:class:`~blurtrap.inference._problems.SpectralArgs` in one fused pass over the ordinates, and
the binned coarse objective for start values (used by
:class:`~blurtrap.inference._problems.SpectralObjective`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp

from .._constants import BOLTZMANN
from ..physics import blur_factor_unchecked as _blur_factor
from ..physics import rho_b_unchecked as _rho_b

if TYPE_CHECKING:
    from ._problems import SpectralArgs


# For the core closed-form model (no effects) every ordinate is
#     E[I_j] = A + C T(r, s_j; M),   A = dt C(0), C = 2 dt C(1), r = dt/tau, s_j = sin^2(pi f_j dt)
# (``_expected_block_periodogram``): linear in the per-recording scalars A and C, and
# nonlinear only through T(r, s; M) = [N_1 - N_2/(M D)]/D, a rational function of s whose
# coefficients depend on r alone. Value, gradient and exact Hessian of the Whittle sum then
# need, per ordinate, only T, dT/dr and d^2T/dr^2 (one division for 1/D, one for 1/P, one log)
# and 11 running sums, all in one fused pass (a variadic reduction). The chain rule from the
# log-parameters x to (A, C, r) involves per-recording scalars only.


def _t_coefficients(r, m):
    """Coefficients of T(r, s; M) = (b0 + b1 s)/D - (e0 + e1 s + e2 s^2)/D^2, D = a0 + a1 s
    (the same cancellation-free arrangement as ``_expected_block_periodogram``)."""
    rho = jnp.exp(-r)
    omr = -jnp.expm1(-r)
    rm1 = jnp.exp(-r * (m - 1.0))
    omrm1 = -jnp.expm1(-r * (m - 1.0))
    delta = omrm1 - (m - 1.0) * rm1 * omr
    return (omr * omr, 4.0 * rho, omr * omrm1, -2.0 * (1.0 + rm1 * rho),
            delta * (omr * omr) / m,
            -2.0 * (rm1 * omr * (1.0 + 3.0 * rho) + delta * (1.0 + rho * rho) / m),
            -8.0 * rm1 * rho * rho)


def _t_and_derivatives(s, r, m):
    """T and its first two r-derivatives at every ordinate (r, m: per-recording, shape
    broadcastable against s). The r-derivatives of the coefficients are per-recording
    scalars (nested jvp); per ordinate only rational arithmetic with one division."""

    def first(rr):
        return jax.jvp(lambda z: _t_coefficients(z, m), (rr,), (jnp.ones_like(rr),))

    (c, c1), (_, c2) = jax.jvp(first, (r,), (jnp.ones_like(r),))
    a0, a1, b0, b1, e0, e1, e2 = c
    a0p, a1p, b0p, b1p, e0p, e1p, e2p = c1
    a0q, a1q, b0q, b1q, e0q, e1q, e2q = c2
    d = a0 + a1 * s
    dp = a0p + a1p * s
    dq = a0q + a1q * s
    inv = 1.0 / d
    # U = N_1/D, W = N_2/(M D), V = W/D: differentiate U D = N_1 etc. (no further divisions)
    u = (b0 + b1 * s) * inv
    up = (b0p + b1p * s - u * dp) * inv
    uq = (b0q + b1q * s - 2.0 * up * dp - u * dq) * inv
    w = (e0 + s * (e1 + e2 * s)) * inv
    wp = (e0p + s * (e1p + e2p * s) - w * dp) * inv
    wq = (e0q + s * (e1q + e2q * s) - 2.0 * wp * dp - w * dq) * inv
    v = w * inv
    vp = (wp - v * dp) * inv
    vq = (wq - 2.0 * vp * dp - v * dq) * inv
    return u - v, up - vp, uq - vq


def _sum_last(terms):
    """Sums over the last axis of several arrays in ONE fused pass (a variadic reduce; a
    tuple of separate sums makes XLA materialise every intermediate array)."""
    zeros = tuple(jnp.zeros((), t.dtype) for t in terms)
    return jax.lax.reduce(tuple(terms), zeros,
                          lambda x, y: tuple(xi + yi for xi, yi in zip(x, y)),
                          (terms[0].ndim - 1,))


def _whittle_sums(a_c, c_c, r, m, s, power, weight, added=None):
    """Per-recording sums for the value, gradient and Hessian of
    sum_j w_j [log P_j + I_j / P_j] with P_j = A + C T(r, s_j; M) + E_j in the variables
    (A, C, r) and, with ``added = (E, dE, d2E)`` (additive effects: their spectrum E and its
    first and second derivatives in the effects' log-parameters, shapes (R, M), (n_e, R, M),
    (n_e, n_e, R, M)), in those too: the 11 core sums, then per effect parameter i
    sum g dE_i, sum z dE_i, sum z T dE_i, sum z T' dE_i, then for i <= j
    sum z dE_i dE_j + g d2E_ij."""
    col = lambda z: z[..., None]  # noqa: E731
    t, tp, tq = _t_and_derivatives(s, col(r), col(m))
    p = col(a_c) + col(c_c) * t
    if added is not None:
        p = p + added[0]
    u = 1.0 / p
    q = power * u
    g = weight * (1.0 - q) * u  # d/dP of w (log P + I/P)
    z = weight * (2.0 * q - 1.0) * u * u  # d2/dP2
    terms = [weight * (jnp.log(p) + q), g, g * t, g * tp, g * tq,
             z, z * t, z * tp, z * t * t, z * t * tp, z * tp * tp]
    if added is not None:
        _, de, d2e = added
        n_e = de.shape[0]
        for i in range(n_e):
            terms += [g * de[i], z * de[i], z * t * de[i], z * tp * de[i]]
        for i in range(n_e):
            for j in range(i, n_e):
                terms.append(z * de[i] * de[j] + g * d2e[i, j])
    return _sum_last(tuple(terms))


def _additive_spectrum(x, scale, a: SpectralArgs):
    """The additive effects' spectrum E (R, M) and its first and second derivatives in their
    log-parameters ``x[n0:]`` (forward mode, one evaluation per direction): ``(E, dE, d2E)``
    with shapes (R, M), (n_e, R, M), (n_e, n_e, R, M); ``n0`` the number of core parameters."""
    n0 = len(a.layout.names) - len(a.layout.extra_names)
    dt = (a.meta.dt * jnp.ones(a.f.shape[:-1], a.f.dtype))[:, None]

    def spectrum(xe):
        extras = a.layout.unpack_extras(scale * jnp.exp(x.at[n0:].set(xe)))
        return a.model.additive_psd(a.f, dt, extras)

    xe = x[n0:]
    d1 = jax.jacfwd(spectrum)
    e_val = spectrum(xe)
    de = jnp.moveaxis(d1(xe), -1, 0)
    d2e = jnp.moveaxis(jnp.moveaxis(jax.jacfwd(d1)(xe), -1, 0), -1, 0)
    return e_val, de, d2e


def _log_variables(p, a: SpectralArgs):
    """Per recording (log sigma^2, log r, log eps^2), shape (3, R), with sigma^2 = kT/k and
    r = dt/tau = dt k/gamma: affine in the log-parameters for every layout (log k of a
    recording is log of one parameter, or of c plus log P for ``linear_power``)."""
    k_rec, gamma, eps2 = a.layout.unpack(p)
    ones = jnp.ones_like(k_rec)
    lk = jnp.log(k_rec)
    le = jnp.log(eps2) * ones if a.model.noise else jnp.zeros_like(lk)
    return jnp.stack([jnp.log(BOLTZMANN * a.meta.temp) - lk,
                      jnp.log(a.meta.dt) + lk - jnp.log(gamma), le])


def _coefficients_in_log_variables(z, a: SpectralArgs):
    """(A, C, r) = (dt C(0), 2 dt C(1), dt/tau) per recording from z = (log sigma^2, log r,
    log eps^2), with their first and second z-derivatives: the blur factors S and rho B
    depend on log r alone (alpha = (W/dt) r), so only univariate derivatives are needed.

    Returns ``phi`` (3, R), ``jac`` (3, 3, R) and ``hess`` (3, 3, 3, R) (indices: output,
    z, z)."""
    sig2, r = jnp.exp(z[0]), jnp.exp(z[1])
    e2 = jnp.exp(z[2]) if a.model.noise else jnp.zeros_like(sig2)
    dt = a.meta.dt * jnp.ones_like(sig2)
    kappa = (a.meta.w if a.model.blur else 0.0) / a.meta.dt * jnp.ones_like(sig2)

    def blur(u):
        rr = jnp.exp(u)
        return jnp.stack([_blur_factor(kappa * rr), _rho_b(kappa * rr, rr)])

    def blur1(u):
        return jax.jvp(blur, (u,), (jnp.ones_like(u),))

    (bf, bf_u), (_, bf_uu) = jax.jvp(blur1, (z[1],), (jnp.ones_like(z[1]),))
    sa, sb = dt * sig2, 2.0 * dt * sig2
    zero = jnp.zeros_like(sig2)
    a_c = sa * bf[0] + dt * e2
    c_c = sb * bf[1]
    phi = jnp.stack([a_c, c_c, r])
    jac = jnp.stack([jnp.stack([sa * bf[0], sa * bf_u[0], dt * e2]),
                     jnp.stack([c_c, sb * bf_u[1], zero]),
                     jnp.stack([zero, r, zero])])
    hess = jnp.stack([
        jnp.stack([jnp.stack([sa * bf[0], sa * bf_u[0], zero]),
                   jnp.stack([sa * bf_u[0], sa * bf_uu[0], zero]),
                   jnp.stack([zero, zero, dt * e2])]),
        jnp.stack([jnp.stack([c_c, sb * bf_u[1], zero]),
                   jnp.stack([sb * bf_u[1], sb * bf_uu[1], zero]),
                   jnp.stack([zero, zero, zero])]),
        jnp.stack([jnp.stack([zero, zero, zero]),
                   jnp.stack([zero, r, zero]),
                   jnp.stack([zero, zero, zero])]),
    ])
    return phi, jac, hess


def spectral_newton_pass(x, scale, a: SpectralArgs):
    """Value, gradient and exact Hessian of ``spectral_nll(scale * exp(x), a)`` with respect
    to ``x`` in one pass over the ordinates (closed-form expected periodogram only).

    Chain rule: ordinates -> (A, C, r) per recording (the per-ordinate sums) -> z = (log
    sigma^2, log r, log eps^2) (univariate derivatives of the blur factors) -> x (z is affine
    in x, so its Jacobian ``L`` is all that is needed)."""
    z_of_x = lambda xx: _log_variables(scale * jnp.exp(xx), a)  # noqa: E731
    z = z_of_x(x)
    lin = jax.jacfwd(z_of_x)(x)  # (3, R, n), constant in x
    phi, jac, hess = _coefficients_in_log_variables(z, a)
    a_c, c_c, r = phi
    added = _additive_spectrum(x, scale, a) if a.model.extra else None
    sums = _whittle_sums(a_c, c_c, r, a.block_len, a.s2, a.power, a.weight, added)
    val, g0, g1, g2, g3, z0, z1, z2, z11, z12, z22 = sums[:11]
    g_phi = jnp.stack([g0, g1, c_c * g2])  # (3, R)
    h12 = c_c * z12 + g2  # includes d2P/dC dr = dT/dr
    h_phi = jnp.stack([jnp.stack([z0, z1, c_c * z2]),
                       jnp.stack([z1, z11, h12]),
                       jnp.stack([c_c * z2, h12, c_c * c_c * z22 + c_c * g3])])  # (3, 3, R)
    g_z = jnp.einsum("kir,kr->ir", jac, g_phi)
    h_z = (jnp.einsum("kir,klr,ljr->ijr", jac, h_phi, jac)
           + jnp.einsum("kr,kijr->ijr", g_phi, hess))
    value = jnp.sum(val) - a.log_ref * jnp.sum(a.weight)
    grad = jnp.einsum("irn,ir->n", lin, g_z)
    hessian = jnp.einsum("irn,ijr,jrm->nm", lin, h_z, lin)
    if added is None:
        return value, grad, hessian
    # additive effects: P = A + C T + E(x_e), E independent of the core parameters, whose
    # log-variables z do not depend on x_e (``lin`` is 0 in those columns)
    n_e = added[1].shape[0]
    n0 = x.shape[0] - n_e
    per = sums[11:11 + 4 * n_e]
    g_e = jnp.stack([jnp.sum(per[4 * i]) for i in range(n_e)])
    h_phi_e = jnp.stack([jnp.stack([per[4 * i + 1], per[4 * i + 2], c_c * per[4 * i + 3]])
                         for i in range(n_e)], axis=1)  # (3, n_e, R): d2/dphi dx_e
    h_z_e = jnp.einsum("kar,kir->air", jac, h_phi_e)
    h_ce = jnp.einsum("arn,air->ni", lin, h_z_e)  # (n, n_e)
    pair = iter(sums[11 + 4 * n_e:])
    h_ee = jnp.zeros((n_e, n_e), x.dtype)
    for i in range(n_e):
        for j in range(i, n_e):
            v = jnp.sum(next(pair))
            h_ee = h_ee.at[i, j].set(v).at[j, i].set(v)
    grad = grad.at[n0:].add(g_e)
    hessian = (hessian.at[:, n0:].add(h_ce).at[n0:, :].add(h_ce.T)
               .at[n0:, n0:].add(h_ee))
    return value, grad, hessian


def _binned_args(a: SpectralArgs, width: int) -> SpectralArgs:
    """Ordinates averaged in groups of ``width`` (weighted; the tail that does not fill a
    group is dropped): a cheap, nearly equivalent objective for start values."""
    n = (a.power.shape[-1] // width) * width

    def grp(z):
        return z[..., :n].reshape(z.shape[:-1] + (n // width, width))

    wt = grp(a.weight)
    wsum = jnp.sum(wt, axis=-1)
    safe = jnp.where(wsum > 0, wsum, 1.0)
    mean = lambda z: jnp.where(wsum > 0, jnp.sum(wt * grp(z), axis=-1) / safe,  # noqa: E731
                               jnp.mean(grp(z), axis=-1))
    return eqx.tree_at(lambda z: (z.f, z.s2, z.power, z.weight), a,
                       (mean(a.f), mean(a.s2), mean(a.power), wsum))


#: the coarse start-value objective has at least this many groups of at most
#: ``_COARSE_MAX_WIDTH`` ordinates: its optimum is then within ~1e-4 (log units) of the full
#: one (measured: 0.5-1e-4 with 2048 groups of 16 at 65 536 frames, 2e-6 with groups of 32 at
#: 2^20 frames), close enough for the full fit to finish in one Newton step and one check
_COARSE_GROUPS = 2048
_COARSE_MAX_WIDTH = 32


def _fused_pass_applies(a: SpectralArgs) -> bool:
    """The closed-form expected periodogram, with no effects or additive ones only (drift,
    line noise: their spectrum is added, :func:`_additive_spectrum`); static fields only."""
    return bool(a.block_len is not None and a.model.closed_form and a.model.alias
                and all(e.kind == "additive" for e in a.model.extra))


def coarse_start_applies(a: SpectralArgs) -> bool:
    """The binned coarse objective gives start values: the fused pass with no effects (a
    narrow line or a 1/f^2 excess is not kept by averaging ordinates in groups)."""
    return _fused_pass_applies(a) and not a.model.extra


def spectral_newton_plan(a: SpectralArgs):
    """``(pass_fn, coarse_args)`` of :class:`SpectralObjective` when the model is the
    closed-form expected periodogram with no effects or additive ones only (``coarse_args``
    None with effects), else ``None`` (generic autodiff). Decided from static fields and
    shapes only."""
    if not _fused_pass_applies(a):
        return None
    width = min(_COARSE_MAX_WIDTH, a.power.shape[-1] // _COARSE_GROUPS)
    coarse = coarse_start_applies(a) and width >= 2
    return spectral_newton_pass, (_binned_args(a, width) if coarse else None)
