r"""Stationary Gaussian frames from their discrete power spectrum (``method="spectral"``).

Frequency-dependent friction (``hydrodynamics``: fluid inertia and the Basset force,
Berg-Sorensen & Flyvbjerg 2004) has no Markovian simulation in the position alone, but the
frames of a linear trap are a stationary Gaussian sequence fully described by their discrete
two-sided PSD ``P_d(f) = sum_n P(f + n fs) |H(f + n fs)|^2`` (continuous position PSD ``P``,
detection transfer ``|H|^2`` = exposure ``sinc^2(f W)`` times an optional photodiode filter).

**Sampler (circulant embedding).** With ``L = 2 N`` and ``f_j = j/(L dt)``, draw complex
normals ``w_j`` (independent real and imaginary parts N(0, 1)) and set
``y = FFT(sqrt(P_d(f_j) / (L dt)) w)``. ``Re y`` and ``Im y`` are two independent stationary
Gaussian sequences of length ``L`` whose autocovariance is the circulant
``c_L(n) = sum_m C(n + m L)`` of the exact frame autocovariance ``C`` (Dietrich & Newsam
1997); the first ``N`` values are returned. The embedding is always valid (``P_d > 0``).

**What it assumes.** (1) Wrap-around: for lags ``n < N`` the covariance differs from the exact
one by ``sum_{m != 0} C(n + m L)``, i.e. by about ``C(L - n) <= C(N)``: negligible when the
record is much longer than the correlation time (``C(N) ~ exp(-N dt/tau)`` for the
Lorentzian; the hydrodynamic long-time tail of a trapped bead decays as ``t^(-5/2)``, still
~1e-7 of C(0) after 100 tau). (2) Folding: ``|n| <= n_alias`` aliases are summed explicitly
and the rest by the Euler-Maclaurin integral ``(1/fs) int_{(n_alias + 1/2) fs}^inf``
(64-point Gauss-Legendre in ``u = a/s^2``), relative error < 1e-6 for the default
``n_alias = 128`` (checked against a 20 000-term sum in the tests). (3) Gaussianity and
linearity: the trap is harmonic (no ``force``), the detector linear.

Cost: one FFT of length ``2N`` per two traces and ``~(2 n_alias + 130) N`` spectrum
evaluations; memory O(N). Everything runs in units of ``sigma`` and ``tau``.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ..physics import hydro_lorentzian, photodiode_transfer

N_ALIAS = 128
_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def continuous_psd(f, p):
    """Continuous two-sided PSD of the detected position (units sigma^2 tau), times the
    detection transfer. `p`: dict of dimensionless scalars ``w`` (exposure / tau), and
    optionally ``f_nu``, ``f_m`` (hydrodynamics, times tau; ``x_wall`` = radius / distance
    to a surface, absent in bulk) and ``f3db``, ``alpha`` (photodiode, f3db times tau)."""
    if "f_nu" in p:
        # D = 1, fc = 1/(2 pi) in units of sigma and tau
        lor = hydro_lorentzian(f, 1.0, 1.0 / (2.0 * jnp.pi), p["f_nu"], p["f_m"],
                               p.get("x_wall", 0.0))
    else:
        lor = 2.0 / (1.0 + (2.0 * jnp.pi * f) ** 2)
    out = lor * jnp.sinc(f * p["w"]) ** 2
    if "f3db" in p:
        out = out * photodiode_transfer(f, p["f3db"], p["alpha"])
    return out


def folded_psd(f, p, dt, n_alias: int = N_ALIAS):
    """Discrete two-sided PSD of the frames at ``f`` (units sigma^2 tau, f in 1/tau):
    ``sum_n continuous_psd(f + n/dt)``, explicit for ``|n| <= n_alias`` (a ``fori_loop``,
    memory O(len(f))) plus the Euler-Maclaurin integral of the remaining tail."""
    fs = 1.0 / dt

    def body(n, acc):
        nn = n.astype(f.dtype)
        return acc + continuous_psd(f + nn * fs, p) + continuous_psd(f - nn * fs, p)

    acc = jax.lax.fori_loop(1, n_alias + 1, body, continuous_psd(f, p))
    # tail: sum_{n > N} g(n) ~ int_{N + 1/2}^inf g(t) dt; substitute t = a / s^2
    a = (n_alias + 0.5) * fs
    s = (jnp.asarray(_GL_X, f.dtype) + 1.0) / 2.0  # nodes on (0, 1)
    wq = jnp.asarray(_GL_W, f.dtype) / 2.0

    def node(i, acc_t):
        u = a / s[i] ** 2
        jac = 2.0 * a / s[i] ** 3
        g = continuous_psd(u + f, p) + continuous_psd(u - f, p)
        return acc_t + wq[i] * jac * g

    tail = jax.lax.fori_loop(0, s.shape[0], node, jnp.zeros_like(f)) / fs
    return acc + tail


@partial(jax.jit, static_argnums=(0, 1, 2, 3))
def _run(n_frames: int, n_traces: int, dtype: str, n_alias: int, p, dt, keys):
    dt_ = jnp.dtype(dtype)
    big = 2 * n_frames
    n_pairs = (n_traces + 1) // 2

    def one(pg, dtg, key):
        j = jnp.arange(big // 2 + 1, dtype=dt_)
        half = folded_psd(j / (big * dtg), pg, dtg, n_alias)
        lam = jnp.concatenate([half, half[1:-1][::-1]])  # P_d(f_j), j = 0..L-1
        scale = jnp.sqrt(lam / (big * dtg))
        kr, ki = jr.split(key)
        w = jax.lax.complex(jr.normal(kr, (n_pairs, big), dt_), jr.normal(ki, (n_pairs, big), dt_))
        y = jnp.fft.fft(scale * w, axis=-1)[:, :n_frames]
        return jnp.concatenate([y.real, y.imag], axis=0)[:n_traces]

    return jax.vmap(one)(p, dt, keys)


def simulate_spectral(p: dict, dt, n_frames, n_traces, dtype, keys, n_alias: int = N_ALIAS):
    """Frames ``(G, T, n)`` in units of sigma. `p`: dict of dimensionless float64 arrays of
    shape (G,) (see :func:`continuous_psd`); `dt`: frame interval / tau, shape (G,)."""
    pj = {k: jnp.asarray(v, dtype=dtype) for k, v in p.items()}
    return _run(int(n_frames), int(n_traces), np.dtype(dtype).name, int(n_alias), pj,
                jnp.asarray(dt, dtype=dtype), keys)
