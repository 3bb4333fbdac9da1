"""eps^2 at its bound 0: one bound rule for fit and result, NaN error for the bound parameter,
conditional errors for the others, and profile-likelihood intervals checked against an
independent optimiser (scipy L-BFGS-B on the negative log-likelihood in natural units)."""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _circulant import circulant_frames
from scipy.optimize import minimize

import blurtrap as bt
from blurtrap.inference import _profile
from blurtrap.inference._fit import BOUND_NLL, at_lower_bound

T = 295.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1.0 / 1500.0


def _frames(k, w, eps2, n, seed):
    """Exact stationary frames by circulant embedding (numpy only, not blurtrap's simulator)."""
    return circulant_frames(k, GAMMA, w, DT, eps2, n, seed, temperature=T)


def _fit(k, w, eps2, n, seed):
    rec = bt.Recording(_frames(k, w, eps2, n, seed), frame_interval=DT, exposure=w,
                       temperature=T)
    return bt.calibrate(rec, method="likelihood", likelihood="whittle")


@pytest.fixture(scope="module")
def at_bound_fit():
    """A 16 384-frame record with no tracking noise, k = 0.05 pN/nm, W = 0.1 dt: eps^2 runs
    to its bound in about half the seeds; the first such seed."""
    for seed in range(40):
        fit = _fit(5e-5, 0.1 * DT, 0.0, 2**14, seed)
        if fit.at_bounds:
            return fit
    pytest.fail("no seed put eps^2 at its bound")


@pytest.fixture(scope="module")
def interior_fit():
    """Well conditioned: k = 0.01 pN/nm, eps = 6 nm (eps^2 ~ 4 SE), 16 384 frames."""
    return _fit(1e-5, 0.1 * DT, (6e-9) ** 2, 2**14, 7)


def _independent_profile(fit, i, value):
    """min over the other parameters (natural units, eps^2 >= 0) of the fit's own negative
    log-likelihood with parameter i held at ``value``: scipy L-BFGS-B from several starts."""
    src = fit.interval_source
    sc = np.abs(np.asarray(fit.values, float))
    sc[2] = max(sc[2], math.sqrt(abs(src.cov[2, 2])) if np.isfinite(src.cov[2, 2]) else 0.0,
                1e-18)
    f = jax.jit(lambda q: src.nll(jnp.asarray(sc) * q, src.args))
    free = [j for j in range(3) if j != i]
    best = math.inf
    for e0 in (0.0, 0.3, 1.0, 3.0):
        def obj(z):
            q = np.empty(3)
            q[i] = value / sc[i]
            q[free] = z
            return float(f(jnp.asarray(q)))

        z0 = np.array([fit.values[j] / sc[j] for j in free])
        if 2 in free:
            z0[-1] = e0
        res = minimize(obj, z0, method="L-BFGS-B",
                       bounds=[(0.0, None) if j == 2 else (1e-3, None) for j in free],
                       options={"ftol": 1e-15, "gtol": 1e-11, "maxiter": 500})
        best = min(best, res.fun)
    return best


def test_bound_rule_is_one_rule(at_bound_fit):
    fit = at_bound_fit
    assert fit.at_bounds == ("tracking_var",)
    # the bound parameter: NaN error; the others: finite errors (the unconstrained bound,
    # tests/inference/test_bound_errors.py)
    assert math.isnan(fit.tracking_var_err)
    assert np.isfinite(fit.k_err) and fit.k_err > 0
    assert np.isfinite(fit.gamma_err) and fit.gamma_err > 0
    cov = fit.covariance
    assert np.isnan(cov[2, 2]) and cov[0, 2] == 0 and cov[1, 2] == 0
    # the same rule, evaluated on the fit's own objective: the change of the objective when
    # eps^2 goes from its estimate to 0 is below BOUND_NLL
    src = fit.interval_source
    p = np.asarray(fit.values, float)
    v_hat = float(src.nll(jnp.asarray(p), src.args))
    v_zero = float(src.nll(jnp.asarray(np.r_[p[:2], 0.0]), src.args))
    assert abs(v_zero - v_hat) < BOUND_NLL
    # ... and at_lower_bound says so from log-space derivatives at the estimate
    from blurtrap.inference._fit import _plan

    pass_fn = _plan(src.nll, src.args)[0]
    x = jnp.log(jnp.asarray(p) / jnp.asarray(src.scale))
    _, g, h = pass_fn(x, jnp.asarray(src.scale), src.args)
    assert np.asarray(at_lower_bound(g, h)).tolist() == [False, False, True]


