"""Variance-based estimators (paper sections 6.1-6.3, appendix B).

- sample variance with the correlated-sample standard error (DESIGN item 10);
- naive and blur-corrected equipartition;
- variance vs exposure / variance vs power: weighted least squares (Levenberg-Marquardt in
  log k/c and log gamma, eps^2 >= 0 projected out in closed form) from a global Pade-grid
  start, weights from the model's own correlated-sample standard errors, iterated to the
  fixed point (their 95 % profile-likelihood intervals are in ``_variance_profile``).

Drift (progressive ideal high-pass and extrapolation to 0 Hz, appendix B) is in ``_drift``.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN
from ..physics import sample_variance_var_unchecked as _sample_variance_var
from ._models import TrapModel
from ._problems import Layout, RecMeta


def empirical_variance_se(y, max_lag: int | None = None) -> tuple[float, float]:
    """Sample variance and a model-free standard error from the empirical autocovariance
    (``var(s^2) ~ (2/N) sum_n C(n)^2`` summed until C(n) first drops below zero)."""
    y = np.asarray(y, dtype=float)
    n = y.size
    yc = y - y.mean()
    v = float(np.mean(yc * yc))
    spec = np.fft.rfft(yc, 2 * n)
    acov = np.fft.irfft(np.abs(spec) ** 2)[:n] / n
    m = max_lag or min(n - 1, 10_000)
    c = acov[: m + 1]
    stop = np.argmax(c <= 0) if np.any(c <= 0) else len(c)
    c = c[: max(stop, 1)]
    var_s2 = 2.0 / n * (c[0] ** 2 + 2.0 * np.sum(c[1:] ** 2))
    return v, float(np.sqrt(var_s2))


def _expected_sample_variance(n, c0, c1, rho):
    """E[(1/N) sum (y - ybar)^2] = C0 - Var(ybar), Var(ybar) in closed form."""
    r = -jnp.log(rho)
    one_m = -jnp.expm1(-r)
    one_m_n = -jnp.expm1(-r * n)
    geo = (n * one_m - one_m_n) / one_m**2  # sum_{m=1}^{N-1} (N-m) rho^(m-1)
    geo = jnp.where(r * n < 1e-8, n * (n - 1.0) / 2.0, geo)
    var_mean = (n * c0 + 2.0 * c1 * geo) / n**2
    return c0 - var_mean


class VarianceArgs(eqx.Module):
    layout: Layout
    model: TrapModel
    meta: RecMeta
    v: jax.Array  # sample variances (ddof 0)
    n: jax.Array  # frames per recording
    se: jax.Array  # weights (standard errors) for this pass


def _predicted(p, a: VarianceArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    c0, c1, rho = a.model.moments(k_rec, gamma, eps2, a.meta.dt, a.meta.w, a.meta.temp)
    return _expected_sample_variance(a.n, c0, c1, rho)


def _predicted_se(p, a: VarianceArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    sigma2 = BOLTZMANN * a.meta.temp / k_rec
    tau = gamma / k_rec
    w = a.meta.w if a.model.blur else jnp.zeros_like(a.meta.w)
    return jnp.sqrt(_sample_variance_var(a.n, sigma2, tau, w, a.meta.dt, eps2))


def _eps_slope(a: VarianceArgs):
    """d E[s^2] / d eps^2 per recording (the model is linear in eps^2): 1 - 1/N."""
    return 1.0 - 1.0 / a.n


def _to_params(x, scale, a: VarianceArgs, profile_eps: bool):
    """Internal coordinates -> SI parameters.

    ``x[:nk+1]`` are log(k/scale) (or log(c/scale)) and log(gamma/scale). With noise,
    ``x[-1]`` is eps^2/scale unless ``profile_eps``: then eps^2 is projected out in closed
    form (variable projection: the weighted least-squares eps^2 given k and gamma, clipped
    at its bound 0), which removes the curved k-eps^2 valley that Levenberg-Marquardt
    crawls along when the exposures hardly separate sigma^2 from eps^2."""
    nk1 = x.shape[0] - int(a.layout.noise)
    q = scale[:nk1] * jnp.exp(x[:nk1])
    if not a.layout.noise:
        return q
    if not profile_eps:
        return jnp.concatenate([q, scale[nk1:] * x[nk1:]])
    f0 = _predicted(jnp.concatenate([q, jnp.zeros(1)]), a)
    c = _eps_slope(a)
    wt = 1.0 / a.se**2
    e = jnp.sum(wt * c * (a.v - f0)) / jnp.sum(wt * c * c)
    return jnp.concatenate([q, jnp.maximum(e, 0.0)[None]])


#: the small jitted pieces the host loops below call thousands of times per fit (a
#: Levenberg-Marquardt step, a profile point): jax.jit's dispatch is ~30 us against ~190 us
#: for eqx.filter_jit with these arguments (VarianceArgs' static parts are static fields),
#: and it takes numpy arguments without a jnp.asarray copy (variance_vs_exposure with its
#: profile intervals on 4 recordings, warm: 3.9-4.4 s -> 2.7-3.0 s; benchmarks/RESULTS.md)
_host_jit = functools.partial(jax.jit, static_argnames=("profile_eps",))


@_host_jit
def _resid_jac(x, scale, a: VarianceArgs, profile_eps: bool = True):
    def res(xx):
        return (a.v - _predicted(_to_params(xx, scale, a, profile_eps), a)) / a.se

    return res(x), jax.jacfwd(res)(x)


@_host_jit
def _params(x, scale, a: VarianceArgs, profile_eps: bool = True):
    return _to_params(x, scale, a, profile_eps)


@jax.jit
def _fisher_p(p, a: VarianceArgs):
    """J^T J of the weighted residuals in SI parameters (eps^2 free)."""
    jac = jax.jacfwd(lambda q: (a.v - _predicted(q, a)) / a.se)(p)
    return jac.T @ jac


@jax.jit
def _chi2_many(ps, a: VarianceArgs):
    """chi^2 at each row of ``ps`` (SI parameters) with this pass's (fixed) weights."""
    return jax.vmap(lambda p: jnp.sum(((a.v - _predicted(p, a)) / a.se) ** 2))(ps)


