"""Generic maximum-likelihood machinery: Newton's method on the score in log parameters
(BFGS fallback), observed-Fisher covariance in natural parameters, result codes.

Every parameter handled here is positive (k, gamma, eps^2, c ...). The optimiser works in
``x = log(p / scale)`` (O(1) unknowns, positivity by construction); the covariance is the
inverse Hessian of the negative log-likelihood with respect to the *natural* parameters
(scaled to O(1) for conditioning), so that a parameter near its lower bound 0 (eps^2) keeps a
finite, meaningful standard error. One *at* the bound (:func:`at_lower_bound`, the single rule
of the package) gets a NaN variance, and the others' errors are the unconstrained Cramer-Rao
bound at the estimate: the inverse of the full observed information in natural parameters,
the bound parameter included as free (:func:`._bound_errors.release_bound`).

The Newton iteration is the optimistix minimiser
:class:`blurtrap.inference._newton.SafeguardedNewton`. Each iteration needs the value,
gradient and exact Hessian at one point (a "pass"): JAX autodiff of ``nll`` by default; an
objective that is an :class:`blurtrap.inference._newton.AbstractObjective` may provide a
faster pass and a cheap coarse version of its data for start values (see
:class:`blurtrap.inference._problems.SpectralObjective`).
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from . import _chunked
from ._bound_errors import release_bound
from ._chi2 import chi2_sf as chi2_sf
from ._chunked import (
    chunked_applies,
    coarse_chunks,
    host_newton_loop,
    host_newton_minimise,
    ordinate_chunks,
)
from ._exact_chunks import exact_chunk_grads, exact_chunk_pass
from ._newton import MAX_LOG_STEP as MAX_LOG_STEP
from ._newton import (
    FdObjective,
    as_objective,
    autodiff_pass,
    fd_hessian_pass,
    newton_iterate,
    newton_minimise,
    not_above,
)

#: Newton iterations before giving up (the BFGS fallback takes over)
NEWTON_STEPS = 64
#: tolerance and step limit of the coarse start-value fit (its optimum is only ~1e-3 from the
#: final one; if it fails the full fit starts from the closed-form start values)
COARSE_TOL = 1e-5
COARSE_STEPS = 16


class FitOutput(eqx.Module):
    value: jax.Array  # natural parameters
    cov: jax.Array  # covariance of natural parameters
    nll: jax.Array
    grad_norm: jax.Array
    n_steps: jax.Array
    success: jax.Array  # bool: optimiser converged and Hessian positive definite
    converged: jax.Array
    hessian_pd: jax.Array
    #: bool per parameter: at its lower bound 0 (:func:`at_lower_bound`); NaN variance there
    at_bound: jax.Array | None = None
    #: the optimiser's result code (``successful`` exactly when ``converged``); None where
    #: an output was assembled without one
    result: optx.RESULTS | None = None
    #: with a parameter at its bound (after :func:`._bound_errors.release_bound`): the
    #: covariance conditional on the bound (the others' block of the information inverted;
    #: NaN variance for the bound ones), which the profile intervals use for their first
    #: steps; else None
    cov_given_bound: jax.Array | None = None
    #: with a parameter at its bound: True when ``cov`` is still conditional on the bound (the
    #: full information was not positive definite; the errors are then too small), False
    #: when it is the unconstrained bound; else None
    conditional: jax.Array | None = None


#: THE bound rule (used by every fit and by the result): a positive parameter is at its lower
#: bound 0 when moving it from its estimate to exactly 0, the others held, changes the
#: negative log-likelihood by less than this (in nats; the 95 % interval cut is 1.92, so this
#: is statistically nothing). At an interior optimum that change is (p / sigma)^2 / 2, sigma
#: the parameter's SE conditional on the others: the rule then means p < 1.4e-3 sigma. At a
#: boundary optimum (the score at 0 points into the bound) the log-space fit stops once the
#: change is below the Newton decrement tolerance (< 1e-13 (1 + |nll|)), far below this.
BOUND_NLL = 1e-6


def at_lower_bound(grad_x, h_x):
    """Which parameters are at their lower bound 0, from the gradient and Hessian of the
    objective in log parameters ``x = log(p / scale)`` at the fit (``u = exp(x)``).

    The change of the objective when ``u_i`` goes from its value to 0 (others held) is, to
    second order in ``u_i``, ``-u f' + u^2 f''/2 = H_ii/2 - 3 g_i/2`` (``g_i = u f'``,
    ``H_ii = u^2 f'' + u f'``): below :data:`BOUND_NLL` in magnitude the parameter is at 0.
    Scale-free (no reference to start values or data variances)."""
    h_ii = jnp.diagonal(h_x)
    change = 0.5 * h_ii - 1.5 * grad_x
    return jnp.abs(change) < BOUND_NLL


def _finish_from(x, value, grad_x, h_x, scale, converged, n_steps, x_value=None,
                 result=None):
    """Assemble a FitOutput from the value, gradient and Hessian in log parameters at ``x``:
    observed Fisher information in natural (scaled) parameters u = exp(x),
    d2f/du2 = (H_x - diag(grad_x))/(u u^T). The reported parameters are ``x_value`` (default
    ``x``), e.g. ``x`` plus the final, tiny Newton step. ``result`` (an ``optx.RESULTS``)
    defaults to ``successful`` where ``converged``, else ``nonlinear_divergence``.

    Parameters at their lower bound (:func:`at_lower_bound`, e.g. eps^2 -> 0) are held here:
    the others' covariance is the inverse of their own block of the information (conditional
    on the bound) and the bound parameter's variance is NaN. Its d2f/du2 would be
    (H - g)/u^2 with H and g both ~u: rounding noise, and with it the whole covariance was NaN
    (measured: weak photodiode-filter refits). :func:`._bound_errors.release_bound` then
    replaces the conditional errors by the unconstrained ones (natural-parameter Hessian)."""
    u_hat = jnp.exp(x)
    bound = at_lower_bound(grad_x, h_x)
    free = ~bound
    both = free[:, None] & free[None, :]
    hess = (h_x - jnp.diag(grad_x)) / (u_hat[:, None] * u_hat[None, :])
    hess = 0.5 * (hess + hess.T)
    eye = jnp.eye(x.shape[0], dtype=hess.dtype)
    hess = jnp.where(both, hess, eye)  # bound parameters decoupled (identity rows)
    evals = jnp.linalg.eigvalsh(hess)
    pd = jnp.all(evals > 0) & jnp.all(jnp.isfinite(evals)) & jnp.any(free)
    cov = jnp.linalg.inv(hess) * scale[:, None] * scale[None, :]
    cov = jnp.where(both, cov, jnp.where(eye > 0, jnp.nan, 0.0))
    cov = jnp.where(pd, cov, jnp.nan)
    if result is None:
        result = optx.RESULTS.where(converged, optx.RESULTS.successful,
                                    optx.RESULTS.nonlinear_divergence)
    return FitOutput(
        value=scale * jnp.exp(x if x_value is None else x_value),
        cov=cov,
        nll=value,
        grad_norm=jnp.max(jnp.abs(grad_x)),
        n_steps=n_steps,
        success=converged & pd,
        converged=converged,
        hessian_pd=pd,
        at_bound=bound,
        result=result,
    )


def _finish(f, x, args, scale, result, n_steps):
    """FitOutput at ``x`` with value, gradient and Hessian of ``f(x, (args, scale))`` (the
    objective of :func:`_log_objective`) by autodiff; ``result`` the optimiser's code."""
    a = (args, scale)
    return _finish_from(x, f(x, a), jax.grad(f)(x, a), jax.hessian(f)(x, a), scale,
                        result == optx.RESULTS.successful, n_steps, result=result)


