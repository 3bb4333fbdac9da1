"""Allan variance: the overlapping estimator, its exact expectation and covariance, and a fit
of k, gamma and eps^2 by generalised least squares (``calibrate(..., method="allan")``).

The expectation is exact for blurred, aliased, noisy frames at any exposure W <= dt
(``blurtrap.physics._allan``), so no Lorentzian/blur approximation enters. The covariance of the
estimates at all cluster sizes is computed exactly for Gaussian frames (all pairs of second
differences, summed by lag), so the fit's errors need no rule-of-thumb error bars; it is
re-evaluated at the current estimate for three passes (iterated GLS).
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import optimistix as optx

from .._constants import BOLTZMANN
from ..physics import (
    allan_from_moments,
    allan_variance_model,
    frame_moments,
)
from ._fit import at_lower_bound
from ._problems import Layout, RecMeta


@dataclasses.dataclass(frozen=True)
class AllanVariance:
    """Overlapping Allan variance of one recording (SI): cluster sizes ``m`` (frames),
    averaging times ``tau = m dt`` [s], estimates ``avar`` [m^2] and ``n_terms`` (the number
    of overlapping second differences averaged at each m)."""

    m: np.ndarray
    tau: np.ndarray
    avar: np.ndarray
    n_terms: np.ndarray
    frame_interval: float
    n_frames: int

    def model(self, k, gamma, exposure, temperature=295.0, tracking_var=0.0) -> np.ndarray:
        """The exact expected Allan variance at this estimate's cluster sizes [m^2]."""
        sigma2 = BOLTZMANN * temperature / k
        return np.asarray(allan_variance_model(jnp.asarray(self.m, float), sigma2, gamma / k,
                                               exposure, self.frame_interval, tracking_var))

    def to_dict(self) -> dict:
        return {"m": self.m.tolist(), "tau_s": self.tau.tolist(), "avar_m2": self.avar.tolist(),
                "n_terms": self.n_terms.tolist(), "frame_interval_s": self.frame_interval,
                "n_frames": self.n_frames}


def octave_cluster_sizes(n_frames: int, min_clusters: int = 8) -> np.ndarray:
    """Octave-spaced cluster sizes 1, 2, 4, ... with at least `min_clusters` clusters."""
    if n_frames < 2 * min_clusters:
        raise ValueError(f"the Allan variance needs at least {2 * min_clusters} frames; got "
                         f"n_frames = {n_frames}")
    top = int(math.floor(math.log2(n_frames / min_clusters)))
    return 2 ** np.arange(top + 1)


def _positions(data, frame_interval):
    if hasattr(data, "positions"):
        return np.asarray(data.positions, dtype=float), float(data.frame_interval)
    y = np.asarray(data, dtype=float)
    if y.ndim != 1:
        raise ValueError(f"positions must be 1-D; got shape {y.shape}")
    if frame_interval is None or not (float(frame_interval) > 0):
        raise ValueError("frame_interval [s] > 0 is required with a plain array; got "
                         f"frame_interval = {frame_interval!r}")
    return y, float(frame_interval)


def allan_variance(data, frame_interval=None, *, m=None) -> AllanVariance:
    """Overlapping Allan variance of a recording (or a 1-D array with `frame_interval` [s]) at
    octave-spaced cluster sizes (or the integer cluster sizes `m`). Invariant to a constant
    offset (only differences of block sums enter). O(N) per cluster size."""
    y, dt = _positions(data, frame_interval)
    n = y.size
    m = octave_cluster_sizes(n) if m is None else np.asarray(m)
    if m.ndim != 1 or m.size == 0 or np.any(m < 1) or np.any(m != np.round(m)) \
            or np.any(2 * m >= n):
        raise ValueError(f"m must be whole numbers 1 <= m < n_frames/2 = {n / 2:g}; got m = {m}")
    m = m.astype(np.int64)
    cs = np.concatenate([[0.0], np.cumsum(y - y.mean())])
    avar, n_terms = [], []
    for mm in m:  # one vectorised pass per cluster size (a few dozen at most)
        d = cs[2 * mm:] - 2.0 * cs[mm:-mm] + cs[: -2 * mm]
        avar.append(float(np.mean(d * d)) / (2.0 * mm * mm))
        n_terms.append(d.size)
    return AllanVariance(m=m, tau=m * dt, avar=np.array(avar), n_terms=np.array(n_terms),
                         frame_interval=dt, n_frames=n)


