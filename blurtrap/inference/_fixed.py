r"""Fits with some parameters held at given values (``calibrate(..., fixed={...})``), and the
propagation of the given values' uncertainties into the errors of the fitted ones.

Holding a parameter is a reduced objective: ``nll_fixed(q, args) = nll(p(q), args.inner)``
with ``p`` the full vector (the held entries from ``args.full``, the free ones from ``q``).
The reduced objective is a module-level function per original objective (cached), so the
fits compile once per problem shape as usual.

**Uncertainty of a held input.** If a held parameter ``x`` is known only to ``x0 +- s_x`` (a
bead radius +- 3 %, a viscosity, a temperature), the free estimate moves with it:
``q_hat(x) ~ q_hat(x0) + J (x - x0)`` with ``J = -H_qq^{-1} H_qx`` (implicit function
theorem at the optimum; ``H`` the Hessian of the negative log-likelihood in natural
parameters). The reported covariance is ``Cov(q) + J V_x J^T`` with the cross covariance
``J V_x`` and ``Var(x) = V_x``: the usual first-order propagation of an input error (its
bias is second order).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._fit import FitOutput


class FixedArgs(eqx.Module):
    """The arguments of a reduced objective: the original ``inner`` args, the full natural
    parameter vector ``full`` (the held values in place) and the free indices (static)."""

    inner: Any
    full: jax.Array
    free: tuple = eqx.field(static=True)


_REDUCED: dict = {}


def reduced_objective(nll):
    """``nll`` with the held parameters of :class:`FixedArgs` inserted (cached per ``nll``)."""
    if nll not in _REDUCED:
        def f(q, a: FixedArgs):
            p = a.full.at[jnp.asarray(a.free)].set(q)
            return nll(p, a.inner)

        f.__name__ = f"{getattr(nll, '__name__', 'nll')}_fixed"
        _REDUCED[nll] = f
    return _REDUCED[nll]


def parse_fixed(fixed, names) -> dict[str, tuple[float, float]]:
    """``{name: (value, standard error)}`` from ``fixed`` (``{name: value}`` or
    ``{name: (value, se)}``), checked against the model's parameter ``names``."""
    if fixed is None:
        return {}
    if not isinstance(fixed, dict):
        raise ValueError(f"fixed must be a dict {{parameter name: value or (value, se)}} (SI); "
                         f"got {type(fixed).__name__} {fixed!r:.80}")
    out = {}
    for name, spec in fixed.items():
        if names is not None and name not in names:
            raise ValueError(f"fixed names parameter {name!r}, which this model does not have; "
                             f"its parameters are {list(names)}")
        pair = isinstance(spec, (tuple, list)) and len(spec) == 2
        value, se = (spec[0], spec[1]) if pair else (spec, 0.0)
        checks: tuple[tuple[str, Any], ...] = (("value", value), ("standard error", se))
        for what, v in checks:
            if not (isinstance(v, numbers.Real) and not isinstance(v, bool)
                    and math.isfinite(float(v)) and float(v) >= 0):
                raise ValueError(f"fixed[{name!r}]: the {what} must be a finite number >= 0 "
                                 f"(SI); got {v!r}")
        if float(value) == 0 and name != "tracking_var":  # pyright: ignore[reportArgumentType]
            raise ValueError(f"fixed[{name!r}] = 0: only tracking_var may be held at 0; "
                             "the others are positive")
        out[name] = (float(value), float(se))  # pyright: ignore[reportArgumentType]
    if names is not None and len(out) == len(names):
        raise ValueError(f"fixed holds every parameter {list(names)}: nothing left to fit")
    return out


def reduce(names, scale, args, fixed: dict):
    """``(free indices, free scale, FixedArgs)`` for a fit of ``names`` with ``fixed`` held."""
    free = tuple(i for i, n in enumerate(names) if n not in fixed)
    full = np.asarray(scale, dtype=float).copy()
    for i, n in enumerate(names):
        if n in fixed:
            full[i] = fixed[n][0]
    return free, jnp.asarray(np.asarray(scale)[list(free)]), FixedArgs(args, jnp.asarray(full),
                                                                        free)


def expand(out: FitOutput, free, n: int, full) -> FitOutput:
    """The reduced fit's output on the full parameter vector (held entries: their value,
    zero covariance, not at a bound)."""
    idx = jnp.asarray(free)
    value = jnp.asarray(full).at[idx].set(out.value)

    def embed(c):
        return jnp.zeros((n, n), dtype=c.dtype).at[idx[:, None], idx[None, :]].set(c)

    at_bound = out.at_bound if out.at_bound is None else \
        jnp.zeros(n, dtype=bool).at[idx].set(out.at_bound)
    return FitOutput(value=value, cov=embed(out.cov), nll=out.nll, grad_norm=out.grad_norm,
                     n_steps=out.n_steps, success=out.success, converged=out.converged,
                     hessian_pd=out.hessian_pd, at_bound=at_bound, result=out.result,
                     cov_given_bound=(None if out.cov_given_bound is None
                                      else embed(out.cov_given_bound)), conditional=out.conditional)


_GRADS: dict = {}


def _grad_fn(nll):
    if nll not in _GRADS:
        _GRADS[nll] = eqx.filter_jit(jax.vmap(jax.grad(nll), in_axes=(0, None)))
    return _GRADS[nll]


def propagate(nll, args, value, cov, names, fixed: dict, rel_step=1e-4):
    """The covariance with the held inputs' standard errors propagated (module docstring).
    ``value``/``cov``: full vector and covariance with zero rows for the held entries;
    ``args``: the original (full) objective's args. Unchanged when no held input has an
    error."""
    cov = np.array(cov, dtype=float)
    held = [i for i, n in enumerate(names) if n in fixed and fixed[n][1] > 0]
    if not held:
        return cov
    value = np.asarray(value, dtype=float)
    free = [i for i, n in enumerate(names) if n not in fixed]
    pts = []
    steps = []
    for i in held:
        h = rel_step * abs(value[i])
        steps.append(h)
        for s in (h, -h):
            p = value.copy()
            p[i] += s
            pts.append(p)
    grads = np.asarray(_grad_fn(nll)(jnp.asarray(np.stack(pts)), args))
    # H[free, x]: d/dx of the free gradient, by central differences of the exact gradient
    h_fx = np.stack([(grads[2 * j][free] - grads[2 * j + 1][free]) / (2 * steps[j])
                     for j in range(len(held))], axis=-1)
    c_ff = cov[np.ix_(free, free)]
    c_ff = np.where(np.isfinite(c_ff), c_ff, 0.0)  # a parameter at its bound stays there
    jac = -c_ff @ h_fx  # (free, held): J = -H_ff^{-1} H_fx
    v_x = np.diag([fixed[names[i]][1] ** 2 for i in held])
    add = np.zeros_like(cov)
    add[np.ix_(free, free)] = jac @ v_x @ jac.T
    add[np.ix_(free, held)] = jac @ v_x
    add[np.ix_(held, free)] = (jac @ v_x).T
    add[np.ix_(held, held)] = v_x
    return cov + add