def _log_objective(nll):
    """``f(x, (args, scale)) = nll(scale * exp(x), args)``. ``scale`` travels in the args, not
    in a closure: optimistix closure-converts the objective, and a closed-over traced value
    stays alive in jax's caches (a tracer leak under JAX_CHECK_TRACER_LEAKS)."""

    def f(x, a):
        args, scale = a
        return nll(scale * jnp.exp(x), args)

    return f


def _autodiff_pass(nll):
    return autodiff_pass(nll)


def _plan(nll, args):
    """(pass_fn, coarse_args or None) of the objective (:func:`as_objective`): its own
    value/gradient/Hessian pass (autodiff unless it provides a faster one) and its coarse
    start-value data if it has any."""
    obj = as_objective(nll)
    return obj.value_grad_hess, obj.coarse_args(args)


def _newton_iterate(pass_fn, scale, args, x0, rtol, atol, max_steps, flat_atol=0.0):
    """Safeguarded Newton from ``x0`` (:class:`blurtrap.inference._newton.SafeguardedNewton`
    through ``optx.minimise``). Returns ``(x, value, grad, hess, dx, n_steps, done,
    value_at_x0)`` at the last accepted point ``x``; the estimate is ``x - dx``."""
    return newton_iterate(pass_fn, scale, args, x0, rtol, atol, max_steps, flat_atol)


