"""The safeguarded Newton minimiser as an optimistix solver, and the objective type."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.optimize
import scipy.stats

from blurtrap.inference import _fit
from blurtrap.inference._newton import (
    AbstractObjective,
    FunctionObjective,
    SafeguardedNewton,
    as_objective,
    newton_minimise,
)
from blurtrap.inference._problems import SpectralObjective, spectral_nll


def _rosenbrock(x, args):
    return (1.0 - x[0]) ** 2 + 100.0 * (x[1] - x[0] ** 2) ** 2


def _with_derivatives(f):
    """``fn(x, args) -> (value, (grad, hess))``, the protocol of SafeguardedNewton."""

    def fn(x, args):
        return f(x, args), (jax.grad(f)(x, args), jax.hessian(f)(x, args))

    return fn


def test_minimiser_through_optx_minimise_finds_the_rosenbrock_minimum():
    """The Hessian is indefinite at parts of the path from (-1.2, 1): the modified direction
    and the backtracking keep it descending; optimum (1, 1), checked against scipy too."""
    x0 = jnp.array([-1.2, 1.0])
    sol = optx.minimise(_with_derivatives(_rosenbrock), SafeguardedNewton(rtol=1e-10, atol=1e-10),
                        x0, has_aux=True, max_steps=200, throw=False)
    assert sol.result == optx.RESULTS.successful
    ref = scipy.optimize.minimize(lambda z: float(_rosenbrock(jnp.asarray(z), None)),
                                  np.array([-1.2, 1.0]), method="Nelder-Mead",
                                  options={"xatol": 1e-10, "fatol": 1e-20, "maxiter": 20000})
    np.testing.assert_allclose(np.asarray(sol.value), [1.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(np.asarray(sol.value), ref.x, atol=1e-6)
    assert 5 < int(sol.stats["num_steps"]) < 200
    g, h = sol.aux  # gradient and Hessian at the last accepted point
    assert float(jnp.max(jnp.abs(g))) < 1e-6 and float(jnp.min(jnp.linalg.eigvalsh(h))) > 0


def test_running_out_of_steps_is_reported():
    sol = optx.minimise(_with_derivatives(_rosenbrock), SafeguardedNewton(rtol=1e-10, atol=1e-10),
                        jnp.array([-1.2, 1.0]), has_aux=True, max_steps=3, throw=False)
    assert sol.result == optx.RESULTS.nonlinear_max_steps_reached
    assert not bool(sol.state.done)


def _nan_away(x, args):
    """Finite only at the start point (an objective no step can decrease)."""
    x0, bad = args
    base = jnp.sum((x - 2.0) ** 2)
    return jnp.where(bad & jnp.any(x != x0), jnp.nan, base)


def test_a_search_that_cannot_decrease_reports_divergence_per_batch_item():
    """Under vmap one failing item must not abort or spoil the others (throw=False)."""
    x0 = jnp.zeros(2)

    def one(bad):
        def pass_fn(x, scale, args):
            v, (g, h) = _with_derivatives(_nan_away)(x, args)
            return v, g, h

        return newton_minimise(pass_fn, None, (x0, bad), x0, 1e-9, 1e-9, 64)

    sol = jax.vmap(one)(jnp.array([False, True]))
    assert list(np.asarray(sol.result == optx.RESULTS.successful)) == [True, False]
    assert list(np.asarray(sol.result == optx.RESULTS.nonlinear_divergence)) == [False, True]
    np.testing.assert_allclose(np.asarray(sol.value[0]), [2.0, 2.0], atol=1e-12)
    assert bool(sol.state.done[0]) and not bool(sol.state.done[1])


C = jnp.array([0.5, 2.0, 1.3])


def _convex_nll(p, args):
    return jnp.sum(p - C * jnp.log(p))  # optimum p = C, var(p_i) = C_i exactly


class _SlowHessian(AbstractObjective):
    """The same objective, with a pass whose Hessian is 3x too large (linear convergence,
    rate 2/3): the fit can only be slow if it really uses this pass."""

    def __call__(self, p, args):
        return _convex_nll(p, args)

    def value_grad_hess(self, x, scale, args):
        v, g, h = super().value_grad_hess(x, scale, args)
        return v, g, 3.0 * h


def test_fit_ml_uses_the_objective_own_pass():
    scale = jnp.ones(3)
    plain = _fit.fit_ml(_convex_nll, scale, None)
    slow = _fit.fit_ml(_SlowHessian(), scale, None)
    # the covariance comes from the pass's Hessian too: C for the true one, C / 3 here
    for out, factor in ((plain, 1.0), (slow, 3.0)):
        assert bool(out.success) and out.result == optx.RESULTS.successful
        np.testing.assert_allclose(np.asarray(out.value), np.asarray(C), rtol=1e-8)
        np.testing.assert_allclose(np.diag(np.asarray(out.cov)), np.asarray(C) / factor,
                                   rtol=1e-6)
    assert int(plain.n_steps) <= 8 < 30 < int(slow.n_steps)


def test_objectives():
    assert isinstance(spectral_nll, SpectralObjective)
    wrapped = as_objective(_convex_nll)
    assert isinstance(wrapped, FunctionObjective) and as_objective(wrapped) is wrapped
    assert wrapped.coarse_args(None) is None
    p = jnp.array([1.0, 2.0, 3.0])
    assert float(wrapped(p, None)) == float(_convex_nll(p, None))
    with pytest.raises(TypeError, match=r"nll must be callable as nll\(p, args\); got nll = 3"):
        as_objective(3)


def _gamma_nll(p, y):
    shape, rate = p
    return -jnp.sum(shape * jnp.log(rate) - jax.scipy.special.gammaln(shape)
                    + (shape - 1.0) * jnp.log(y) - rate * y)


def test_fd_newton_fit_agrees_with_the_exact_hessian_fit_and_scipy():
    """Gamma-distribution maximum likelihood: the finite-difference-Hessian Newton (one
    compiled loop) against the autodiff-Hessian fit and scipy.stats.gamma.fit; its
    covariance against the exact observed information (O(h^2) ~ 1e-8 relative)."""
    y = jnp.asarray(np.random.default_rng(5).gamma(3.0, 1 / 2.0, size=500))
    scale = jnp.array([1.0, 1.0])
    fd = _fit.fit_ml_fd_newton(_gamma_nll, scale, y)
    ad = _fit.fit_ml(_gamma_nll, scale, y)
    assert bool(fd.success) and fd.result == optx.RESULTS.successful
    a, _, sc = scipy.stats.gamma.fit(np.asarray(y), floc=0)
    np.testing.assert_allclose(np.asarray(fd.value), [a, 1 / sc], rtol=1e-4)
    np.testing.assert_allclose(np.asarray(fd.value), np.asarray(ad.value), rtol=1e-8)
    np.testing.assert_allclose(np.asarray(fd.cov), np.asarray(ad.cov), rtol=1e-6)


def test_a_fit_started_at_its_optimum_converges_despite_rounding_in_the_value():
    """Started at the optimum (as after an exact coarse fit) of an objective of size ~1e6
    whose later evaluations come out a few 1e-15 relative higher (a long record's sum in
    another order), the host Newton loop stops after one step and the fit counts as converged
    (before: the end value above the start by rounding failed the check, and calibrate fell
    back to BFGS compiled per padded length: a 1.5e6-sample photodiode record)."""
    from blurtrap.inference import _chunked

    calls = []
    x_opt = jnp.array([0.3, -0.2])

    def pass_fn(x):
        calls.append(1)
        d = x - x_opt
        noise = 0.0 if len(calls) == 1 else 3e-9  # later passes: +3e-15 relative
        v = 1e6 + 0.5e5 * jnp.dot(d, d) + noise
        return v, 1e5 * d, 1e5 * jnp.eye(2)

    # 1e-7 from the optimum: one Newton step, whose end value is above the start by rounding
    st, res = _chunked.host_newton_loop(pass_fn, x_opt + 1e-7, 1e-9, 1e-9, 64)
    assert len(calls) == 2 and float(st.value) > float(st.value_start)
    fit = _fit._fit_from_state(st, res)
    assert bool(fit.ok) and res == optx.RESULTS.successful
    np.testing.assert_allclose(np.asarray(fit.x_hat), np.asarray(x_opt), atol=1e-12)
    # a real increase above the start is still refused (rounding allowance 1e-12 relative)
    from blurtrap.inference._newton import not_above

    assert bool(not_above(1e6 + 3e-10, 1e6)) and bool(not_above(-1e6 + 3e-10, -1e6))
    assert not bool(not_above(1e6 + 1e-3, 1e6)) and not bool(not_above(2e-12, 0.0))