@jax.jit
def _model_se(p, a: VarianceArgs):
    return _predicted_se(p, a)


#: Convergence: the Gauss-Newton decrement (the chi^2 reduction a full Newton step would
#: still bring, i.e. the squared distance to the optimum in standard errors) below this
#: fraction of chi^2 + dof. Scale-free, and far above rounding (so it does not depend on
#: the CPU's last bits: rounding moves the decrement by ~1e-28 relative); 1e-10 of
#: chi^2 + dof is ~1e-5 sqrt(chi^2 + dof) standard errors from the optimum.
_DECREMENT_RTOL = 1e-10
#: ... and where no step lowers chi^2 any more (rounding), still accepted below this
#: (~1e-3 SE): a statistically irrelevant distance, never a failure.
_STALL_RTOL = 1e-6


def _solve_lsq(a: VarianceArgs, scale, x0, free, profile_eps=True, max_iter=300, atol=0.0):
    """Levenberg-Marquardt on the weighted residuals over the coordinates ``free`` (the
    others held at ``x0``), host loop (problems have a handful of parameters).
    ``atol``: also accept a decrement below this (chi^2 units; profiles need ~1e-3).
    Returns ``(x, chi2, converged)``."""
    x = np.asarray(x0, dtype=float).copy()
    free = np.asarray(free, dtype=bool)
    r, jac = jax.device_get(_resid_jac(x, scale, a, profile_eps))
    chi2 = float(r @ r)
    dof = max(r.size - int(free.sum()), 0)
    lam = 1e-3
    for _ in range(max_iter):
        jf = jac[:, free]
        gf = jf.T @ r  # half the gradient of chi^2
        hf = jf.T @ jf
        d_gn = _safe_solve(hf, -gf)
        if d_gn is None:
            return x, chi2, False
        decrement = float(-gf @ d_gn)  # chi^2 drop of the Gauss-Newton step (quadratic model)
        if decrement <= max(_DECREMENT_RTOL * (chi2 + dof), atol):
            return x, chi2, True
        improved = False
        while lam < 1e12:
            d = _safe_solve(hf + lam * np.diag(np.diag(hf)), -gf)
            if d is not None:
                xn = x.copy()
                xn[free] += np.clip(d, -3.0, 3.0)  # at most a factor e^3 per step in a log scale
                rn, jn = jax.device_get(_resid_jac(xn, scale, a, profile_eps))
                cn = float(rn @ rn)
                if np.isfinite(cn) and cn <= chi2:
                    x, r, jac, chi2, improved = xn, rn, jn, cn, True
                    lam = max(lam / 5.0, 1e-9)
                    break
            lam *= 4.0
        if not improved:
            # no step lowers chi^2 (rounding level): accept if the decrement is small anyway
            return x, chi2, decrement <= max(_STALL_RTOL * (chi2 + dof), atol)
    return x, chi2, False


