"""95 % profile-likelihood (chi^2 profile) intervals of the variance-method fits
(:func:`blurtrap.inference._variance.fit_variances`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._variance import VarianceArgs, _fisher_p, _internal, _layout_kinds, _solve_lsq

#: Delta chi^2 of a 95 % profile interval for one parameter (chi^2_1 quantile).
CHI2_95 = 3.841458820694124


def profile_intervals(a: VarianceArgs, p, chi2_min, level_delta=CHI2_95, max_factor=1e3):
    """95 % profile-likelihood (chi^2 profile) interval of every parameter, the weights held
    at the fit's: ``{i: (low, high)}`` in SI. Each end is where the minimum of chi^2 over
    the other parameters (eps^2 >= 0) rises by ``level_delta``; found by bracketing and
    bisection in log scale (linear for eps^2). An end that is not reached within a factor
    ``max_factor`` of the estimate is reported as 0 or inf (the data do not bound it);
    eps^2 whose chi^2 at 0 is within the level gets 0. Interval ends that fail to converge
    are NaN."""
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
            x, c2, _ = _solve_lsq(a, sc, x0, free, profile_eps, max_iter=100, atol=1e-4)
            # a solve that stalls (the eps^2 >= 0 kink, or a parameter running off along an
            # unbounded direction) still gives an upper bound on the profile minimum: use it
            return c2 - chi2_min - level_delta, x, bool(np.isfinite(c2))

        ends = []
        for sign in (-1.0, 1.0):
            lo_t, x_lo = x_hat[j], x_hat.copy()
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
                if f > 0:  # bracketed between lo_t (inside) and t (outside): bisect
                    hi_t = t
                    for _ in range(40):
                        mid = 0.5 * (lo_t + hi_t)
                        fm, xm, okm = excess(mid, x_lo)
                        if not okm:
                            break
                        if fm > 0:
                            hi_t = mid
                        else:
                            lo_t, x_lo = mid, xm
                        if abs(hi_t - lo_t) < 0.01 * step:
                            end = 0.5 * (lo_t + hi_t)
                            break
                    break
                lo_t, x_lo = t, xt
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