def test_at_bound_intervals(at_bound_fit):
    fit = at_bound_fit
    ivs, kinds = fit.intervals, fit.interval_kinds
    assert set(kinds.values()) == {"profile"}  # a bound makes every Wald interval suspect
    lo, hi = ivs["tracking_var"]
    assert lo == 0.0 and np.isfinite(hi) and hi > 0
    for name in ("k", "gamma"):
        lo, hi = ivs[name]
        v = fit.params[name]
        assert 0 < lo < v < hi
        # honest: wider than the conditional Wald interval (the bound held fixed; the
        # interval source keeps that covariance, the reported errors are unconstrained)
        j = fit.param_names.index(name)
        assert hi - lo > 2 * 1.96 * math.sqrt(fit.interval_source.cov[j, j])
    d = fit.to_dict()
    json.dumps(d["intervals"], allow_nan=False)  # JSON-safe (NaN ends would be None)
    assert d["intervals"]["tracking_var"][0] == 0.0
    assert d["interval_kinds"]["k"] == "profile"
    assert "95 % interval" in fit.summary() and "profile" in fit.summary()


def test_profile_end_points_drop_by_1_92(at_bound_fit, interior_fit):
    for fit in (at_bound_fit, interior_fit):
        src = fit.interval_source
        low, high, ok = _profile.profile_intervals(src.nll, src.args, src.scale, src.value,
                                                   src.cov, src.at_bound)
        assert ok.all()
        v_min = min(_independent_profile(fit, 0, float(fit.values[0])),
                    _independent_profile(fit, 1, float(fit.values[1])))
        for i in range(3):
            for end in (low[i], high[i]):
                if end == 0.0:  # the bound: the profile there is within 1.92
                    assert _independent_profile(fit, i, 0.0) - v_min <= _profile.DROP
                    continue
                drop = _independent_profile(fit, i, float(end)) - v_min
                assert abs(drop - _profile.DROP) < 5e-3, (fit.param_names[i], end, drop)


def test_intervals_match_wald_when_well_conditioned(interior_fit):
    fit = interior_fit
    assert fit.at_bounds == ()
    src = fit.interval_source
    low, high, ok = _profile.profile_intervals(src.nll, src.args, src.scale, src.value,
                                               src.cov, src.at_bound)
    assert ok.all()
    for i, name in enumerate(fit.param_names):
        v, se = fit.values[i], fit.errors[i]
        half = 1.959964 * se
        assert low[i] < v < high[i]
        lo, hi = fit.intervals[name]
        assert lo < v < hi
        # k and gamma: within a few % of the Wald half-width; eps^2 (4 SE from its bound,
        # visibly skewed) within 15 %
        tol = 0.04 if name != "tracking_var" else 0.15
        assert abs((v - low[i]) / half - 1) < tol, (name, low[i], v - half)
        assert abs((high[i] - v) / half - 1) < tol, (name, high[i], v + half)
    # where the quadratic check passes the Wald interval itself is reported
    kinds = fit.interval_kinds
    for name in ("k", "gamma"):
        if kinds[name] == "wald":
            i = fit.param_names.index(name)
            lo, hi = fit.intervals[name]
            assert lo == pytest.approx(fit.values[i] - 1.959964 * fit.errors[i], rel=1e-6)


def test_results_without_a_likelihood_get_wald_intervals():
    rec = bt.Recording(_frames(1e-5, 0.1 * DT, 4e-18, 4096, 3), frame_interval=DT,
                       exposure=0.1 * DT, temperature=T)
    fit = bt.calibrate(rec, method="equipartition")
    lo, hi = fit.intervals["k"]
    assert lo == pytest.approx(fit.k - 1.959964 * fit.k_err)
    assert hi == pytest.approx(fit.k + 1.959964 * fit.k_err)
    assert fit.interval_kinds == {"k": "wald"}