def _safe_solve(h, b):
    if h.size == 0:
        return np.zeros(0)
    d = np.sqrt(np.clip(np.diag(h), 1e-300, None))
    hs = h / d[:, None] / d[None, :]
    try:
        sol = np.linalg.solve(hs, b / d) / d
    except np.linalg.LinAlgError:
        return None
    return sol if np.all(np.isfinite(sol)) else None


def _layout_kinds(layout):
    nk = 1 if layout.linear_power else layout.n_k
    return nk, np.array([True] * (nk + 1) + [False] * int(layout.noise))


def _pade_stiffness(v, diffusion, w, kt):
    """Closed-form k given var(X_m) - eps^2 = v, D and W (DESIGN item 3, appendix D)."""
    dw = diffusion * w
    root = np.sqrt(np.clip(225.0 * v**2 + 240.0 * dw * v - 11.0 * dw**2, 0.0, None))
    return 30.0 * kt / (2.0 * dw + 15.0 * v + root)


def _grid_starts(a: VarianceArgs, scale):
    """Global starts: over a log grid of D (and of eps^2 when fitted), the closed-form Pade
    stiffness of every recording, pooled per k parameter, scored by chi^2 with fixed weights
    (the model SE at the moment start; a candidate's own weights would favour candidates
    that inflate their SEs). Returns candidate parameter vectors, best first."""
    layout = a.layout
    nk, _ = _layout_kinds(layout)
    v = np.asarray(a.v, dtype=float)
    n = np.asarray(a.n, dtype=float)
    w = np.asarray(a.meta.w, dtype=float) if a.model.blur else np.zeros_like(v)
    kt = BOLTZMANN * np.asarray(a.meta.temp, dtype=float)
    d0 = float(np.median(kt)) / float(scale[nk])
    d_grid = d0 * np.geomspace(1e-2, 1e2, 81)
    e_grid = [0.0]
    if layout.noise:
        e_grid += list(float(np.min(v)) * np.geomspace(1e-4, 0.7, 15))
    idx = np.asarray(layout.k_index)
    power = np.asarray(layout.power, dtype=float)
    e_arr = np.asarray(e_grid)[:, None, None]
    vv = np.maximum(v - e_arr * (1.0 - 1.0 / n), 1e-3 * v)  # (E, 1, R)
    log_k = np.log(_pade_stiffness(vv, d_grid[None, :, None], w, kt))  # (E, D, R)
    if layout.linear_power:
        kvec = np.exp(np.mean(log_k - np.log(power), axis=-1))[..., None]
    else:
        groups = (idx[None, :] == np.arange(nk)[:, None]).astype(float)  # (nk, R)
        cnt = groups.sum(axis=1)
        kvec = np.exp(log_k @ groups.T / np.maximum(cnt, 1.0))
        kvec = np.where(cnt > 0, kvec, scale[:nk])
    shape = kvec.shape[:2]
    gam = np.broadcast_to((float(np.median(kt)) / d_grid)[None, :, None], shape + (1,))
    parts = [kvec, gam]
    if layout.noise:
        parts.append(np.broadcast_to(e_arr[:, :, :1], shape + (1,)))
    cands = np.concatenate(parts, axis=-1).reshape(-1, nk + 1 + int(layout.noise))
    a0 = eqx.tree_at(lambda x: x.se, a, _model_se(jnp.asarray(scale), a))
    chi2 = np.asarray(_chi2_many(jnp.asarray(cands), a0))
    chi2 = np.where(np.isfinite(chi2), chi2, np.inf)
    return cands[np.argsort(chi2)]