def _block_sum_variance_np(n, c0, c1, r):
    """NumPy twin of ``physics._allan.block_sum_variance`` (tested against it): the covariance
    needs ~K^2/2 pairs of lag windows of varying length; as eager JAX calls (each new window
    length recompiles) one 14 x 14 matrix at 65 536 frames took 11.8 s against 1.8 s here,
    measured on the same (loaded) machine."""
    u = -np.expm1(-r)
    geo = (n * u + np.expm1(-r * n)) / u**2
    return np.where(n > 0, n * c0 + 2.0 * c1 * geo, 0.0)


_COEF = np.array([1.0, -2.0, 1.0])


def _pair_cov(mi, mj, ni, nj, c0, c1, r):
    """Cov(A(mi), A(mj)) of the overlapping estimator: 2 sum_L count(L) c(L)^2 /
    (4 mi^2 mj^2 ni nj), with c(L) = -1/2 sum_pq a_p b_q V(|L + t_q - s_p|) the covariance of
    second differences at lag L (``physics._allan`` docstring). Beyond the windows' overlap c(L) decays as
    rho^|gap|, so lags more than 20/r past it (relative weight < e^-40) are left out."""
    tail = int(min(ni + nj, math.ceil(20.0 / r) + 1))
    lags = np.arange(max(-ni + 1, -2 * mj - tail), min(nj, 2 * mi + tail), dtype=float)
    s = np.array([0.0, mi, 2.0 * mi])
    t = np.array([0.0, mj, 2.0 * mj])
    sep = np.abs(lags[:, None, None] + t[None, None, :] - s[None, :, None])
    c = -0.5 * np.einsum("p,q,lpq->l", _COEF, _COEF, _block_sum_variance_np(sep, c0, c1, r))
    count = np.clip(np.minimum(ni, nj - lags) - np.maximum(0.0, -lags), 0.0, None)
    return 2.0 * np.sum(count * c * c) / (4.0 * mi**2 * mj**2 * ni * nj)


def allan_covariance(m, n_terms, n_frames, c0, c1, r) -> np.ndarray:
    """Exact covariance matrix of overlapping Allan-variance estimates of Gaussian frames with
    moments ``(C(0), c_1, r)`` (``blurtrap.physics._allan.frame_moments``)."""
    m = np.asarray(m, float)
    nt = np.asarray(n_terms, float)
    c0, c1, r = float(c0), float(c1), float(r)
    k = m.size
    cov = np.zeros((k, k))
    for i in range(k):
        for j in range(i, k):
            cov[i, j] = cov[j, i] = _pair_cov(m[i], m[j], nt[i], nt[j], c0, c1, r)
    return cov


class AllanArgs(eqx.Module):
    layout: Layout
    meta: RecMeta
    m: jax.Array  # (R, K) cluster sizes (1 on padding)
    avar: jax.Array  # (R, K) estimates
    mask: jax.Array  # (R, K) 1 where an estimate exists
    chol: jax.Array  # (R, K, K) Cholesky factors of the estimates' covariance (this pass)
    blur: bool = eqx.field(static=True)


