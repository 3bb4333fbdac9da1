"""Errors of the other parameters when one is at its lower bound 0 (eps^2 -> 0): the
unconstrained Cramer-Rao bound at the estimate, i.e. the inverse of the full observed
information in natural parameters with the bound parameter counted as free (it can move both
ways; conservative near the bound). Conditional on the bound (the others' block of the
information inverted, what the log-space fit gives) they are far too small where the bound is
reached only by chance: in the issue's camera case (benchmarks/RESULTS_instruments.md, section
4) 0.40 % of k against 3.9 %, and 0 of 30 such fits covered the truth.

The log-space Hessian of the fit cannot give the bound parameter's row (``(H - g)/u^2`` with
``u ~ 0``: rounding noise), so the natural-parameter Hessian is evaluated anew at the
estimate, only when a bound is hit (a host-side decision after the fit). Where that full
information is not positive definite the errors stay conditional (``conditional`` True; the
result's note then says they are too small and points to ``result.intervals``).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

#: the full information counts as positive definite when the smallest eigenvalue of its
#: Jacobi-scaled form (unit diagonal) exceeds this (below, its inverse is rounding noise)
_PD_RTOL = 1e-10
#: finite-difference step (natural parameters in units of ``s``) of the ``fd`` Hessian
_FD_STEP = 1e-4
#: a bound parameter's difference Hessian is trusted when its curvature is at least this
#: fraction of its gradient (both in units of ``s``): the gradient difference over the step
#: is then ~1e-10 of the gradient, far above rounding (~1e-16)
_FD_SIGNAL = 1e-6
#: otherwise its unit is widened by this factor and the Hessian evaluated again (at most
#: ``_FD_WIDEN_PASSES`` times): a start value of ~1e-28 m^2 for eps^2 made its step rounding
#: noise, and the curvature scale from it meaningless
_FD_WIDEN = 1e4
_FD_WIDEN_PASSES = 8


def natural_hessian(nll, value, args, s, at_bound, fd=False, with_grad=False):
    """Hessian of ``nll`` with respect to ``u = p / s`` at ``p = value``. By autodiff, or with
    ``fd`` by differences of the exact autodiff gradient (for objectives whose second-order
    graph is expensive to compile): central in the interior, second-order one-sided
    ``(-3 g(u) + 4 g(u + h) - g(u + 2h)) / 2h`` upwards for a parameter at its bound (no
    evaluation below its estimate ~0); error O(h^2) ~ 1e-8 relative. Pure JAX (vmappable).
    With ``with_grad``: ``(Hessian, gradient)``."""
    u = value / s

    def f(v):
        return nll(s * v, args)

    if not fd:
        h = jax.hessian(f)(u)
        return (h, jax.grad(f)(u)) if with_grad else h
    g = jax.vmap(jax.grad(f))(_fd_points(u, at_bound))
    h = _fd_assemble(g, at_bound)
    return (h, g[0]) if with_grad else h


def _fd_points(u, at_bound):
    """``u``, ``u + h e_i`` and ``u - h e_i`` (``u + 2h e_i`` for a parameter at its bound)."""
    n = u.shape[0]
    eye = jnp.eye(n, dtype=u.dtype) * _FD_STEP
    back = jnp.where(at_bound[:, None], -2 * eye, eye)  # at the bound: u - back = u + 2h
    return jnp.concatenate([u[None], u[None] + eye, u[None] - back])


def _fd_assemble(g, at_bound):
    """The difference Hessian from the gradients ``g`` at :func:`_fd_points`."""
    n = g.shape[1]
    g0, gp, gm = g[0], g[1:1 + n], g[1 + n:]
    central = (gp - gm) / (2 * _FD_STEP)
    one_sided = (-3 * g0[None] + 4 * gp - gm) / (2 * _FD_STEP)
    return jnp.where(at_bound[:, None], one_sided, central)


_natural_hessian_jit = eqx.filter_jit(natural_hessian)


def bound_units(scale, value, at_bound):
    """Coordinates ``u = p / s`` for the Hessian at a bound: ``s`` the estimate, or, for a
    parameter at its bound (estimate ~0), the fit's start value (numpy, batched)."""
    scale, value = np.asarray(scale, float), np.asarray(value, float)
    s = np.where(np.asarray(at_bound, bool) | ~(value > 0), scale, value)
    return np.where(s > 0, s, 1.0)


def rescaled_units(s, h, at_bound):
    """``s`` with each bound parameter's unit set to its curvature scale ``1/sqrt(H_jj)``
    (``h`` the Hessian in units of ``s``): a difference step of ``_FD_STEP`` is then a fixed
    fraction of its standard error (the start value of a parameter fitted at its bound can
    be ~1e-7 of it). Numpy, batched."""
    d = np.diagonal(np.asarray(h, float), axis1=-2, axis2=-1)
    good = np.asarray(at_bound, bool) & np.isfinite(d) & (d > 0)
    return np.where(good, s / np.sqrt(np.where(good, d, 1.0)), s)