def _internal(p, is_log, v_scale):
    scale = np.where(is_log, p, v_scale)
    x0 = np.where(is_log, 0.0, p / v_scale)
    return scale, x0


def _irls(args: VarianceArgs, p0, is_log, max_pass: int = 40):
    """Reweighted least squares to the fixed point (weights = model SE at the estimate).
    Returns ``(p, args, chi2, converged)``; ``args`` carries the final weights."""
    p = np.asarray(p0, dtype=float).copy()
    v_scale = float(np.median(np.asarray(args.v)))
    free = np.asarray(is_log)  # eps^2 (if any) is projected out
    chi2 = np.inf  # (max_pass >= 1 always sets it)
    for _ in range(max_pass):
        scale, x0 = _internal(p, is_log, v_scale)
        args = eqx.tree_at(lambda a: a.se, args, _model_se(jnp.asarray(p), args))
        sc = jnp.asarray(scale)
        x, chi2, ok = _solve_lsq(args, sc, x0, free)
        if not ok:
            return p, args, chi2, False
        p_new = np.asarray(_params(jnp.asarray(x), sc, args))
        # the weights' change moves the optimum: stop when a pass moves it by less than
        # ~1e-4 sqrt(chi^2 + n) standard errors
        dp = p_new - p
        moved = float(dp @ np.asarray(_fisher_p(jnp.asarray(p_new), args)) @ dp)
        p = p_new
        if moved <= 1e2 * _DECREMENT_RTOL * (chi2 + p.size):
            return p, args, chi2, True
    return p, args, chi2, False


def fit_variances(args: VarianceArgs, scale):
    """Weighted least squares of the sample variances with the model's own correlated-frame
    standard errors as weights, iterated to the fixed point (IRLS).

    Robust by construction: eps^2 enters linearly and is projected out in closed form
    (bounded at 0); k (or c) and gamma are fitted in log scale from the best point of a
    global grid over D (and eps^2) with the closed-form Pade stiffness per recording, with
    the moment start ``scale`` and further grid points as fallbacks; convergence is judged
    by the Gauss-Newton decrement relative to chi^2 + dof (not by a rounding-level
    tolerance). Returns ``(p, cov, chi2, converged, fisher_pd, args)`` (``args`` with the
    final weights, for profile intervals)."""
    _, is_log = _layout_kinds(args.layout)
    scale = np.asarray(scale, dtype=float)
    grid = _grid_starts(args, scale)
    starts = [grid[0], scale] + list(grid[1:80:8])
    best = None
    for i, p0 in enumerate(starts):
        if best is not None and i >= 2:
            break
        out = _irls(args, p0, is_log)
        if out[-1] and (best is None or out[2] < best[2]):
            best = out
    if best is None:
        nan = np.full((scale.size, scale.size), np.nan)
        return scale, nan, np.nan, False, False, args
    p, a, _, _ = best
    # chi^2 and the Fisher information with the weights at the estimate itself
    a = eqx.tree_at(lambda x: x.se, a, _model_se(jnp.asarray(p), a))
    chi2 = float(np.asarray(_chi2_many(jnp.asarray(p)[None], a))[0])
    fisher = np.asarray(_fisher_p(jnp.asarray(p), a))
    dg = np.sqrt(np.clip(np.diag(fisher), 1e-300, None))
    evals = np.linalg.eigvalsh(fisher / dg[:, None] / dg[None, :])
    pd = bool(np.all(np.isfinite(evals)) and np.min(evals) > 1e-12 * np.max(evals))
    cov = np.linalg.inv(fisher) if pd else np.full_like(fisher, np.nan)
    return p, cov, float(chi2), True, pd, a