def _predicted(p, a: AllanArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    sigma2 = BOLTZMANN * a.meta.temp / k_rec
    w = a.meta.w if a.blur else jnp.zeros_like(a.meta.w)
    c0, c1, r = frame_moments(sigma2, gamma / k_rec, w, a.meta.dt, eps2)
    return allan_from_moments(a.m, c0[:, None], c1[:, None], r[:, None])


def _whitened(u, a_scale):
    a, scale = a_scale
    resid = (a.avar - _predicted(scale * u, a)) * a.mask
    z = jax.vmap(lambda ch, e: jsl.solve_triangular(ch, e, lower=True))(a.chol, resid)
    return z.ravel()


def _residuals(x, a_scale):
    return _whitened(jnp.exp(x), a_scale)


@eqx.filter_jit
def _gls(a: AllanArgs, scale, x0):
    sol = optx.least_squares(_residuals, optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10), x0,
                             args=(a, scale), max_steps=500, throw=False)
    u = jnp.exp(sol.value)
    jac = jax.jacfwd(_whitened)(u, (a, scale))
    fisher = jac.T @ jac
    evals = jnp.linalg.eigvalsh(fisher)
    pd = jnp.all(evals > 1e-12 * jnp.max(evals)) & jnp.all(jnp.isfinite(evals))
    cov = jnp.linalg.inv(fisher) * scale[:, None] * scale[None, :]
    chi2 = jnp.sum(_whitened(u, (a, scale)) ** 2)
    # a parameter the log-space fit drove to 0 (eps^2 ~ 1e-26 m^2): the rule of the other
    # fits on chi^2 / 2 (:func:`._fit.at_lower_bound`); its error is then NaN (_assemble),
    # the others' the unconstrained ones (the information in natural units is regular at 0)
    half = lambda x: 0.5 * jnp.sum(_residuals(x, (a, scale)) ** 2)
    bound = at_lower_bound(jax.grad(half)(sol.value), jax.hessian(half)(sol.value))
    return (scale * u, jnp.where(pd, cov, jnp.nan), chi2, sol.result == optx.RESULTS.successful,
            pd, bound)


def _covariances(recs, estimates, p, layout, blur, kmax):
    """Per recording: Cholesky factor of the estimates' covariance at parameters p, padded."""
    k_rec, gamma, eps2 = layout.unpack(jnp.asarray(p))
    chols = []
    for i, (r, est) in enumerate(zip(recs, estimates)):
        sigma2 = BOLTZMANN * float(r.temperature) / float(k_rec[i])
        w = float(r.exposure) if blur else 0.0
        c0, c1, rr = frame_moments(sigma2, float(gamma) / float(k_rec[i]), w,
                                   float(r.frame_interval), float(eps2))
        cov = allan_covariance(est.m, est.n_terms, est.n_frames, c0, c1, rr)
        full = np.eye(kmax)
        full[: cov.shape[0], : cov.shape[0]] = cov
        chols.append(np.linalg.cholesky(full))
    return jnp.asarray(np.stack(chols))


def fit_allan(recs, layout: Layout, meta: RecMeta, blur: bool, scale, n_iter: int = 3):
    """Iterated GLS fit of the Allan variances of `recs`. Returns ``(p, cov, chi2, dof, ok, pd,
    estimates, at_bound)``."""
    estimates = [allan_variance(r) for r in recs]
    kmax = max(e.m.size for e in estimates)
    pad = lambda v, fill: np.stack([np.pad(np.asarray(x, float), (0, kmax - len(x)),
                                           constant_values=fill) for x in v])
    args = AllanArgs(layout=layout, meta=meta, m=jnp.asarray(pad([e.m for e in estimates], 1.0)),
                     avar=jnp.asarray(pad([e.avar for e in estimates], 0.0)),
                     mask=jnp.asarray(pad([np.ones(e.m.size) for e in estimates], 0.0)),
                     chol=jnp.zeros((len(recs), kmax, kmax)), blur=blur)
    p = np.asarray(scale)
    x = jnp.zeros_like(scale)
    for _ in range(n_iter):
        args = eqx.tree_at(lambda a: a.chol, args,
                           _covariances(recs, estimates, p, layout, blur, kmax))
        p, cov, chi2, ok, pd, bound = _gls(args, scale, x)
        x = jnp.log(p / scale)
    dof = sum(e.m.size for e in estimates) - len(layout.names)
    return p, cov, chi2, dof, ok, pd, estimates, bound
