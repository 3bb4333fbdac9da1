r"""Exact (O(N)) and Whittle log-likelihoods of a blurred, sampled, noisy trap recording.

**Exact likelihood.** Frames form a stationary Gaussian ARMA(1,1) process: ``C(0) = c0`` and
``C(n) = c1 rho^(n-1)`` for n >= 1 (DESIGN item 5). The unit-triangular transform
``W_1 = y_1``, ``W_t = y_t - rho y_(t-1)`` (Jacobian 1) makes the covariance *tridiagonal*:
``Var W_1 = c0``, ``Var W_t = d = c0 (1 + rho^2) - 2 rho c1`` (t >= 2) and
``Cov(W_t, W_(t+1)) = e = c1 - rho c0`` for all t, zero beyond. Its Cholesky/innovations
recursion ``v_t = d - e^2/v_(t-1)``, ``eps_t = W_t - (e/v_(t-1)) eps_(t-1)`` is solved as

- ``v_t`` in closed form (a Riccati recursion: ``v_t = p_t / p_(t-1)`` with ``p`` a two-term
  linear recurrence), no loop at all;
- ``eps_t`` as a first-order linear recurrence by a two-level chunked scan (O(N) work,
  O(sqrt N) sequential steps, each vectorised over sqrt(N) blocks).

The unknown trap centre is handled by REML: the GLS mean is profiled out and
``-1/2 log(1' Sigma^-1 1)`` added, which removes the O(1/N) downward bias of the variance.
Both are exactly invariant to a constant shift of the frames, so the frames are first centred
on their sample mean: otherwise the profiled quadratic form ``y'S^-1 y - (1'S^-1 y)^2 / 1'S^-1 1``
is the difference of two numbers of order ``N offset^2 / C(0)`` and loses ``log10(offset^2 /
C(0))`` digits (all of them for a 1 m offset on a 10 nm trace).

**Whittle likelihood.** ``-sum_j [log P_j + I_j / P_j]`` over Fourier frequencies in
(0, fs/2] with the exact discrete PSD; O(N log N), asymptotically equivalent.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

_LOG2PI = 1.8378770664093453


def _innovation_variances(c0, d, e, n):
    """v_1 = c0, v_t = d - e^2 / v_(t-1): closed form via p_t = d p_(t-1) - e^2 p_(t-2)."""
    return innovation_variances_at(c0, d, e, jnp.arange(1, n + 1, dtype=c0.dtype))


def innovation_variances_at(c0, d, e, t):
    """The innovation variances ``v_t`` of :func:`_innovation_variances` at the frame
    indices ``t`` (1-based, any array of them): the same closed form, so that a recursion run
    in chunks of frames gets the same numbers as the whole record."""
    disc = jnp.sqrt(jnp.maximum(d * d - 4.0 * e * e, 0.0))
    lam1 = 0.5 * (d + disc)  # steady-state innovation variance
    lam2 = e * e / lam1  # = 0.5 (d - disc), computed without cancellation
    r = lam2 / lam1  # in [0, 1)
    # p_0 = 1, p_1 = c0  ->  p_t = A lam1^t + B lam2^t with A + B = 1, A lam1 + B lam2 = c0
    # v_t = p_t/p_(t-1) = lam1 (1 + g r^t) / (1 + g r^(t-1)),  g = B/A = (lam1 - c0)/(c0 - lam2)
    g = (lam1 - c0) / (c0 - lam2)
    log_r = jnp.log(jnp.maximum(r, jnp.finfo(c0.dtype).tiny))
    rt = jnp.exp(t * log_r)
    rt1 = jnp.exp((t - 1.0) * log_r)
    return lam1 * (1.0 + g * rt) / (1.0 + g * rt1)


def _affine_scan(a, b):
    """x_t = a_t x_(t-1) + b_t with x_0 = 0 along the last axis, as a two-level chunked scan.

    The record is cut into ~sqrt(N) blocks; one ``lax.scan`` of ~sqrt(N) steps runs all
    blocks side by side (vectorised), a second short scan passes the carries between blocks.
    O(N) work, O(sqrt N) sequential steps, small compiled graph (also for gradients).
    """
    n = a.shape[-1]
    batch = a.shape[:-1]
    length = int(min(4096, max(16, 2 ** math.ceil(math.log2(math.sqrt(max(n, 1)))))))
    nblk = -(-n // length)
    pad = nblk * length - n
    if pad:
        a = jnp.concatenate([a, jnp.ones(batch + (pad,), a.dtype)], axis=-1)
        b = jnp.concatenate([b, jnp.zeros(batch + (pad,), b.dtype)], axis=-1)
    a = jnp.moveaxis(a.reshape(batch + (nblk, length)), -1, 0)
    b = jnp.moveaxis(b.reshape(batch + (nblk, length)), -1, 0)

    def inner(carry, ab):
        x, prod = carry
        at, bt = ab
        x = at * x + bt
        prod = at * prod
        return (x, prod), (x, prod)

    zeros = jnp.zeros(batch + (nblk,), b.dtype)
    _, (xloc, pcum) = jax.lax.scan(inner, (zeros, jnp.ones_like(zeros)), (a, b))

    def outer(c, pe):
        p_end, e_end = pe
        return p_end * c + e_end, c

    _, cin = jax.lax.scan(
        outer, jnp.zeros(batch, b.dtype), (jnp.moveaxis(pcum[-1], -1, 0), jnp.moveaxis(xloc[-1], -1, 0))
    )
    x = xloc + pcum * jnp.moveaxis(cin, 0, -1)[None]
    return jnp.moveaxis(x, 0, -1).reshape(batch + (nblk * length,))[..., :n]


def _whiten(y, c0, c1, rho):
    """Innovations eps_t and their variances v_t for the ARMA(1,1) frame covariance.

    ``y`` may have leading batch axes (all whitened with the same covariance).
    """
    n = y.shape[-1]
    d = c0 * (1.0 + rho * rho) - 2.0 * rho * c1
    e = c1 - rho * c0
    v = _innovation_variances(c0, d, e, n)
    w = jnp.concatenate([y[..., :1], y[..., 1:] - rho * y[..., :-1]], axis=-1)
    theta = jnp.concatenate([jnp.zeros((1,), v.dtype), e / v[:-1]])
    eps = _affine_scan(jnp.broadcast_to(-theta, w.shape), w)
    return eps, v


def arma_loglik(y, c0, c1, rho, *, mean: str = "reml", mask=None):
    """Exact Gaussian log-likelihood of frames ``y`` with autocovariance c0, c1 rho^(n-1).

    **Arguments:**

    - `y`: frames [m], shape (N,).
    - `c0`, `c1`, `rho`: C(0) [m^2], C(1) [m^2] and the lag ratio rho (0 <= rho < 1).
    - `mean`: ``"zero"`` (y is already centred on the known trap centre), ``"profile"``
      (GLS mean profiled out) or ``"reml"`` (restricted likelihood, the default).
    - `mask`: optional 0/1 array of shape (N,) that must be a prefix of ones: frames after the
      prefix are padding. The recursion is causal, so padding at the end does not change the
      innovations of the real frames; this lets recordings of different lengths share one
      compiled, vmapped likelihood.

    **Returns:** log-likelihood (scalar).
    """
    if mean not in ("zero", "profile", "reml"):
        raise ValueError(f"mean must be 'zero', 'profile' or 'reml'; got mean = {mean!r}")
    y = jnp.asarray(y)
    c0, c1, rho = (jnp.asarray(v, dtype=y.dtype) for v in (c0, c1, rho))
    if mask is None:
        mask = jnp.ones_like(y)
    n = jnp.sum(mask)
    if mean != "zero":
        # shift-invariant: centre first, so the profiled quadratic form does not cancel
        y = (y - jnp.sum(mask * y) / n) * mask
    if mean == "zero":
        eps, v = _whiten(y, c0, c1, rho)
        return gls_loglik(n, jnp.sum(mask * jnp.log(v)), jnp.sum(mask * eps * eps / v), 0.0,
                          1.0, mean)
    both = jnp.stack([y, mask])
    eps, v = _whiten(both, c0, c1, rho)
    ey, e1 = eps[0], eps[1]
    wv = mask / v
    return gls_loglik(n, jnp.sum(mask * jnp.log(v)), jnp.sum(ey * ey * wv),
                      jnp.sum(e1 * ey * wv), jnp.sum(e1 * e1 * wv), mean)


def gls_loglik(n, slogv, syy, s1y, s11, mean: str):
    """The Gaussian log-likelihood of ``n`` frames from the sums over their innovations
    ``e_t`` (variances ``v_t``) of the frames and ``f_t`` of a column of ones: ``sum log v``,
    ``y'S^-1 y = sum e^2/v``, ``1'S^-1 y = sum f e/v`` and ``1'S^-1 1 = sum f^2/v``. With
    ``mean="zero"`` only the first two are used; ``"profile"`` subtracts the GLS mean's part of
    the quadratic form; ``"reml"`` adds the restricted-likelihood correction. One home for
    every innovations likelihood (:func:`arma_loglik`, the frame chunks of
    :mod:`._exact_chunks`, the irregular-time filter of :mod:`._irregular`)."""
    if mean == "zero":
        return -0.5 * (n * _LOG2PI + slogv + syy)
    ll = -0.5 * (n * _LOG2PI + slogv + (syy - s1y * s1y / s11))
    if mean == "reml":
        ll = ll - 0.5 * jnp.log(s11) + 0.5 * _LOG2PI
    return ll


def periodogram(y, frame_interval):
    """Two-sided periodogram at the Fourier frequencies in (0, fs/2].

    ``I_j = dt/N |sum_t y_t e^(-2 pi i j t/N)|^2`` (mean removed), so that E[I_j] -> P_d(f_j).

    **Returns:** ``(f, I)`` with ``f_j = j/(N dt)``, j = 1 .. floor(N/2).
    """
    n = y.shape[-1]
    yc = y - jnp.mean(y, axis=-1, keepdims=True)
    spec = jnp.fft.rfft(yc, axis=-1)[..., 1:]
    power = (spec.real**2 + spec.imag**2) * frame_interval / n
    f = jnp.arange(1, n // 2 + 1, dtype=y.dtype) / (n * frame_interval)
    return f, power


def whittle_loglik(power, model_psd, *, nyquist_half: bool = True, n_blocks=1):
    """Whittle / Gamma log-likelihood of (block-averaged) periodogram ordinates.

    Each ordinate of an average of ``n_blocks`` independent periodograms is
    ``P_j Gamma(n_blocks, 1)/n_blocks`` (paper appendix C); the log-likelihood up to a
    constant is ``-n_blocks sum_j w_j [log P_j + I_j/P_j]``; the Nyquist ordinate (even N)
    is chi^2_1 and gets weight 1/2 when ``nyquist_half``.
    """
    w = jnp.ones_like(power)
    if nyquist_half:
        w = w.at[..., -1].set(0.5)
    return -n_blocks * jnp.sum(w * (jnp.log(model_psd) + power / model_psd), axis=-1)


def block_periodogram(y, frame_interval, n_blocks: int):
    """Average periodogram of ``n_blocks`` non-overlapping blocks (appendix C).

    Frames that do not fill the last block are *reported*, not silently dropped: the
    function returns how many were left over.

    **Returns:** ``(f, P_mean, n_used_frames)``.
    """
    n = y.shape[-1]
    m = n // n_blocks
    if m < 4:
        raise ValueError(
            f"n_blocks = {n_blocks} leaves {m} frames per block for a record of {n} frames; "
            "need at least 4 frames per block"
        )
    blocks = y[..., : m * n_blocks].reshape(*y.shape[:-1], n_blocks, m)
    f, p = periodogram(blocks, frame_interval)
    return f, jnp.mean(p, axis=-2), m * n_blocks
