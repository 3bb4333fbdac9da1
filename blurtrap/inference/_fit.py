"""Generic maximum-likelihood machinery: Newton's method on the score in log parameters
(BFGS fallback), observed-Fisher covariance in natural parameters, result codes.

Every parameter handled here is positive (k, gamma, eps^2, c ...). The optimiser works in
``x = log(p / scale)`` (O(1) unknowns, positivity by construction); the covariance is the
inverse Hessian of the negative log-likelihood with respect to the *natural* parameters
(scaled to O(1) for conditioning), so that a parameter near its lower bound 0 (eps^2) keeps a
finite, meaningful standard error. One *at* the bound (:func:`at_lower_bound`, the single rule
of the package) gets a NaN variance, and the others' errors are conditional on the bound.

Each Newton iteration needs the value, gradient and exact Hessian at one point (a "pass"). By
default they come from JAX autodiff of ``nll``; an objective may provide a faster pass and a
cheap coarse objective for start values through an attribute ``nll.newton_plan(args)``
returning ``(pass_fn, coarse_args)`` or ``None`` (see
:func:`blurtrap.inference._problems.spectral_newton_plan`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

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


def _finish_from(x, value, grad_x, h_x, scale, converged, n_steps, x_value=None):
    """Assemble a FitOutput from the value, gradient and Hessian in log parameters at ``x``:
    observed Fisher information in natural (scaled) parameters u = exp(x),
    d2f/du2 = (H_x - diag(grad_x))/(u u^T). The reported parameters are ``x_value`` (default
    ``x``), e.g. ``x`` plus the final, tiny Newton step.

    Parameters at their lower bound (:func:`at_lower_bound`, e.g. eps^2 -> 0) are held there:
    the others' covariance is the inverse of their own block of the information (errors
    conditional on the bound, as usual for a boundary estimate) and the bound parameter's
    variance is NaN. Its d2f/du2 would be (H - g)/u^2 with H and g both ~u: rounding noise, and
    with it the whole covariance was NaN (measured: weak photodiode-filter refits)."""
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
    )


def _finish(f, x, args, scale, converged, n_steps):
    """FitOutput at ``x`` with value, gradient and Hessian of ``f(x, (args, scale))`` (the
    objective of :func:`_log_objective`) by autodiff."""
    a = (args, scale)
    return _finish_from(x, f(x, a), jax.grad(f)(x, a), jax.hessian(f)(x, a), scale,
                        converged, n_steps)


def _log_objective(nll):
    """``f(x, (args, scale)) = nll(scale * exp(x), args)``. ``scale`` travels in the args, not
    in a closure: optimistix closure-converts the objective, and a closed-over traced value
    stays alive in jax's caches (a tracer leak under JAX_CHECK_TRACER_LEAKS)."""

    def f(x, a):
        args, scale = a
        return nll(scale * jnp.exp(x), args)

    return f


def _autodiff_pass(nll):
    f = _log_objective(nll)

    def pass_fn(x, scale, args):
        a = (args, scale)
        return f(x, a), jax.grad(f)(x, a), jax.hessian(f)(x, a)

    return pass_fn


def _plan(nll, args):
    """(pass_fn, coarse_args or None): the objective's own fast pass if it has one."""
    plan = getattr(nll, "newton_plan", None)
    out = plan(args) if plan is not None else None
    return out if out is not None else (_autodiff_pass(nll), None)


def _newton_direction(g, h):
    """Modified Newton step ``dx`` (the update is ``x - dx``), whether ``h`` is positive
    definite, and whether it has no negative curvature (semi-definite up to the floor: a flat
    direction, not a saddle): eigenvalues of ``h`` below a small floor are replaced by their
    absolute value (at least the floor), so ``dx`` is always a descent direction; where ``h``
    is positive definite, ``dx = h^-1 g`` exactly."""
    w, q = jnp.linalg.eigh(0.5 * (h + h.T))
    floor = 1e-10 * jnp.max(jnp.abs(w)) + 1e-300
    pd = jnp.all(w > floor)
    psd = jnp.all(w > -floor)
    w_mod = jnp.maximum(jnp.abs(w), floor)
    return q @ ((q.T @ g) / w_mod), pd, psd


