r"""Expected Fisher information of one recording of blurred, sampled, noisy frames.

Parameters are ``theta = (log k, log gamma, log eps^2)`` (``log eps^2`` only with tracking
noise), so ``sqrt(inv(F))_ii`` is the relative standard error of each.

- ``whittle`` (long records): ``F = 1/2 sum_{j=1}^{N-1} g(f_j) g(f_j)^T`` with
  ``g = d log P_d / d theta`` at the Fourier frequencies; for a continuous N this is
  ``N/2 <g g^T>`` averaged over f uniform in (0, fs), computed by Gauss-Legendre quadrature on
  geometrically shrinking segments toward f = 0 (the integrand changes on the scale of the
  corner frequency, which may be << fs for a photodiode). The closed-form ``P_d`` is exact for
  any W <= dt (DESIGN section 2, item 5).
- ``exact`` (short records): ``F_ij = 1/2 tr(S^-1 dS_i S^-1 dS_j)`` for the N x N Toeplitz
  covariance S of the frames (the exact Gaussian information; O(N^3), N <= 4096).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..physics import BOLTZMANN, autocovariance_unchecked, discrete_psd_unchecked

# The unchecked forms: inside an optimiser's line search a trial point may be extreme, and a
# checked function would raise there instead of letting the search step back.

_N_SEG = 40  # geometric segments toward f = 0: the smallest is fs/2 * 2^-40
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)


def _nodes():
    """Quadrature nodes u in (0, 1) and weights for int_0^1 h(u) du, dense toward 0."""
    edges = np.concatenate([[0.0], 2.0 ** -np.arange(_N_SEG, -1, -1, dtype=float)])
    a, b = edges[:-1, None], edges[1:, None]
    u = (a + b) / 2 + (b - a) / 2 * _GL_X[None, :]
    w = (b - a) / 2 * _GL_W[None, :]
    return jnp.asarray(u.ravel()), jnp.asarray(w.ravel())


_U, _UW = _nodes()


def _has_noise(tracking_var) -> bool:
    """eps^2 is a parameter unless it is a concrete zero (then the model has no noise term)."""
    if isinstance(tracking_var, jax.core.Tracer):  # pyright: ignore[reportAttributeAccessIssue]
        return True
    return bool(np.any(np.asarray(tracking_var) > 0))


def _theta(k, gamma, eps2, noise):
    th = [jnp.log(k), jnp.log(gamma)]
    if noise:
        th.append(jnp.log(eps2))
    return jnp.stack(th)


def _unpack(th, noise):
    eps2 = jnp.exp(th[2]) if noise else 0.0
    return jnp.exp(th[0]), jnp.exp(th[1]), eps2


def whittle_information(k, gamma, exposure, frame_interval, n_frames, temperature=295.0,
                        tracking_var=0.0, noise: bool | None = None):
    """Whittle Fisher information (per ``theta``) of ``n_frames`` frames. Differentiable in
    every argument (so a design can be optimised by gradients). `noise` (static): whether
    log eps^2 is a parameter; default: unless `tracking_var` is a concrete zero."""
    noise = _has_noise(tracking_var) if noise is None else bool(noise)
    fs = 1.0 / frame_interval
    f = _U * fs / 2.0  # (0, fs/2): P_d is even, so <.> over (0, fs) equals that over (0, fs/2)

    def log_psd(th):
        kk, gg, e2 = _unpack(th, noise)
        return jnp.log(discrete_psd_unchecked(f, BOLTZMANN * temperature / kk, gg / kk, exposure,
                                              frame_interval, e2))

    th = _theta(k, gamma, tracking_var, noise)
    g = jax.jacfwd(log_psd)(th)  # (n_f, n_par)
    mean_ggt = jnp.einsum("f,fi,fj->ij", _UW, g, g)
    return 0.5 * (n_frames - 1.0) * mean_ggt


def exact_information(k, gamma, exposure, frame_interval, n_frames: int, temperature=295.0,
                      tracking_var=0.0, noise: bool | None = None):
    """Exact Gaussian Fisher information of ``n_frames`` (a Python int <= 4096) frames.
    `noise` (static): whether log eps^2 is a parameter; default: unless `tracking_var` is a
    concrete zero (pass it under jit)."""
    n = int(n_frames)
    if n > 4096:
        raise ValueError(f"exact information is O(N^3); use n_frames <= 4096 or the Whittle "
                         f"form; got n_frames = {n}")
    noise = _has_noise(tracking_var) if noise is None else bool(noise)
    lags = jnp.abs(jnp.arange(n)[:, None] - jnp.arange(n)[None, :])

    def cov(th):
        kk, gg, e2 = _unpack(th, noise)
        return autocovariance_unchecked(lags, BOLTZMANN * temperature / kk, gg / kk, exposure,
                                        frame_interval, e2)

    th = _theta(k, gamma, tracking_var, noise)
    s = cov(th)
    ds = jax.jacfwd(cov)(th)  # (n, n, n_par)
    a = jnp.linalg.solve(s, jnp.moveaxis(ds, -1, 0))  # S^-1 dS_i
    return 0.5 * jnp.einsum("iab,jba->ij", a, a)


def _informations(recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited, noise):
    """Whittle information (n_k, n_par, n_par) of the recordings ``recs`` ((dt, W, N) each;
    shared k, gamma, eps^2) per stiffness in ``ks``, in (log k, log gamma[, log eps^2]).
    A recording ``(dt, W, N, p)`` is at ``p`` times the laser power at which k is given:
    k_i = k p (k = c P), and log k_i = log c + log p, so the first row is that of log c."""
    dts, ws, ns = (jnp.stack([jnp.asarray(r[i], dtype=float) for r in recs]) for i in range(3))
    ps = jnp.stack([jnp.asarray(r[3] if len(r) > 3 else 1.0, dtype=float) for r in recs])
    return _informations_of(dts, ws, ns, ps, ks, gamma, temperature, eps_ref2, w_ref,
                            photon_limited, noise)


def _informations_of(dts, ws, ns, ps, ks, gamma, temperature, eps_ref2, w_ref,
                     photon_limited, noise):
    """:func:`_informations` of recordings given as arrays (frame intervals, exposures,
    frames, relative powers); ``photon_limited`` may be traced."""

    def info(k):
        def one(dt, w, n, p):
            e2 = eps_ref2 * jnp.where(photon_limited, w_ref / w, 1.0)
            return whittle_information(k * p, gamma, w, dt, n, temperature, e2, noise=noise)

        return jnp.sum(jax.vmap(one)(dts, ws, ns, ps), axis=0)

    return jax.vmap(info)(jnp.asarray(ks))


#: recordings of at most this many frames get the exact Gaussian information of their frames
#: in the candidates' predictions (the Whittle form, used by the optimiser, is within 1 % of it
#: at 512 frames and 0.4 % at 128: tests/design)
EXACT_MAX_FRAMES = 512

_exact_jit = jax.jit(exact_information, static_argnames=("n_frames", "noise"))
#: the candidates' Whittle information is compiled for recordings and stiffnesses padded to
#: these multiples (a padded recording has one frame: zero information; a padded stiffness
#: repeats the last, which leaves a worst case over them unchanged), so that every candidate
#: of a design call, and of the next call, runs the same program
REC_PAD = 4
K_PAD = 3
_informations_padded = jax.jit(_informations_of, static_argnums=(10,))


def padded(a, multiple, fill=None):
    """``a`` along its first axis, padded to a multiple of ``multiple`` rows with ``fill``
    (None: copies of the last row)."""
    a = np.asarray(a, dtype=float)
    extra = -(-max(len(a), 1) // multiple) * multiple - len(a)
    pad = np.repeat(a[-1:], extra, axis=0) if fill is None else np.full((extra,) + a.shape[1:],
                                                                         fill)
    return np.concatenate([a, pad])


def candidate_informations(recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited,
                           noise):
    """The information (n_k, n_par, n_par) of a candidate's recordings: Whittle for the long
    ones, the exact Gaussian information for recordings of <= EXACT_MAX_FRAMES frames."""
    short = [r for r in recs if int(round(r[2])) <= EXACT_MAX_FRAMES]
    long = tuple(r for r in recs if int(round(r[2])) > EXACT_MAX_FRAMES)
    n_par = 3 if noise else 2
    if long:
        dts, ws = (padded([r[i] for r in long], REC_PAD) for i in range(2))
        ns = padded([r[2] for r in long], REC_PAD, 1.0)
        ps = padded([r[3] if len(r) > 3 else 1.0 for r in long], REC_PAD, 1.0)
        infos = np.array(_informations_padded(dts, ws, ns, ps, padded(ks, K_PAD), gamma,
                                              temperature, eps_ref2, w_ref,
                                              bool(photon_limited), noise))[: len(ks)]
    else:
        infos = np.zeros((len(ks), n_par, n_par))
    for r in short:
        dt, w, p = r[0], r[1], (r[3] if len(r) > 3 else 1.0)
        e2 = eps_ref2 * (w_ref / w if photon_limited else 1.0)
        for i, k in enumerate(ks):
            infos[i] += np.asarray(_exact_jit(k * p, gamma, w, dt, int(round(r[2])),
                                              temperature, e2, noise=noise))
    return infos