class _NewtonFit(eqx.Module):
    x_hat: jax.Array  # the estimate (final Newton step applied)
    x: jax.Array  # last evaluated point
    value: jax.Array  # objective at x_hat from the local quadratic model
    grad: jax.Array
    hess: jax.Array
    ok: jax.Array
    n_steps: jax.Array
    result: optx.RESULTS


def _newton_fit(nll, scale, args, rtol, atol, max_steps=NEWTON_STEPS) -> _NewtonFit:
    """Newton fit from the closed-form start ``p = scale`` (``x = 0``), preceded by a fit of
    the objective's coarse version when it has one (start values within ~1e-3 of the optimum
    for a small fraction of the cost of one pass). Reported as converged only if the step
    criterion is met at a finite point that does not raise the objective above its start
    (to rounding: :func:`._newton.not_above`).

    ``x_hat = x - dx`` is the estimate (the final Newton step applied), ``value`` its
    objective from the local quadratic model (error O(|dx|^3)); gradient and Hessian are
    exact at the last evaluated point ``x`` (|x - x_hat| is typically < 1e-6, so the observed
    information differs from that at ``x_hat`` by O(1e-6) relative, far below its own
    sampling error). ``n_steps`` counts the Newton steps on the full objective."""
    pass_fn, coarse = _plan(nll, args)
    x0 = jnp.zeros_like(scale)
    if coarse is not None:
        x0 = _coarse_start(newton_minimise(pass_fn, scale, coarse, x0, COARSE_TOL,
                                           COARSE_TOL, COARSE_STEPS).state, x0)
    sol = newton_minimise(pass_fn, scale, args, x0, rtol, atol, max_steps)
    return _fit_from_state(sol.state, sol.result)


def _coarse_start(c, x0):
    """The start of the full fit after the coarse one (state ``c``): its estimate, accepted
    only if it converged to a finite point that lowers the coarse objective below its value
    at the closed-form start ``x0`` (quadratic model at the last step)."""
    xc = c.x - c.step
    good = (c.done & jnp.all(jnp.isfinite(xc))
            & not_above(c.value - 0.5 * jnp.dot(c.grad, c.step), c.value_start))
    return jnp.where(good, xc, x0)


def _fit_from_state(st, sol_result) -> _NewtonFit:
    """:class:`_NewtonFit` from the final Newton state and the minimiser's result code."""
    x_hat = st.x - st.step
    v_hat = st.value - 0.5 * jnp.dot(st.grad, st.step)
    ok = st.done & jnp.all(jnp.isfinite(x_hat)) & not_above(v_hat, st.value_start)
    result = optx.RESULTS.where(
        ok, optx.RESULTS.successful,
        optx.RESULTS.where(sol_result == optx.RESULTS.successful,
                           optx.RESULTS.nonlinear_divergence, sol_result))
    return _NewtonFit(x_hat, st.x, v_hat, st.grad, st.hess, ok, st.n_steps, result)


