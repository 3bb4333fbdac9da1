"""95 % profile-likelihood (chi^2 profile) intervals of the variance-method fits
(:func:`blurtrap.inference._variance.fit_variances`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._variance import (
    VarianceArgs,
    _fisher_p,
    _internal,
    _layout_kinds,
    _model_se,
    _params,
    _solve_lsq,
)

#: Delta chi^2 of a 95 % profile interval for one parameter (chi^2_1 quantile).
CHI2_95 = 3.841458820694124


def profile_intervals(a: VarianceArgs, p, chi2_min, level_delta=CHI2_95, max_factor=1e3,
                      reweight=True):
    """95 % profile-likelihood (chi^2 profile) interval of every parameter: ``{i: (low,
    high)}`` in SI. Each end is where the minimum of chi^2 over the other parameters
    (eps^2 >= 0) rises by ``level_delta`` above the unconstrained minimum. ``reweight``
    (default): the weights (model SE of each sample variance) are re-evaluated at each
    profile point (the constrained fit reweighted to its own fixed point, and the minimum
    recomputed with the same weights); otherwise they are held at the fit's. Held weights
    under-cover where the weights change along the profile (a low gamma estimate means a
    short tau and small SEs, which inflate the chi^2 rise at the truth: 89-92 % for c in
    variance vs power at W = dt = 1/1500 s; benchmarks/RESULTS_variance_methods.md).
    Ends are found by bracketing and bisection in log scale (linear for eps^2). An end
    that is not reached within a factor ``max_factor`` of the estimate is reported as 0 or
    inf (the data do not bound it); eps^2 whose chi^2 at 0 is within the level gets 0.
    Interval ends that fail to converge are NaN."""
    _, is_log = _layout_kinds(a.layout)
    p = np.asarray(p, dtype=float)
    v_scale = float(np.median(np.asarray(a.v)))
    scale, x_hat = _internal(p, is_log, v_scale)
    sc = jnp.asarray(scale)
    fisher = np.asarray(_fisher_p(jnp.asarray(p), a))
    try:
        se = np.sqrt(np.clip(np.diag(np.linalg.inv(fisher)), 0, None))
    except np.linalg.LinAlgError:
        se = np.abs(p) * 0.1
    out = {}
    n = p.size
    for j in range(n):
        eps_param = not is_log[j]
        # eps^2 profiled: hold it, fit the others in log scale (no projection)
        profile_eps = not eps_param
        free = np.asarray(is_log).copy()
        free[j] = False
        step = se[j] / scale[j] if eps_param else max(se[j] / max(p[j], 1e-300), 1e-6)
        step = step if np.isfinite(step) and step > 0 else (0.1 if not eps_param else 1e-3)

        def excess(t, x_start):
            x0 = x_start.copy()
            x0[j] = t
            if reweight:
                d, x = _reweighted_delta(a, sc, x0, free, profile_eps, x_hat, is_log)
                return d - level_delta, x, bool(np.isfinite(d))
            x, c2, _ = _solve_lsq(a, sc, x0, free, profile_eps, max_iter=100, atol=1e-4)
            # a solve that stalls (the eps^2 >= 0 kink, or a parameter running off along an
            # unbounded direction) still gives an upper bound on the profile minimum: use it
            return c2 - chi2_min - level_delta, x, bool(np.isfinite(c2))

        ends = []
        for sign in (-1.0, 1.0):
            lo_t, x_lo, f_lo = x_hat[j], x_hat.copy(), -level_delta
            t = x_hat[j] + sign * step
            end = np.nan
            for _ in range(60):
                if eps_param and t <= 0.0:
                    f0, x0, ok = excess(0.0, x_lo)
                    if ok and f0 <= 0:
                        end = 0.0
                        break
                    t = 0.0
                    f, xt = f0, x0
                else:
                    f, xt, ok = excess(t, x_lo)
                if not ok:
                    break
                if f > 0:  # bracketed between lo_t (inside) and t (outside)
                    end = _bisect(excess, lo_t, x_lo, f_lo, t, f, 0.01 * step)
                    break
                lo_t, x_lo, f_lo = t, xt, f
                far = (abs(t - x_hat[j]) > np.log(max_factor)) if not eps_param else \
                    (abs(t - x_hat[j]) * scale[j] > max_factor * max(p[j], se[j]))
                if far:
                    end = -np.inf if sign < 0 else np.inf
                    break
                if eps_param and t == 0.0:
                    break
                step_t = (t - x_hat[j]) * 2.0
                t = x_hat[j] + step_t
            ends.append(end)
        if eps_param:
            lo, hi = (scale[j] * e if np.isfinite(e) or np.isnan(e) else e for e in ends)
            lo = max(lo, 0.0) if np.isfinite(lo) else lo
        else:
            lo, hi = (scale[j] * np.exp(e) if not np.isnan(e) else np.nan for e in ends)
        out[j] = (float(lo), float(hi))
    return out


def _bisect(excess, lo_t, x_lo, f_lo, hi_t, f_hi, t_tol, f_tol=0.05, max_iter=60):
    """The root of ``excess`` between ``lo_t`` (excess ``f_lo`` <= 0) and ``hi_t``
    (``f_hi`` > 0): bisection until the bracket is below ``t_tol`` *and* the excess across
    it below ``f_tol`` (a step-size tolerance alone leaves the end ~0.3 in chi^2 off where
    the profile is much narrower than the Wald SE, e.g. eps^2 on its bound), then linear
    interpolation inside the bracket (its middle where the profile jumps). NaN where a solve
    fails."""
    for _ in range(max_iter):
        if abs(hi_t - lo_t) < t_tol and f_hi - f_lo < f_tol:
            return lo_t + (hi_t - lo_t) * (-f_lo) / (f_hi - f_lo)
        if abs(hi_t - lo_t) < 1e-4 * t_tol:  # a jump in the profile: the bracket's middle
            return 0.5 * (lo_t + hi_t)
        mid = 0.5 * (lo_t + hi_t)
        fm, xm, okm = excess(mid, x_lo)
        if not okm:
            return np.nan
        if fm > 0:
            hi_t, f_hi = mid, fm
        else:
            lo_t, x_lo, f_lo = mid, xm, fm
    return np.nan


def _reweighted_delta(a, sc, x0, free, profile_eps, x_hat, is_log, n_pass=3):
    """Profile chi^2 excess with the weights re-evaluated at the profile point: the
    constrained fit is reweighted to its own fixed point (weights = model SE at the
    constrained estimate), and the unconstrained minimum is recomputed with those same
    weights, so that both terms of the difference use one set of weights."""
    x = x0
    for _ in range(n_pass):
        x, c2, _ = _solve_lsq(a, sc, x, free, profile_eps, max_iter=100, atol=1e-4)
        p_con = _params(jnp.asarray(x), sc, a, profile_eps)
        a = eqx.tree_at(lambda z: z.se, a, _model_se(p_con, a))
    x, c2, _ = _solve_lsq(a, sc, x, free, profile_eps, max_iter=100, atol=1e-4)
    ref = np.inf
    for xs in (x_hat, x):
        _, c_ref, _ = _solve_lsq(a, sc, np.asarray(xs, dtype=float), np.asarray(is_log),
                                 True, max_iter=100, atol=1e-4)
        ref = min(ref, c_ref)
    return c2 - ref, x
