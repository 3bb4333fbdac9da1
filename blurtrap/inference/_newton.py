"""The safeguarded Newton minimiser of the maximum-likelihood fits, as an optimistix solver,
and the objective type that carries an objective's own fast second-order pass.

Every fit works in log parameters ``x = log(p / scale)``. One Newton iteration needs the
value, gradient and exact Hessian of ``nll(scale * exp(x), args)`` at one point (a "pass").
An objective is an :class:`AbstractObjective`: a callable ``nll(p, args)`` (an ``eqx.Module``)
whose :meth:`~AbstractObjective.value_grad_hess` is JAX autodiff by default and may be
overridden by a fused pass (the closed-form Whittle pass of
:class:`blurtrap.inference._problems.SpectralObjective`), and whose
:meth:`~AbstractObjective.coarse_args` may return a cheap, nearly equivalent version of the
data for start values. A plain function is wrapped by :func:`as_objective`.

:class:`SafeguardedNewton` is an ``optx.AbstractMinimiser``. The function it minimises
returns its own gradient and Hessian as auxiliary output, ``fn(x, args) -> (value, (grad,
hess))`` (``has_aux=True``): that is how the fused pass reaches the solver. Use
:func:`newton_minimise` to build that function from a pass and call ``optx.minimise``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

#: relative rounding allowance of the decrease test (objective values of ~1e6 agree to ~1e-10
#: relative between passes that sum the same terms in different order)
_ROUNDING = 1e-12
#: largest step in log parameters (a factor e^2 ~ 7.4) per Newton iteration
MAX_LOG_STEP = 2.0
_FTOL = 1e-13  # relative Newton decrement that counts as converged (boundary optima)
#: Armijo slope and backtracking factor of the step length
_ARMIJO = 1e-4
_BACKTRACK = 0.25
#: the search gives up once the step length falls below this
_MIN_STEP = 1e-12
#: smallest positive curvature (relative to the largest) the Newton step divides by
_CURV_MIN = 1e-30


def not_above(value, reference):
    """``value <= reference`` up to the rounding allowance :data:`_ROUNDING` (relative): the
    one rule of each Newton step's decrease test and of a fit's end value against its start
    (a fit started at its optimum by a coarse fit ends at the same value, which a long
    record's sum gives a few 1e-15 relative higher or lower in another evaluation)."""
    return value <= reference + _ROUNDING * (1.0 + jnp.abs(reference))


# ------------------------------------------------------------------------------------------
# Objectives
# ------------------------------------------------------------------------------------------
class AbstractObjective(eqx.Module):
    """A negative log-likelihood ``nll(p, args)`` over positive parameters ``p``.

    Subclasses implement ``__call__``; they may override :meth:`value_grad_hess` (a faster
    second-order pass) and :meth:`coarse_args` (data for a cheap start-value fit). Both
    decide from static fields and shapes of ``args`` only (they run while tracing)."""

    def __call__(self, p: Array, args: Any) -> Float[Array, ""]:
        raise NotImplementedError

    def value_grad_hess(self, x, scale, args):
        """Value, gradient and Hessian of ``nll(scale * exp(x), args)`` with respect to
        ``x`` (JAX autodiff)."""
        return autodiff_pass(self)(x, scale, args)

    def coarse_args(self, args) -> Any | None:
        """A cheap, nearly equivalent ``args`` for start values, or None (no coarse stage)."""
        del args
        return None


class FunctionObjective(AbstractObjective):
    """A plain function ``nll(p, args)`` as an objective (autodiff pass, no coarse stage)."""

    fn: Callable

    def __call__(self, p, args):
        return self.fn(p, args)


class FdObjective(AbstractObjective):
    """A plain function ``nll(p, args)`` whose pass is :func:`fd_hessian_pass` (step ``h``)."""

    fn: Callable
    h: float = eqx.field(static=True, default=1e-4)

    def __call__(self, p, args):
        return self.fn(p, args)

    def value_grad_hess(self, x, scale, args):
        return fd_hessian_pass(self.fn, self.h)(x, scale, args)


class FixedArgs(eqx.Module):
    """The arguments of a :class:`ReducedObjective`: the full objective's ``inner`` args, the
    full natural parameter vector ``full`` (the held values in place), the free indices, and
    whether every held value is positive (``positive``: the full objective's own pass, in log
    parameters, may run with the held ones at log-offset 0; all static)."""

    inner: Any
    full: jax.Array
    free: tuple = eqx.field(static=True)
    positive: bool = eqx.field(static=True, default=True)


class ReducedObjective(AbstractObjective):
    """The objective ``inner`` with some parameters held (``calibrate(..., fixed=...)``):
    ``nll(q, a) = inner(p, a.inner)``, ``p`` the full vector with the free entries ``q``.

    Its pass is the full objective's own pass (the fused Whittle pass, or the exact
    likelihood's) restricted to the free rows and columns: in log parameters the held entries
    sit at ``x = 0`` with scale their value, so the derivatives in the free ones are exactly
    the full pass's. A held value of 0 (``tracking_var``) has no log parameter: there the pass
    is autodiff of the reduced function. Its coarse start-value data are the full one's."""

    inner: Callable

    def __call__(self, q, a: FixedArgs):
        return self.inner(a.full.at[jnp.asarray(a.free)].set(q), a.inner)

    def value_grad_hess(self, x, scale, a: FixedArgs):
        if not a.positive:
            return super().value_grad_hess(x, scale, a)
        idx = jnp.asarray(a.free)
        xf = jnp.zeros_like(a.full).at[idx].set(x)
        v, g, h = as_objective(self.inner).value_grad_hess(xf, a.full.at[idx].set(scale),
                                                           a.inner)
        return v, g[idx], h[idx[:, None], idx[None, :]]

    def coarse_args(self, a: FixedArgs):
        c = as_objective(self.inner).coarse_args(a.inner)
        return None if c is None else eqx.tree_at(lambda z: z.inner, a, c)


def as_objective(nll) -> AbstractObjective:
    """``nll`` itself if it is an :class:`AbstractObjective`, else wrapped in
    :class:`FunctionObjective`."""
    if isinstance(nll, AbstractObjective):
        return nll
    if not callable(nll):
        raise TypeError(f"nll must be callable as nll(p, args); got nll = {nll!r}")
    return FunctionObjective(nll)


def autodiff_pass(nll):
    """The pass ``(x, scale, args) -> (value, grad, hess)`` of ``nll(scale * exp(x), args)``
    by JAX autodiff (exact Hessian, forward over reverse)."""

    def f(x, a):
        args, scale = a
        return nll(scale * jnp.exp(x), args)

    def pass_fn(x, scale, args):
        a = (args, scale)
        return f(x, a), jax.grad(f)(x, a), jax.hessian(f)(x, a)

    return pass_fn


def fd_hessian_pass(nll, h=1e-4):
    """A pass whose Hessian is the central difference of the exact JAX gradient at
    ``x +- h e_i`` (one vmapped value-and-gradient call on 2n + 1 points): for objectives
    whose second-order autodiff graph is expensive to compile (the exact time-domain
    likelihood: forward-over-reverse through scans). Hessian error O(h^2) ~ 1e-8 relative."""

    def f(x, a):
        args, scale = a
        return nll(scale * jnp.exp(x), args)

    vg = jax.vmap(jax.value_and_grad(f), in_axes=(0, None))

    def pass_fn(x, scale, args):
        n = x.shape[0]
        eye = jnp.eye(n, dtype=x.dtype) * h
        pts = jnp.concatenate([x[None], x[None] + eye, x[None] - eye])
        vals, grads = vg(pts, (args, scale))
        hess = (grads[1:1 + n] - grads[1 + n:]) / (2 * h)
        return vals[0], grads[0], 0.5 * (hess + hess.T)

    return pass_fn


# ------------------------------------------------------------------------------------------
# The minimiser
# ------------------------------------------------------------------------------------------
def newton_direction(g, h):
    """Modified Newton step ``dx`` (the update is ``x - dx``), whether ``h`` is positive
    definite, and whether it has no negative curvature (semi-definite up to the floor: a flat
    direction, not a saddle): eigenvalues of ``h`` below a small floor are replaced by their
    absolute value (at least the floor), so ``dx`` is always a descent direction; where ``h``
    is positive definite, ``dx = h^-1 g`` exactly."""
    w, q = jnp.linalg.eigh(0.5 * (h + h.T))
    scale = jnp.max(jnp.abs(w))
    floor = 1e-10 * scale + 1e-300
    pd = jnp.all(w > floor)
    psd = jnp.all(w > -floor)
    # a small positive curvature is kept (down to _CURV_MIN relative): a parameter running to
    # its bound (v ~ v0 + c e^x in log units, curvature ~ gradient) then moves ~1 log unit per
    # step and its Newton decrement is the decrease still to come; floored at 1e-10 it crept
    # (step ~ 1/n) and took ~40 more steps to converge
    w_mod = jnp.where(w > _CURV_MIN * scale, w, jnp.maximum(jnp.abs(w), floor))
    return q @ ((q.T @ g) / w_mod), pd, psd


class NewtonState(eqx.Module):
    """State at the last accepted point ``x`` (the solver's ``y``)."""

    x: Array  # last accepted point
    value: Float[Array, ""]
    grad: Array
    hess: Array
    step: Array  # full modified-Newton step at x (the update is x - step)
    lam: Float[Array, ""]  # fraction of ``step`` tried next (cap, then backtracking)
    n_steps: Int[Array, ""]  # Newton steps taken (-1 before the first pass)
    done: Bool[Array, ""]
    value_start: Float[Array, ""]  # objective at y0
    size_prev: Float[Array, ""]  # max |step| at the previous accepted point


class SafeguardedNewton(optx.AbstractMinimiser):
    """Newton's method on an objective that returns its own gradient and Hessian:
    ``fn(x, args) -> (value, (grad, hess))``, used with ``has_aux=True``.

    - Descent: the modified Newton direction (:func:`newton_direction`), a descent
      direction even where the Hessian is indefinite.
    - Search: the step is capped at ``MAX_LOG_STEP`` (max norm) and shortened by
      ``_BACKTRACK`` until the objective decreases (Armijo, with a rounding allowance).
      Far from the optimum an undamped Newton iteration on these likelihoods can wander into
      the k -> 0 corner (measured on a 100 kHz photodiode record).
    - Convergence: with a = max |dx| of the full Newton step at the current point and a_prev
      that of the previous one, the error of ``x - dx`` is estimated as a^2 / (a_prev - a)
      (geometric convergence with the observed ratio a / a_prev; Newton's quadratic
      convergence makes it far smaller); the iteration stops when that (or a) is below
      ``tol = atol + rtol max |x|`` with a positive-definite Hessian. The step that proves
      convergence is not taken: the estimate is ``x - dx``, which :meth:`postprocess`
      returns. A parameter whose optimum is on its boundary (eps^2 -> 0) moves by
      ~MAX_LOG_STEP in log units for ever while the objective stops changing and the Hessian
      becomes only semi-definite; there, and only there, a Newton decrement ``g.dx`` below
      ``_FTOL (1 + |v|) + flat_atol`` counts as converged. With ``value_atol`` > 0 (a fit
      whose value is all that is used: diagnose's screening fits), a Newton decrement
      ``g.dx`` (twice the decrease still to come) below it with a positive semi-definite
      Hessian also counts.

    Each step makes exactly one pass (one call of ``fn``). ``optx.minimise``'s ``max_steps``
    counts passes: ``max_steps = n + 1`` allows ``n`` Newton steps. The final state holds the
    last accepted point, its value, gradient, Hessian and Newton step."""

    rtol: float | Array
    atol: float | Array
    norm: Callable = eqx.field(static=True, default=optx.max_norm)
    flat_atol: float | Array = 0.0
    value_atol: float | Array = 0.0

    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> NewtonState:
        n = y.shape[0]
        z = jnp.zeros((), y.dtype)
        return NewtonState(x=y, value=z, grad=jnp.zeros(n, y.dtype),
                           hess=jnp.eye(n, dtype=y.dtype), step=jnp.zeros(n, y.dtype),
                           lam=jnp.ones((), y.dtype), n_steps=jnp.asarray(-1), done=jnp.asarray(False),
                           value_start=z, size_prev=z)

    def _converged(self, t, vt, gt, dxt, pd, psd, size_prev):
        a = jnp.max(jnp.abs(dxt))
        tol = self.atol + self.rtol * jnp.max(jnp.abs(t))
        dec = jnp.abs(jnp.dot(gt, dxt))
        flat = ~pd & psd & (dec < _FTOL * (1.0 + jnp.abs(vt)) + self.flat_atol)
        quick = (a < size_prev) & (a * a < tol * (size_prev - a))
        return (pd & ((a < tol) | quick)) | flat | (psd & (dec < self.value_atol)), a

    def step(self, fn, y, args, options, state: NewtonState, tags):
        t = self.trial(y, state)
        vt, (gt, ht) = fn(t, args)
        new = self.update(y, state, t, vt, gt, ht)
        return new.x, new, (new.grad, new.hess)

    @staticmethod
    def trial(y, state: NewtonState):
        """The point the next step evaluates: ``y`` first, then ``y - lam * step``."""
        return jnp.where(state.n_steps < 0, y, y - state.lam * state.step)

    def update(self, y, state: NewtonState, t, vt, gt, ht) -> NewtonState:
        """The state after evaluating value ``vt``, gradient ``gt`` and Hessian ``ht`` at the
        trial point ``t`` (:meth:`trial`): accepted or backtracked; ``.x`` is the new ``y``."""
        first = state.n_steps < 0
        decrease = not_above(vt + _ARMIJO * state.lam * jnp.dot(state.grad, state.step),
                             state.value)
        accept = first | (jnp.isfinite(vt) & jnp.all(jnp.isfinite(gt)) & decrease)
        dxt, pd, psd = newton_direction(gt, ht)
        done_t, a = self._converged(t, vt, gt, dxt, pd, psd, state.size_prev)
        pick = lambda new, old: jnp.where(accept, new, old)  # noqa: E731
        lam = jnp.where(accept, jnp.minimum(1.0, MAX_LOG_STEP / jnp.maximum(a, 1e-300)),
                        _BACKTRACK * state.lam)
        new = NewtonState(x=pick(t, y), value=pick(vt, state.value), grad=pick(gt, state.grad),
                          hess=pick(ht, state.hess), step=pick(dxt, state.step), lam=lam,
                          n_steps=state.n_steps + 1, done=accept & done_t,
                          value_start=jnp.where(first, vt, state.value_start),
                          size_prev=pick(a, state.size_prev))
        return new

    def terminate(self, fn, y, args, options, state: NewtonState, tags):
        diverged = ~jnp.all(jnp.isfinite(state.step)) | (state.lam <= _MIN_STEP)
        # the loop goes on while the result is successful and ``terminate`` is False
        stuck = diverged & ~state.done
        result = optx.RESULTS.where(stuck, optx.RESULTS.nonlinear_divergence,
                                    optx.RESULTS.successful)
        return state.done | diverged, result

    def postprocess(self, fn, y, aux, args, options, state: NewtonState, tags, result):
        return jnp.where(state.done, y - state.step, y), aux, {}


class _PassFunction(eqx.Module):
    """``fn(x, (scale, args)) -> (value, (grad, hess))`` for :class:`SafeguardedNewton`."""

    pass_fn: Callable

    def __call__(self, x, sa):
        scale, args = sa
        v, g, h = self.pass_fn(x, scale, args)
        return v, (g, h)


def newton_minimise(pass_fn, scale, args, x0, rtol, atol, max_steps, flat_atol=0.0):
    """Minimise with :class:`SafeguardedNewton` from ``x0`` through ``optx.minimise``
    (``throw=False``): at most ``max_steps`` Newton steps. ``pass_fn(x, scale, args)``
    returns value, gradient and Hessian in ``x``. Returns the ``optx.Solution``: ``value`` is
    the estimate (the final Newton step applied when converged), ``state`` a
    :class:`NewtonState`."""
    solver = SafeguardedNewton(rtol=rtol, atol=atol, flat_atol=flat_atol)
    return optx.minimise(_PassFunction(pass_fn), solver, x0, args=(scale, args), has_aux=True,
                         max_steps=max_steps + 1, throw=False)


def newton_iterate(pass_fn, scale, args, x0, rtol, atol, max_steps, flat_atol=0.0):
    """:func:`newton_minimise` as a tuple ``(x, value, grad, hess, dx, n_steps, done,
    value_at_x0)`` at the last accepted point ``x`` (the estimate is ``x - dx``)."""
    st = newton_minimise(pass_fn, scale, args, x0, rtol, atol, max_steps, flat_atol).state
    return st.x, st.value, st.grad, st.hess, st.step, st.n_steps, st.done, st.value_start
