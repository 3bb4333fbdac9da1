r"""Exact frames of the trap seen through a photodiode filter (``detector_filter``).

The Berg-Sorensen et al. (2003) photodiode responds with a fraction ``alpha`` instantly and
with the rest through a first-order low-pass of corner ``f_3dB``,
``H(f) = alpha + (1 - alpha) / (1 + i f/f_3dB)``, so
``|H|^2 = alpha^2 + (1 - alpha^2) / (1 + (f/f_3dB)^2)``. In the time domain the detector
signal is ``y = alpha x + (1 - alpha) z`` with ``dz/dt = lam (x - z)``, ``lam = 2 pi f_3dB``:
together with the trap's ``dx = -x dt/tau + sqrt(2 D) dB`` this is a linear Gaussian system
in ``s = (x, z)``. Adding the exposure integral ``J = int y dt`` as a third state, one
exposure is one exact Gaussian transition of ``(x, z, J)`` from ``(x0, z0, 0)`` (frame
``= J/W``), and the dead time ``dt - W`` is one exact transition of ``(x, z)``. The
transition matrices and noise covariances come from the matrix exponential (Van Loan 1978),
computed in float64 on the host, with step doubling so that no exponent exceeds 1; the
initial state is drawn from the exact stationary law (Lyapunov equation). The filter acts
before the exposure average and the sampling, as in a real detector; the result is exact at
any ``W <= dt`` and ``f_3dB`` (no substeps, O(1) per frame).

Everything runs in units of ``sigma = sqrt(kT/k)`` and ``tau = gamma/k``.
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np


def _expm(m: np.ndarray) -> np.ndarray:
    """Matrix exponential of a small float64 matrix: scaling and squaring of a Taylor
    series (norm scaled below 1/2; 20 terms reach machine precision)."""
    norm = float(np.max(np.sum(np.abs(m), axis=0)))
    s = max(0, int(math.ceil(math.log2(norm / 0.5)))) if norm > 0.5 else 0
    x = m / 2.0**s
    out = np.eye(m.shape[0])
    term = np.eye(m.shape[0])
    for j in range(1, 21):
        term = term @ x / j
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def discretize(a: np.ndarray, g: np.ndarray, h: float):
    """Exact discretisation of ``ds = a s dt + dW`` with ``E[dW dW^T] = g dt`` over ``h``:
    returns ``(phi, q)`` with ``s(h) = phi s(0) + N(0, q)``. Van Loan's block exponential on
    a step small enough that ``|a| h_j <= 1``, composed by doubling
    (``(phi, q) -> (phi^2, phi q phi^T + q)``), so growing exponentials never cancel."""
    n = a.shape[0]
    norm = float(np.max(np.sum(np.abs(a), axis=0))) * h
    d = max(0, int(math.ceil(math.log2(norm)))) if norm > 1.0 else 0
    hj = h / 2.0**d
    big = np.zeros((2 * n, 2 * n))
    big[:n, :n] = -a
    big[:n, n:] = g
    big[n:, n:] = a.T
    e = _expm(big * hj)
    phi = e[n:, n:].T
    q = phi @ e[:n, n:]
    for _ in range(d):
        q = phi @ q @ phi.T + q
        phi = phi @ phi
    q = 0.5 * (q + q.T)
    return phi, q


def _sqrt_psd(q: np.ndarray) -> np.ndarray:
    """A square root ``l`` with ``l l^T = q`` for a symmetric PSD matrix (eigen
    decomposition; tiny negative eigenvalues from rounding are clipped to 0)."""
    w, v = np.linalg.eigh(q)
    return v * np.sqrt(np.clip(w, 0.0, None))


def _lyapunov(a: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Stationary covariance ``p`` of ``ds = a s dt + dW``: ``a p + p a^T + g = 0``."""
    n = a.shape[0]
    eye = np.eye(n)
    m = np.kron(eye, a) + np.kron(a, eye)
    p = np.linalg.solve(m, -g.reshape(-1)).reshape(n, n)
    return 0.5 * (p + p.T)