#: relative rounding allowance of the decrease test (objective values of ~1e6 agree to ~1e-10
#: relative between passes that sum the same terms in different order)
_ROUNDING = 1e-12
#: largest step in log parameters (a factor e^2 ~ 7.4) per Newton iteration
MAX_LOG_STEP = 2.0
_FTOL = 1e-13  # relative Newton decrement that counts as converged (boundary optima)


def _newton_iterate(pass_fn, scale, args, x0, rtol, atol, max_steps, flat_atol=0.0):
    """Safeguarded Newton's method from ``x0``: modified Newton direction (descent even
    where the Hessian is indefinite, :func:`_newton_direction`), steps capped at
    ``MAX_LOG_STEP`` and backtracking (step / 4) until the objective decreases (Armijo). Far
    from the optimum an undamped Newton iteration on these likelihoods can wander into the
    k -> 0 corner (measured on a 100 kHz photodiode record).

    Convergence: with a = max |dx| of the full Newton step at the current point and a_prev
    that of the previous one, the error of ``x - dx`` is estimated as a^2 / (a_prev - a)
    (geometric convergence with the observed ratio a / a_prev; Newton's quadratic
    convergence makes it far smaller) and the iteration stops when that is below
    ``tol = atol + rtol max |x|`` (or when a < tol) with a positive-definite Hessian. The
    step that proves convergence is then also the last one: no further pass is needed, and
    a slowly (linearly) converging iteration is not mistaken for a converged one.

    ``flat_atol`` (nats) is added to the flat-direction tolerance ``_FTOL (1 + |v|)``: the
    profile-likelihood fits (:mod:`blurtrap.inference._profile`) need the objective only to
    ~1e-7, and a parameter driven into its bound there would otherwise creep towards it by
    floor-limited steps for many iterations.

    Returns ``(x, value, grad, hess, dx, n_passes, done, value_at_x0)`` at the last
    accepted point ``x``."""

    def body(st):
        x, v, g, h, dx, lam, k, _, v0, a_prev = st
        first = k < 0
        t = jnp.where(first, x, x - lam * dx)
        vt, gt, ht = pass_fn(t, scale, args)
        accept = first | (jnp.isfinite(vt) & jnp.all(jnp.isfinite(gt))
                          & (vt - v <= -1e-4 * lam * jnp.dot(g, dx) + _ROUNDING * (1.0 + jnp.abs(v))))
        dxt, pd, psd = _newton_direction(gt, ht)
        a = jnp.max(jnp.abs(dxt))
        tol = atol + rtol * jnp.max(jnp.abs(t))
        # a parameter whose optimum is on its boundary (eps^2 -> 0) moves by ~MAX_LOG_STEP in
        # log units for ever while the objective stops changing and its log-space curvature
        # vanishes, so the Hessian becomes only semi-definite (measured: a hydrodynamic
        # record fitted with the standard model; the BFGS fallback then went to k -> 0). There,
        # and only there (a positive-definite, slowly converging iteration must still meet the
        # step rule), a Newton decrement g.dx (twice the predicted decrease) below
        # _FTOL (1 + |v|) counts as converged
        flat = ~pd & psd & (jnp.abs(jnp.dot(gt, dxt)) < _FTOL * (1.0 + jnp.abs(vt)) + flat_atol)
        done_t = (pd & ((a < tol) | ((a < a_prev) & (a * a < tol * (a_prev - a))))) | flat
        pick = lambda new, old: jnp.where(accept, new, old)  # noqa: E731
        return (pick(t, x), pick(vt, v), pick(gt, g), pick(ht, h), pick(dxt, dx),
                jnp.where(accept, jnp.minimum(1.0, MAX_LOG_STEP / jnp.maximum(a, 1e-300)),
                          0.25 * lam),
                k + 1, accept & done_t, jnp.where(first, vt, v0), pick(a, a_prev))

    def cond(st):
        _, _, _, _, dx, lam, k, done, _, _ = st
        return ~done & (k < max_steps) & jnp.all(jnp.isfinite(dx)) & (lam > 1e-12)

    dim = x0.shape[0]
    z = jnp.zeros((), x0.dtype)
    init = (x0, z, jnp.zeros(dim, x0.dtype), jnp.eye(dim, dtype=x0.dtype),
            jnp.zeros(dim, x0.dtype), jnp.ones((), x0.dtype), jnp.asarray(-1),
            jnp.asarray(False), z, z)
    x, v, g, h, dx, _, k, done, v0, _ = jax.lax.while_loop(cond, body, init)
    return x, v, g, h, dx, k, done, v0