def _newton(nll, scale, args, rtol, atol, max_steps=NEWTON_STEPS):
    """:func:`_newton_fit` as ``(x_hat, x, value, grad, hess, ok, n_steps)``."""
    r = _newton_fit(nll, scale, args, rtol, atol, max_steps)
    return r.x_hat, r.x, r.value, r.grad, r.hess, r.ok, r.n_steps


def _bfgs(nll, scale, args, rtol, atol, max_steps):
    """BFGS minimisation with line search: the robust fallback."""
    f = _log_objective(nll)
    sol = optx.minimise(
        f, optx.BFGS(rtol=rtol, atol=atol), jnp.zeros_like(scale), args=(args, scale),
        max_steps=max_steps, throw=False,
    )
    return f, sol.value, sol.result, sol.stats["num_steps"]


@eqx.filter_jit
def _newton_jit(nll, scale, args, rtol, atol):
    r = _newton_fit(nll, scale, args, rtol, atol)
    return _finish_from(r.x, r.value, r.grad, r.hess, scale, r.ok, r.n_steps,
                        x_value=r.x_hat, result=r.result)


_coarse_start_jit = eqx.filter_jit(_coarse_start)


@eqx.filter_jit
def _finish_state_jit(st, sol_result, scale):
    r = _fit_from_state(st, sol_result)
    return _finish_from(r.x, r.value, r.grad, r.hess, scale, r.ok, r.n_steps,
                        x_value=r.x_hat, result=r.result)


def _chunked_newton(nll, scale, args, rtol, atol, max_steps=NEWTON_STEPS,
                    value_atol=0.0) -> FitOutput:
    """:func:`_newton_jit` with the ordinates in fixed-size chunks and the Newton loop on the
    host (:mod:`._chunked`): the same iteration, but only the per-chunk pass depends on the
    record length, and its chunk shapes are a small fixed set, so a recording of a new length
    compiles nothing new once a first one of at least two chunks was fitted."""
    x0 = jnp.zeros_like(scale)
    coarse = coarse_chunks(args)
    if coarse is not None:
        c, _ = host_newton_minimise(nll, scale, coarse, x0, COARSE_TOL, COARSE_TOL,
                                    COARSE_STEPS)
        x0 = _coarse_start_jit(c, x0)
    st, result = host_newton_minimise(nll, scale, ordinate_chunks(args), x0, rtol, atol,
                                      max_steps, value_atol)
    return _finish_state_jit(st, result, scale)


@eqx.filter_jit
def _bfgs_jit(nll, scale, args, rtol, atol, max_steps):
    f, x, result, n = _bfgs(nll, scale, args, rtol, atol, max_steps)
    return _finish(f, x, args, scale, result, n)


def fit_ml(nll: Callable, scale, args, *, rtol=1e-9, atol=1e-9, max_steps=400,
           release=True) -> FitOutput:
    """Minimise ``nll(p, args)`` over positive ``p`` starting at ``p = scale``.

    Newton on the score first (:class:`blurtrap.inference._newton.SafeguardedNewton`, with
    the objective's own value/gradient/Hessian pass when ``nll`` is an
    :class:`~blurtrap.inference._newton.AbstractObjective` that has one); if it fails (or
    lands on a non-minimum) BFGS takes over, compiled only when needed. The Whittle
    objective runs the same iteration in fixed-size ordinate chunks with the loop on the host
    (:func:`_chunked_newton`: a new record length compiles nothing), with the fused pass for
    the core model, and autodiff of each chunk's sum for models with effects
    (:func:`._chunked.args_chunkable` says where; ``_chunked.EFFECTS = False`` compiles one
    loop per padded length for them instead). ``nll`` must be a
    pure, module-level JAX function or objective: calls with arrays of the same shapes reuse
    the compiled code. With a parameter at its bound the others' errors are the
    unconstrained ones (:func:`._bound_errors.release_bound`), unless ``release`` is False
    (a fit whose errors are not used: they stay conditional).
    """
    chunked = chunked_applies(nll, args)
    if chunked:
        out = _chunked_newton(nll, scale, args, rtol, atol)
    else:
        out = _newton_jit(nll, scale, args, rtol, atol)
    if not (bool(out.converged) and bool(out.hessian_pd)):
        out = _bfgs_jit(nll, scale, args, rtol, atol, max_steps)
    if not release:
        return out
    if _chunked.objective_chunkable(nll, args):
        # the natural-parameter Hessian at a bound summed over ordinate chunks
        return release_bound(nll, scale, args, out, parts=ordinate_chunks(args))
    return release_bound(nll, scale, args, out)


