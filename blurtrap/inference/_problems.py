"""Parameter layouts and negative log-likelihoods for single recordings and joint fits.

Parameters are shared or per-recording according to a :class:`Layout`:

- ``k="shared"``: one stiffness for all recordings;
- ``k="per_recording"``: one stiffness per recording;
- ``k="per_power"``: one stiffness per distinct laser power;
- ``k="linear_power"``: ``k_i = c P_i`` (paper section 6.3), parameter ``c`` [N/m/W].

``gamma`` and ``tracking_var`` are shared (one bead, one detector). The negative
log-likelihoods are module-level pure functions so that jitted fits are compiled once per
data shape.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN
from ..physics import blur_factor_unchecked as _blur_factor
from ..physics import rho_b_unchecked as _rho_b
from ._likelihood import arma_loglik
from ._models import TrapModel
from ._newton import AbstractObjective

K_MODES = ("shared", "per_recording", "per_power", "linear_power")


class Layout(eqx.Module):
    k_index: jax.Array  # per recording: which k parameter (unused for linear_power)
    power: jax.Array  # per recording laser power [W] (linear_power only)
    n_k: int = eqx.field(static=True)
    linear_power: bool = eqx.field(static=True)
    noise: bool = eqx.field(static=True)
    names: tuple = eqx.field(static=True)
    k_labels: tuple = eqx.field(static=True)
    extra_names: tuple = eqx.field(static=True, default=())

    def unpack_extras(self, p) -> dict:
        """Effect parameters (after the core ones) by name."""
        n0 = len(self.names) - len(self.extra_names)
        return {name: p[n0 + i] for i, name in enumerate(self.extra_names)}

    def unpack(self, p):
        nk = 1 if self.linear_power else self.n_k
        if self.linear_power:
            k_rec = p[0] * self.power
        else:
            k_rec = p[:nk][self.k_index]
        gamma = p[nk]
        eps2 = p[nk + 1] if self.noise else jnp.zeros_like(gamma)
        return k_rec, gamma, eps2


def make_layout(recordings, k_mode: str, noise: bool, extra_names: tuple = ()) -> Layout:
    if k_mode not in K_MODES:
        raise ValueError(f"k must be one of {K_MODES}; got k = {k_mode!r}")
    n = len(recordings)
    powers = np.array(
        [np.nan if r.laser_power is None else float(r.laser_power) for r in recordings]
    )
    if k_mode in ("per_power", "linear_power") and np.any(np.isnan(powers)):
        missing = [i for i in range(n) if np.isnan(powers[i])]
        raise ValueError(
            f"k = {k_mode!r} needs laser_power on every recording; missing on recordings {missing}"
        )
    if k_mode == "shared":
        idx = np.zeros(n, dtype=np.int32)
        labels = ("k",)
    elif k_mode == "per_recording":
        idx = np.arange(n, dtype=np.int32)
        labels = tuple(f"k[{getattr(r, 'name', None) or i}]" for i, r in enumerate(recordings))
    elif k_mode == "per_power":
        uniq = np.unique(powers)
        idx = np.searchsorted(uniq, powers).astype(np.int32)
        labels = tuple(f"k[P={p * 1e3:g} mW]" for p in uniq)
    else:
        idx = np.zeros(n, dtype=np.int32)
        labels = ("c",)
    linear = k_mode == "linear_power"
    names = labels + ("gamma",) + (("tracking_var",) if noise else ()) + tuple(extra_names)
    return Layout(
        extra_names=tuple(extra_names),
        k_index=jnp.asarray(idx),
        power=jnp.asarray(np.nan_to_num(powers, nan=0.0)),
        n_k=len(labels),
        linear_power=linear,
        noise=noise,
        names=names,
        k_labels=labels,
    )


#: padded lengths are rounded up to 2^j times one of these (``bucket_length``), so that
#: recordings of nearby lengths share one compiled fit; ``None`` turns bucketing off. Plain
#: powers of two: a compilation (15-25 s on 2 cores) costs far more than fitting up to twice
#: the ordinates or frames (< 0.5 s at 2^16 frames); (1, 1.25, 1.5, 1.75) gave 2-3x more
#: compilations over one octave of lengths (benchmarks/bench_buckets.py)
BUCKET_STEPS: tuple | None = (1.0,)
#: lengths up to this are rounded up to a power of two (tiny arrays: padding is free)
_BUCKET_MIN = 64


def bucket_length(n: int) -> int:
    """The padded length for ``n`` real entries: the smallest ``2^j * s`` (``s`` in
    :data:`BUCKET_STEPS`, an integer) that is at least ``n``; ``n`` itself when bucketing is
    off. Every reduction over padded arrays gives the padding weight (or mask) 0."""
    n = int(n)
    if BUCKET_STEPS is None or n <= 1:
        return max(n, 1)
    if n <= _BUCKET_MIN:
        return 1 << (n - 1).bit_length()
    base = 1 << ((n - 1).bit_length() - 1)  # base < n <= 2 base
    return min(int(round(base * s)) for s in (*BUCKET_STEPS, 2.0) if base * s >= n)


class RecMeta(eqx.Module):
    dt: jax.Array
    w: jax.Array
    temp: jax.Array


def rec_meta(recordings) -> RecMeta:
    return RecMeta(
        dt=jnp.asarray([float(r.frame_interval) for r in recordings]),
        w=jnp.asarray([float(r.exposure) for r in recordings]),
        temp=jnp.asarray([float(r.temperature) for r in recordings]),
    )


class SpectralArgs(eqx.Module):
    """Periodogram ordinates of R recordings, padded to a common length M (weight 0 on
    padding), so that every evaluation is a broadcast over (R, M) with no gathers."""

    layout: Layout
    model: TrapModel
    meta: RecMeta
    f: jax.Array  # (R, M) [Hz]
    s2: jax.Array  # (R, M) sin^2(pi f dt)
    power: jax.Array  # (R, M) [m^2/Hz]
    weight: jax.Array  # (R, M): n_blocks (1/2 at Nyquist), 0 on padding
    log_ref: jax.Array
    block_len: jax.Array | None = None  # (R,) frames per block: exact expected periodogram
    n_ordinates: jax.Array | None = None  # (R,) real ordinates (the rest is bucket padding)


def spectral_model_psd(p, a: SpectralArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    extras = a.layout.unpack_extras(p)
    temp = a.meta.temp
    if a.model.extra:
        k_rec, gamma, temp = a.model.relations(k_rec, gamma, temp, a.layout.power, extras)
    return a.model.psd(a.f, k_rec, gamma, eps2, a.meta.dt, a.meta.w, temp, s2=a.s2,
                       extras=extras, block_len=a.block_len)


def _spectral_nll(p, a: SpectralArgs):
    """Whittle/Gamma negative log-likelihood of (blocked) periodogram ordinates of all
    recordings at once (one vectorised evaluation); :data:`spectral_nll` is its objective."""
    psd = spectral_model_psd(p, a)
    return jnp.sum(a.weight * (jnp.log(psd) - a.log_ref + a.power / psd))


# ------------------------------------------------------------------------------------------
# Fast second-order pass for the closed-form expected periodogram (the default fit)
# ------------------------------------------------------------------------------------------
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


def _whittle_sums(a_c, c_c, r, m, s, power, weight):
    """Per-recording sums for the value, gradient and Hessian of
    sum_j w_j [log P_j + I_j / P_j] with P_j = A + C T(r, s_j; M) in the variables (A, C, r)."""
    col = lambda z: z[..., None]  # noqa: E731
    t, tp, tq = _t_and_derivatives(s, col(r), col(m))
    p = col(a_c) + col(c_c) * t
    u = 1.0 / p
    q = power * u
    g = weight * (1.0 - q) * u  # d/dP of w (log P + I/P)
    z = weight * (2.0 * q - 1.0) * u * u  # d2/dP2
    return _sum_last((weight * (jnp.log(p) + q), g, g * t, g * tp, g * tq,
                      z, z * t, z * tp, z * t * t, z * t * tp, z * tp * tp))


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
    val, g0, g1, g2, g3, z0, z1, z2, z11, z12, z22 = _whittle_sums(
        a_c, c_c, r, a.block_len, a.s2, a.power, a.weight)
    g_phi = jnp.stack([g0, g1, c_c * g2])  # (3, R)
    h12 = c_c * z12 + g2  # includes d2P/dC dr = dT/dr
    h_phi = jnp.stack([jnp.stack([z0, z1, c_c * z2]),
                       jnp.stack([z1, z11, h12]),
                       jnp.stack([c_c * z2, h12, c_c * c_c * z22 + c_c * g3])])  # (3, 3, R)
    g_z = jnp.einsum("kir,kr->ir", jac, g_phi)
    h_z = (jnp.einsum("kir,klr,ljr->ijr", jac, h_phi, jac)
           + jnp.einsum("kr,kijr->ijr", g_phi, hess))
    value = jnp.sum(val) - a.log_ref * jnp.sum(a.weight)
    return (value, jnp.einsum("irn,ir->n", lin, g_z),
            jnp.einsum("irn,ijr,jrm->nm", lin, h_z, lin))


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
    """The closed-form expected periodogram with no effects (static fields only)."""
    return bool(a.block_len is not None and not a.model.extra and a.model.closed_form
                and a.model.alias)


def spectral_newton_plan(a: SpectralArgs):
    """``(pass_fn, coarse_args)`` of :class:`SpectralObjective` when the model is the
    closed-form expected periodogram with no effects, else ``None`` (generic autodiff).
    Decided from static fields and shapes only."""
    if not _fused_pass_applies(a):
        return None
    width = min(_COARSE_MAX_WIDTH, a.power.shape[-1] // _COARSE_GROUPS)
    return spectral_newton_pass, (_binned_args(a, width) if width >= 2 else None)


class SpectralObjective(AbstractObjective):
    """The Whittle/Gamma negative log-likelihood ``nll(p, a)`` of :class:`SpectralArgs` as a
    Newton objective: the fused one-pass value/gradient/Hessian
    (:func:`spectral_newton_pass`) and the binned coarse data for start values where
    :func:`spectral_newton_plan` allows them, autodiff otherwise."""

    def __call__(self, p, a: SpectralArgs):
        return _spectral_nll(p, a)

    def value_grad_hess(self, x, scale, a: SpectralArgs):
        if not _fused_pass_applies(a):
            return super().value_grad_hess(x, scale, a)
        return spectral_newton_pass(x, scale, a)  # looked up at call time (tests patch it)

    def coarse_args(self, a: SpectralArgs):
        plan = spectral_newton_plan(a)
        return None if plan is None else plan[1]


#: the Whittle/Gamma negative log-likelihood ``spectral_nll(p, a)`` (a callable objective)
spectral_nll = SpectralObjective()


class ExactArgs(eqx.Module):
    """Frames of R recordings zero-padded to a common length (``mask`` marks real frames)."""

    layout: Layout
    model: TrapModel
    meta: RecMeta
    ys: jax.Array  # (R, N_max)
    mask: jax.Array  # (R, N_max)
    mean: str = eqx.field(static=True, default="reml")


def make_exact_args(recordings, layout, model, mean="reml") -> ExactArgs:
    n_max = bucket_length(max(r.n_frames for r in recordings))  # masked beyond each record
    ys = np.zeros((len(recordings), n_max))
    mask = np.zeros((len(recordings), n_max))
    for i, r in enumerate(recordings):
        y = np.asarray(r.positions, dtype=float)
        # "reml" and "profile" are exactly invariant to a constant shift: centre on the host in
        # float64 (a large offset would otherwise cost digits in the profiled quadratic form)
        ys[i, : r.n_frames] = y if mean == "zero" else y - y.mean()
        mask[i, : r.n_frames] = 1.0
    return ExactArgs(layout=layout, model=model, meta=rec_meta(recordings),
                     ys=jnp.asarray(ys), mask=jnp.asarray(mask), mean=mean)


def exact_nll(p, a: ExactArgs):
    """Exact (REML) negative log-likelihood summed over recordings (one vmapped graph)."""
    k_rec, gamma, eps2 = a.layout.unpack(p)
    c0, c1, rho = a.model.moments(k_rec, gamma, eps2, a.meta.dt, a.meta.w, a.meta.temp)

    def one(y, m, c0_, c1_, rho_):
        return arma_loglik(y, c0_, c1_, rho_, mean=a.mean, mask=m)

    return -jnp.sum(jax.vmap(one)(a.ys, a.mask, c0, c1, rho))