def _newton(nll, scale, args, rtol, atol, max_steps=NEWTON_STEPS):
    """Newton fit from the closed-form start ``p = scale`` (``x = 0``), preceded by a fit of
    the objective's coarse version when it has one (start values within ~1e-3 of the optimum
    for a small fraction of the cost of one pass). Reported as converged only if the step
    criterion is met at a finite point that does not raise the objective above its start.

    Returns ``(x_hat, x, value, grad, hess, ok, n_steps)``: ``x_hat = x - dx`` is the estimate
    (the final Newton step applied), ``value`` its objective from the local quadratic model
    (error O(|dx|^3)); gradient and Hessian are exact at the last evaluated point ``x``
    (|x - x_hat| is typically < 1e-6, so the observed information differs from that at
    ``x_hat`` by O(1e-6) relative, far below its own sampling error).
    ``n_steps`` counts the Newton steps on the full objective."""
    pass_fn, coarse = _plan(nll, args)
    x0 = jnp.zeros_like(scale)
    if coarse is not None:
        xc, vc, gc, _, dxc, _, done_c, vc0 = _newton_iterate(
            pass_fn, scale, coarse, x0, COARSE_TOL, COARSE_TOL, COARSE_STEPS)
        xc = xc - dxc
        # accepted only if it converged to a finite point that lowers the coarse objective
        # below its value at the closed-form start (quadratic model at the last step)
        good = (done_c & jnp.all(jnp.isfinite(xc))
                & (vc - 0.5 * jnp.dot(gc, dxc) <= vc0))
        x0 = jnp.where(good, xc, x0)
    x, v, g, h, dx, k, done, v_start = _newton_iterate(pass_fn, scale, args, x0, rtol, atol,
                                                       max_steps)
    x_hat = x - dx
    v_hat = v - 0.5 * jnp.dot(g, dx)
    ok = done & jnp.all(jnp.isfinite(x_hat)) & (v_hat <= v_start)
    return x_hat, x, v_hat, g, h, ok, k


def _bfgs(nll, scale, args, rtol, atol, max_steps):
    """BFGS minimisation with line search: the robust fallback."""
    f = _log_objective(nll)
    sol = optx.minimise(
        f, optx.BFGS(rtol=rtol, atol=atol), jnp.zeros_like(scale), args=(args, scale),
        max_steps=max_steps, throw=False,
    )
    return f, sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]


@eqx.filter_jit
def _newton_jit(nll, scale, args, rtol, atol):
    x_hat, x, v, g, h, ok, n = _newton(nll, scale, args, rtol, atol)
    return _finish_from(x, v, g, h, scale, ok, n, x_value=x_hat)


@eqx.filter_jit
def _bfgs_jit(nll, scale, args, rtol, atol, max_steps):
    f, x, ok, n = _bfgs(nll, scale, args, rtol, atol, max_steps)
    return _finish(f, x, args, scale, ok, n)


def fit_ml(nll: Callable, scale, args, *, rtol=1e-9, atol=1e-9, max_steps=400) -> FitOutput:
    """Minimise ``nll(p, args)`` over positive ``p`` starting at ``p = scale``.

    Newton on the score first; if it fails (or lands on a non-minimum) BFGS takes over,
    compiled only when needed. ``nll`` must be a pure, module-level JAX function: calls with
    arrays of the same shapes reuse the compiled code.
    """
    out = _newton_jit(nll, scale, args, rtol, atol)
    if not (bool(out.converged) and bool(out.hessian_pd)):
        out = _bfgs_jit(nll, scale, args, rtol, atol, max_steps)
    return out


@eqx.filter_jit
def _bfgs_value_only(nll, scale, args, rtol, atol, max_steps):
    f, x, ok, n = _bfgs(nll, scale, args, rtol, atol, max_steps)
    return scale * jnp.exp(x), f(x, (args, scale)), ok


