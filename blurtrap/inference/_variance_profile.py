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
                      reweight=True, info=None):
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
    Interval ends that fail to converge are NaN. Where the profile set has a second
    component at small eps^2 (see ``_second_branch``) the intervals are its hull with the
    first, and ``info`` (a dict, if given) gets ``"second_branch"``: ``(point, delta)``, the
    constrained fit at eps^2 = 0 (SI) and its Delta chi^2."""
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
    n = p.size
    cut = float(level_delta)
    ends, excess_fns, steps = {}, {}, {}
    for j in range(n):
        eps_param = not is_log[j]
        step = se[j] / scale[j] if eps_param else max(se[j] / max(p[j], 1e-300), 1e-6)
        steps[j] = step if np.isfinite(step) and step > 0 else (0.1 if not eps_param else 1e-3)
        excess_fns[j] = _excess_fn(a, sc, j, is_log, x_hat, chi2_min, reweight, cut)
        far = _far_fn(j, is_log, x_hat, scale, p, se, max_factor)
        ends[j] = [_walk(excess_fns[j], x_hat[j], x_hat, -cut, sign, steps[j], far, not is_log[j])
                   for sign in (-1.0, 1.0)]
    if a.layout.noise and ends[n - 1][0] > 0.0:
        alt = _second_branch(ends, excess_fns, steps, is_log, x_hat, scale, p, se, max_factor)
        if alt is not None and info is not None:
            x0, d0 = alt
            info["second_branch"] = (np.asarray(_params(jnp.asarray(x0), sc, a, False)),
                                     d0 + cut)
    out = {}
    for j in range(n):
        if not is_log[j]:
            lo, hi = (scale[j] * e if np.isfinite(e) or np.isnan(e) else e for e in ends[j])
            lo = max(lo, 0.0) if np.isfinite(lo) else lo
        else:
            lo, hi = (scale[j] * np.exp(e) if not np.isnan(e) else np.nan for e in ends[j])
        out[j] = (float(lo), float(hi))
    return out


def _excess_fn(a, sc, j, is_log, x_hat, chi2_min, reweight, cut):
    """``excess(t, x_start) -> (Delta chi^2 - cut, constrained x, ok)`` with parameter ``j``
    held at internal value ``t``."""
    eps_param = not is_log[j]
    profile_eps = not eps_param  # eps^2 profiled: hold it, fit the others in log scale
    free = np.asarray(is_log).copy()
    free[j] = False

    def excess(t, x_start):
        x0 = np.asarray(x_start, dtype=float).copy()
        x0[j] = t
        if reweight:
            d, x = _reweighted_delta(a, sc, x0, free, profile_eps, x_hat, is_log)
            return d - cut, x, bool(np.isfinite(d))
        x, c2, _ = _solve_lsq(a, sc, x0, free, profile_eps, max_iter=100, atol=1e-4)
        # a solve that stalls (the eps^2 >= 0 kink, or a parameter running off along an
        # unbounded direction) still gives an upper bound on the profile minimum: use it
        return c2 - chi2_min - cut, x, bool(np.isfinite(c2))

    return excess


def _far_fn(j, is_log, x_hat, scale, p, se, max_factor):
    if is_log[j]:
        return lambda t: abs(t - x_hat[j]) > np.log(max_factor)
    return lambda t: abs(t - x_hat[j]) * scale[j] > max_factor * max(p[j], se[j])


def _walk(excess, t0, x0, f0, sign, step, far, eps_param):
    """The end of the profile set's component that contains ``t0`` (excess ``f0`` <= 0,
    constrained point ``x0``) on the side ``sign``: steps doubling from ``t0`` until the
    excess is positive, then bisection; +-inf where ``far`` (unbounded), NaN where a solve
    fails; eps^2 stops at its bound 0."""
    lo_t, x_lo, f_lo = t0, np.asarray(x0, dtype=float).copy(), f0
    t = t0 + sign * step
    for _ in range(60):
        if eps_param and t <= 0.0:
            f, xt, ok = excess(0.0, x_lo)
            if ok and f <= 0:
                return 0.0
            t = 0.0
        else:
            f, xt, ok = excess(t, x_lo)
        if not ok:
            return np.nan
        if f > 0:  # bracketed between lo_t (inside) and t (outside)
            return _bisect(excess, lo_t, x_lo, f_lo, t, f, 0.01 * step)
        lo_t, x_lo, f_lo = t, xt, f
        if far(t):
            return -np.inf if sign < 0 else np.inf
        if eps_param and t == 0.0:
            return np.nan
        t = t0 + (t - t0) * 2.0
    return np.nan


def _second_branch(ends, excess_fns, steps, is_log, x_hat, scale, p, se, max_factor):
    """The profile set can have two components where the exposures hardly separate sigma^2
    from eps^2: one around the estimate and one at small eps^2 (k and gamma near the values
    that read the variances as mostly thermal), with a hump of Delta chi^2 ~ 5-7 between
    them (variance vs exposure at alpha = 0.05-0.5; benchmarks/RESULTS_variance_methods.md,
    session 12). Bracketing outward from the estimate stops at the hump. Here: if eps^2 = 0
    itself is within the cut, the intervals are widened to the hull of both components
    (eps^2 down to 0; every other parameter at least to its value at the constrained fit
    with eps^2 = 0, and on to the outer end of that value's component where the parameter's
    own profile is within the cut there: with reweighting, the statistic is not exactly a
    minimum over the others, and the constrained solve can land on the other branch).
    Updates ``ends`` in place; returns ``(x, excess)`` at the eps^2 = 0 point, or None."""
    je = len(is_log) - 1
    f0, x0, ok = excess_fns[je](0.0, x_hat)
    if not (ok and f0 <= 0.0):
        return None
    ends[je][0] = 0.0
    for j in np.flatnonzero(is_log):
        t_alt = float(x0[j])
        lo, hi = ends[j]
        side = 1 if t_alt > hi else 0 if t_alt < lo else None
        if side is None:
            continue
        ends[j][side] = t_alt  # the hull contains the eps^2 = 0 point itself
        f, xa, ok = excess_fns[j](t_alt, x0)
        if ok and f <= 0.0:
            far = _far_fn(j, is_log, x_hat, scale, p, se, max_factor)
            end = _walk(excess_fns[j], t_alt, xa, f, 1.0 if side else -1.0, steps[j], far, False)
            ends[j][side] = end if not np.isnan(end) else t_alt
    return x0, f0


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