def photodiode_coefficients(lam, alpha, a_exp, r_dead):
    """Per grid point (dimensionless ``lam = 2 pi f_3dB tau``, exposure ``a = W/tau``, dead
    time ``r = (dt - W)/tau``): the exact laws of one frame. Returns a dict of float64
    arrays: ``pe (G,3,2)``, ``le (G,3,3)`` (exposure transition of (x, z, J) and a noise
    square root), ``pd (G,2,2)``, ``ld (G,2,2)`` (dead time), ``l0 (G,2,2)`` (stationary
    square root), ``inv_a (G,)``. The (x, z) rows of ``pe`` and ``pd`` are the transitions
    minus the identity (the scan updates by increments)."""
    g_n = len(a_exp)
    out = {k: [] for k in ("pe", "le", "pd", "ld", "l0")}
    for i in range(g_n):
        la, al = float(lam[i]), float(alpha[i])
        a2 = np.array([[-1.0, 0.0], [la, -la]])
        g2 = np.diag([2.0, 0.0])
        a3 = np.zeros((3, 3))
        a3[:2, :2] = a2
        a3[2, :2] = [al, 1.0 - al]
        g3 = np.diag([2.0, 0.0, 0.0])
        phi_e, q_e = discretize(a3, g3, float(a_exp[i]))
        # transitions of (x, z) minus the identity: the scan updates by increments,
        # s' = s + (phi - 1) s + noise, which keeps float32 accurate for short steps
        pe = phi_e[:, :2].copy()
        pe[:2] -= np.eye(2)
        out["pe"].append(pe)
        out["le"].append(_sqrt_psd(q_e))
        if r_dead[i] > 0:
            phi_d, q_d = discretize(a2, g2, float(r_dead[i]))
        else:
            phi_d, q_d = np.eye(2), np.zeros((2, 2))
        out["pd"].append(phi_d - np.eye(2))
        out["ld"].append(_sqrt_psd(q_d))
        out["l0"].append(_sqrt_psd(_lyapunov(a2, g2)))
    res = {k: np.stack(v) for k, v in out.items()}
    res["inv_a"] = 1.0 / np.asarray(a_exp, dtype=np.float64)
    return res


_CHUNK_NORMALS = 1 << 22  # normals drawn per compiled chunk (memory bound)


@partial(jax.jit, static_argnums=(0, 1))
def _init(n_traces: int, dtype: str, c, key_init):
    def one(cg, k0):
        return jr.normal(k0, (n_traces, 2), jnp.dtype(dtype)) @ cg["l0"].T  # stationary (x, z)

    return jax.vmap(one)(c, key_init)


@partial(jax.jit, static_argnums=(0, 1))
def _chunk(n: int, dtype: str, c, s0, key_frames, index):
    """`n` frames from state `s0` (G, T, 2); normals from ``fold_in(key, index)``."""

    def one(cg, s, kf):
        z = jr.normal(jr.fold_in(kf, index), (n, 5, s.shape[0]), jnp.dtype(dtype))
        pe, le, pd, ld = cg["pe"], cg["le"], cg["pd"], cg["ld"]

        def step(carry, zi):
            x, y = carry  # trap position and filter state, (T,) each
            # explicit 2x2 / 3x3 products: elementwise over traces is faster than tiny dots
            # (the (x, z) rows of pe and pd are the transitions minus the identity)
            xw = x + (pe[0, 0] * x + pe[0, 1] * y
                      + le[0, 0] * zi[0] + le[0, 1] * zi[1] + le[0, 2] * zi[2])
            yw = y + (pe[1, 0] * x + pe[1, 1] * y
                      + le[1, 0] * zi[0] + le[1, 1] * zi[1] + le[1, 2] * zi[2])
            jw = pe[2, 0] * x + pe[2, 1] * y + le[2, 0] * zi[0] + le[2, 1] * zi[1] + le[2, 2] * zi[2]
            x = xw + (pd[0, 0] * xw + pd[0, 1] * yw + ld[0, 0] * zi[3] + ld[0, 1] * zi[4])
            y = yw + (pd[1, 0] * xw + pd[1, 1] * yw + ld[1, 0] * zi[3] + ld[1, 1] * zi[4])
            return (x, y), jw * cg["inv_a"]

        (x, y), frames = jax.lax.scan(step, (s[:, 0], s[:, 1]), z)
        return jnp.stack([x, y], axis=-1), frames.T

    return jax.vmap(one)(c, s0, key_frames)


def simulate_photodiode(lam, alpha, a_exp, r_dead, n_frames, n_traces, dtype, key_init,
                        key_frames):
    """Exact photodiode-filtered frames, shape ``(G, T, n)`` in units of sigma (see module
    docstring). `lam`, `alpha`, `a_exp`, `r_dead`: float64 arrays of shape (G,). Frames are
    produced in chunks of frames (normals of chunk ``c`` from ``fold_in(key, c)``)."""
    coef = photodiode_coefficients(lam, alpha, a_exp, r_dead)
    name = np.dtype(dtype).name
    c = {k: jnp.asarray(v, dtype=dtype) for k, v in coef.items()}
    s = _init(int(n_traces), name, c, key_init)
    # chunk length independent of the grid size, so a grid call equals the individual calls
    chunk = max(1, min(int(n_frames), _CHUNK_NORMALS // (5 * int(n_traces))))
    outs = []
    for i, start in enumerate(range(0, int(n_frames), chunk)):
        s, fr = _chunk(chunk, name, c, s, key_frames, jnp.int32(i))
        outs.append(fr[..., : min(chunk, int(n_frames) - start)])
    return outs[0] if len(outs) == 1 else jnp.concatenate(outs, axis=-1)