def _finish_fd(st, sol_result, scale):
    """FitOutput of the finite-difference Newton fit from its final state and result code."""
    ok = st.done & jnp.all(jnp.isfinite(jnp.where(st.done, st.x - st.step, st.x)))
    return _finish_from(st.x, st.value - 0.5 * jnp.dot(st.grad, st.step), st.grad, st.hess,
                        scale, ok, st.n_steps, x_value=st.x - st.step, result=sol_result)


@eqx.filter_jit
def _fd_newton_jit(nll, scale, args, h, tol, max_iter):
    sol = newton_minimise(fd_hessian_pass(nll, h), scale, args, jnp.zeros_like(scale), tol,
                          tol, max_iter)
    return _finish_fd(sol.state, sol.result, scale)


_finish_fd_jit = eqx.filter_jit(_finish_fd)


def fit_ml_fd_newton(
    nll: Callable, scale, args, *, h=1e-4, tol=1e-9, max_iter=30, max_steps=400
) -> FitOutput:
    """Newton's method whose Hessian is the central difference of the exact JAX gradient.

    For likelihoods whose second-order autodiff graph is expensive to compile (the exact
    time-domain likelihood: forward-over-reverse through scans), every iteration evaluates
    value and gradient at ``x`` and ``x +- h e_i`` in one vmapped call
    (:func:`blurtrap.inference._newton.fd_hessian_pass`). The Hessian error is O(h^2) ~ 1e-8
    relative, far below statistical error. The iteration is the safeguarded Newton of
    :func:`fit_ml`, at most ``max_iter`` steps, with its loop on the host
    (``_chunked.HOST_NEWTON``; one compiled loop otherwise). The exact and irregular-time
    likelihoods' pass runs in fixed-size frame chunks (:mod:`._exact_chunks`: a new record
    length compiles nothing); other objectives' pass is compiled per padded length. The
    covariance is the inverse of that observed Fisher information in natural parameters.
    Falls back to optimistix BFGS if Newton does not converge. With a parameter at its bound
    the others' errors are the unconstrained ones (:func:`._bound_errors.release_bound`, its
    Hessian by differences of the autodiff gradient, in the same frame chunks where they
    apply).
    """
    if _chunked.HOST_NEWTON:  # loop on the host: only the pass depends on the length
        x0 = jnp.zeros_like(scale)
        chunked = exact_chunk_pass(nll, args, h)  # none per length: frames in fixed chunks
        if chunked is not None:
            st, res = host_newton_loop(lambda x: chunked(x, scale), x0, tol, tol, max_iter)
        else:
            st, res = host_newton_minimise(FdObjective(nll, h), scale, [args], x0, tol, tol,
                                           max_iter)
        out = _finish_fd_jit(st, res, scale)
    else:
        out = _fd_newton_jit(nll, scale, args, h, tol, max_iter)
    if not bool(out.converged):
        out = _bfgs_jit(nll, scale, args, tol, tol, max_steps)
    grads = None  # built only when needed: it cuts the frames into chunks again
    if _chunked.HOST_NEWTON and out.at_bound is not None and bool(jnp.any(out.at_bound)):
        grads = exact_chunk_grads(nll, args)
    return release_bound(nll, scale, args, out, fd=True, grads=grads)