def cov_from_hessian(h, s, at_bound):
    """``(cov, pd)`` from the full information ``h`` in units of ``s`` (numpy, batched over
    leading axes): its inverse in natural units, every parameter free, with the bound
    parameters' variance NaN and their covariances 0. ``pd``: finite and positive definite
    (Jacobi-scaled smallest eigenvalue above ``_PD_RTOL``); where not, ``cov`` is NaN."""
    h = np.asarray(h, float)
    s = np.asarray(s, float)
    at_bound = np.asarray(at_bound, bool)
    n = h.shape[-1]
    eye = np.eye(n)
    h = 0.5 * (h + np.swapaxes(h, -1, -2))
    d = np.diagonal(h, axis1=-2, axis2=-1)
    ok = np.asarray(np.isfinite(h).all(axis=(-2, -1)) & (np.nan_to_num(d) > 0).all(axis=-1),
                    dtype=bool)
    dinv = 1.0 / np.sqrt(np.where(ok[..., None], d, 1.0))
    hs = np.where(ok[..., None, None], h * dinv[..., :, None] * dinv[..., None, :], eye)
    ev = np.linalg.eigvalsh(hs)
    pd = ok & (ev[..., 0] > _PD_RTOL)
    scl = dinv * s
    cov = np.linalg.inv(np.where(pd[..., None, None], hs, eye))
    cov = cov * scl[..., :, None] * scl[..., None, :]
    free = ~at_bound
    cov = np.where(free[..., :, None] & free[..., None, :], cov,
                   np.where(eye > 0, np.nan, 0.0))
    return np.where(pd[..., None, None], cov, np.nan), pd


def unconstrained_cov(nll, value, args, scale, at_bound, fd=False, parts=None, grads=None):
    """``(cov, pd)``: the inverse of the full observed information in natural parameters at
    ``value``, every parameter free, the bound ones included (they can move both ways;
    conservative near the bound), from :func:`natural_hessian` (with ``fd`` first passes
    set the bound parameters' difference step: widened until their curvature stands above
    rounding, ``_FD_SIGNAL``, then :func:`rescaled_units`); see
    :func:`cov_from_hessian`. On the host; one jitted Hessian per pass. ``parts``: pieces of
    ``args`` whose objectives sum to ``nll`` on ``args`` (e.g. ordinate chunks, so that a new
    record length compiles no Hessian program); their Hessians are summed. ``grads`` (with
    ``fd``): ``grads(xs, s) -> (values, gradients in x)`` of ``nll(s exp(x))`` at points
    ``xs`` (the frame chunks of :func:`._exact_chunks.exact_chunk_grads`: no Hessian program
    per record length); the natural gradient at ``u = exp(x)`` is the one in ``x`` over ``u``."""
    at_bound = np.asarray(at_bound, bool)
    parts = [args] if parts is None else parts

    def hess(s):  # (Hessian, gradient) in units of s
        if fd and grads is not None:
            u = np.asarray(_fd_points(jnp.asarray(value / s), jnp.asarray(at_bound)))
            if np.all(u > 0):
                g = np.asarray(grads(jnp.asarray(np.log(u)), jnp.asarray(s))[1]) / u
                return np.asarray(_fd_assemble(jnp.asarray(g), jnp.asarray(at_bound))), g[0]
        if not fd:  # the gradient only sets the difference step
            return sum(np.asarray(_natural_hessian_jit(nll, jnp.asarray(value), a,
                                                       jnp.asarray(s), jnp.asarray(at_bound)))
                       for a in parts), None
        out = [_natural_hessian_jit(nll, jnp.asarray(value), a, jnp.asarray(s),
                                    jnp.asarray(at_bound), True, True) for a in parts]
        return (sum(np.asarray(o[0]) for o in out), sum(np.asarray(o[1]) for o in out))

    s = bound_units(scale, value, at_bound)
    h, g = hess(s)
    if fd:
        for _ in range(_FD_WIDEN_PASSES):  # a bound parameter's step above rounding first
            # |curvature| above the signal level is real of either sign: a negative one
            # cannot be widened away (it scales with s^2), so the loop stops there too
            d = np.diagonal(h)
            narrow = at_bound & ~(np.abs(d) > _FD_SIGNAL * np.abs(g))
            if not narrow.any():
                break
            s = np.where(narrow, s * _FD_WIDEN, s)
            h, g = hess(s)
        s = rescaled_units(s, h, at_bound)
        h, _ = hess(s)
    return cov_from_hessian(h, s, at_bound)


def release_bound(nll, scale, args, out, fd=False, parts=None, grads=None):
    """``out`` (a ``FitOutput``) with the errors of the parameters not at a bound replaced
    by the unconstrained ones (:func:`unconstrained_cov`) when some parameter is at its bound;
    the conditional covariance kept in ``cov_given_bound``. Where the full information is not positive
    definite ``cov`` stays conditional and ``conditional`` is True. Decided on the host after
    the fit: nothing is computed when no parameter is at a bound. ``parts``, ``grads``: see
    :func:`unconstrained_cov`."""
    if out.at_bound is None or not bool(jnp.any(out.at_bound)) or not bool(out.hessian_pd):
        return out
    cov, pd = unconstrained_cov(nll, np.asarray(out.value), args, np.asarray(scale),
                                np.asarray(out.at_bound), fd, parts, grads)
    new = jnp.asarray(cov) if bool(pd) else out.cov
    return dataclasses.replace(out, cov=new, cov_given_bound=out.cov,
                               conditional=jnp.asarray(not bool(pd)))