def fit_nll_only(nll: Callable, scale, args, *, rtol=1e-8, atol=1e-8, max_steps=400):
    """Minimum of ``nll`` (BFGS; no Hessian, so compilation is cheap): ``(p, nll, ok)``.
    For screening many candidate models where only the likelihood ratio is needed."""
    p, v, ok = _bfgs_value_only(nll, scale, args, rtol, atol, max_steps)
    return p, float(v), bool(ok)


@eqx.filter_jit
def _value_grad_batch(nll, scale, args, xs):
    f = _log_objective(nll)
    return jax.vmap(jax.value_and_grad(f), in_axes=(0, None))(xs, (args, scale))


def _fd_hessian_points(x, h):
    eye = jnp.eye(x.shape[0]) * h
    return jnp.concatenate([x[None], x[None] + eye, x[None] - eye])


def fit_ml_fd_newton(
    nll: Callable, scale, args, *, h=1e-4, tol=1e-9, max_iter=30, max_steps=400
) -> FitOutput:
    """Newton's method whose Hessian is the central difference of the exact JAX gradient.

    For likelihoods whose second-order autodiff graph is expensive to compile (the exact
    time-domain likelihood: forward-over-reverse through scans), every iteration evaluates
    value and gradient at ``x`` and ``x +- h e_i`` in one vmapped call (a single compiled
    function). The Hessian error is O(h^2) ~ 1e-8 relative, far below statistical error. The
    covariance is the inverse of that observed Fisher information in natural parameters.
    Falls back to optimistix BFGS if a Newton step cannot decrease the objective.
    """
    p_dim = scale.shape[0]
    x = jnp.zeros_like(scale)
    converged = False
    n_it = 0
    for n_it in range(1, max_iter + 1):  # a few Newton iterations, not a loop over frames
        vals, grads = _value_grad_batch(nll, scale, args, _fd_hessian_points(x, h))
        f0, g = vals[0], grads[0]
        hess = (grads[1 : 1 + p_dim] - grads[1 + p_dim :]) / (2 * h)
        hess = 0.5 * (hess + hess.T)
        if not bool(jnp.all(jnp.linalg.eigvalsh(hess) > 0)):
            break
        dx = -jnp.linalg.solve(hess, g)
        dx = dx * jnp.minimum(1.0, 2.0 / jnp.max(jnp.abs(dx)))
        if float(jnp.max(jnp.abs(dx))) < tol:
            converged = True
            break
        t = 1.0
        while t > 1e-4:
            fv, _ = _value_grad_batch(nll, scale, args, (x + t * dx)[None])
            if bool(fv[0] <= f0 + 1e-12 * abs(float(f0))):
                break
            t *= 0.5
        if t <= 1e-4:
            break
        x = x + t * dx
    if not converged:
        return _bfgs_jit(nll, scale, args, tol, tol, max_steps)
    # covariance and bound rule as every other fit (a non-positive-definite information
    # gives NaN errors and success False)
    return _finish_from(x, f0, g, hess, scale, jnp.asarray(True), jnp.asarray(n_it))


def chi2_sf(x, dof) -> float:
    """Survival function P(chi^2_dof > x) for scalars, on the host (no JAX compilation):
    the regularised upper incomplete gamma Q(dof/2, x/2) by its series (x < a + 1) or
    continued fraction (Numerical Recipes 6.2), relative accuracy ~1e-14."""
    a, z = 0.5 * float(dof), 0.5 * float(x)
    if not (a > 0 and math.isfinite(a)) or math.isnan(z):
        return math.nan
    if z <= 0:
        return 1.0
    if math.isinf(z):
        return 0.0
    log_pref = -z + a * math.log(z) - math.lgamma(a)
    if z < a + 1.0:  # P(a, z) by its series; Q = 1 - P is not small here
        term = total = 1.0 / a
        n = 0
        while abs(term) > 1e-17 * abs(total) and n < 100000:
            n += 1
            term *= z / (a + n)
            total += term
        return max(0.0, 1.0 - total * math.exp(log_pref))
    # Q(a, z) by the continued fraction (modified Lentz)
    tiny = 1e-300
    b = z + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    return math.exp(log_pref) * h
