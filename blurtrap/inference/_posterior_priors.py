"""The priors of :func:`sample_posterior`: per-parameter :class:`Prior` objects with defaults
on wide physical bounds, and checks of user log-prior functions before any fit."""

from __future__ import annotations

import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ._posterior_result import _base
from ._priors import DEFAULT_BOUNDS, LogNormal, LogUniform, Normal, Prior, Uniform


def _resolve_priors(layout, priors) -> tuple[tuple, tuple]:
    """Per-parameter Prior objects (defaults: log-uniform bounds) and user log-prior fns.

    ``priors`` maps parameter names (``layout.names``; the base name ``k`` applies to every
    ``k[...]``) to :class:`Prior` objects; callables under the key ``None`` or in a list under
    ``"log_prior"``, or ``priors`` given as a callable / sequence of callables, are
    user log-prior functions ``f(params: dict) -> scalar`` (JAX-traceable, natural SI values
    keyed by ``layout.names``; a density in the natural parameters)."""
    per: dict[str, Prior] = {}
    fns: list[Callable] = []
    if priors is None:
        priors = {}
    if callable(priors) and not isinstance(priors, Prior):
        fns.append(priors)
        priors = {}
    elif isinstance(priors, (list, tuple)):
        for f in priors:
            if not callable(f):
                raise TypeError(f"priors: expected callables in a sequence; got {f!r}")
            fns.append(f)
        priors = {}
    valid = set(layout.names) | {_base(n) for n in layout.names}
    for key, val in dict(priors).items():  # pyright: ignore[reportCallIssue, reportArgumentType]
        if key is None or key == "log_prior":
            vals = val if isinstance(val, (list, tuple)) else [val]
            for f in vals:
                if not callable(f):
                    raise TypeError(f"priors[{key!r}] must be callable; got {f!r}")
                fns.append(f)
            continue
        if key not in valid:
            raise ValueError(
                f"priors: unknown parameter {key!r}; the parameters of this model are "
                f"{list(layout.names)}"
            )
        if not isinstance(val, Prior):
            raise TypeError(
                f"priors[{key!r}] must be a blurtrap Prior (LogUniform, Normal, LogNormal, "
                f"InverseGamma, ...); got {type(val).__name__}"
            )
        per[key] = val  # pyright: ignore[reportArgumentType]  # key: a str in layout.names
    out = []
    for name in layout.names:
        base = _base(name)
        if name in per:
            out.append(per[name])
        elif base in per:
            out.append(per[base])
        elif base == "tracking_var":
            out.append(Uniform(*DEFAULT_BOUNDS[base]))
        elif base in DEFAULT_BOUNDS:
            out.append(LogUniform(*DEFAULT_BOUNDS[base]))
        else:  # pragma: no cover - every effect parameter has default bounds
            raise ValueError(f"priors: no default prior for parameter {name!r}; give one, "
                             f"e.g. priors={{{name!r}: LogUniform(low, high)}}")
    return tuple(out), tuple(fns)


def _prior_range(prior):
    """Where most of a prior's mass lies, ``(low, high)`` in its parameter's units, or None."""
    def f(v):
        return float(np.max(np.asarray(v, dtype=float)))

    if isinstance(prior, (LogUniform, Uniform)):
        return f(prior.low), f(prior.high)
    if isinstance(prior, Normal):
        return f(prior.mean) - 3 * f(prior.sd), f(prior.mean) + 3 * f(prior.sd)
    if isinstance(prior, LogNormal):
        return f(prior.median) * math.exp(-3 * f(prior.sigma)), f(prior.median) * math.exp(
            3 * f(prior.sigma))
    return None


def check_prior_units(names, priors, volts=False) -> None:
    """A prior of k, c or gamma that puts (almost) no mass in the physically plausible range
    of its quantity (``Param.bounds``, the default prior's support) is a ValueError naming
    the likely unit slip (lab units instead of SI): the posterior of such a prior is the
    flat-prior one, silently (an independent pass: Normal(0.0268, 5e-4) for gamma in
    pN s/um, a 2 % prior, changed nothing). Not for positions in volts."""
    from ..effects import QUANTITIES, UNIT_SLIP_QUANTITIES

    for name, prior in zip(names, priors):
        base = _base(name)
        q = QUANTITIES.get(base)
        rng = _prior_range(prior)
        if volts or base not in UNIT_SLIP_QUANTITIES or q is None or q.bounds is None \
                or rng is None:
            continue
        lo, hi = q.bounds
        if rng[1] >= lo and rng[0] <= hi:
            continue
        raise ValueError(
            f"priors[{base!r}] = {type(prior).__name__}(...) puts its mass at {rng[0]:.3g}..{rng[1]:.3g} "
            f"{q.unit}, outside the plausible range of the {q.description}, {q.range_text()}: "
            f"this looks like a unit slip; priors take SI ({q.unit}; 1 {q.lab_unit} = "
            f"{1 / q.lab_factor:g} {q.unit})")


#: a prior whose mass lies this many combined standard deviations from the data's maximum-
#: likelihood value conflicts with the data (a note names it)
CONFLICT_Z = 5.0


def prior_conflict_notes(names, priors, values, errors) -> list[str]:
    """Notes for priors that conflict with the data's maximum-likelihood estimate (more than
    :data:`CONFLICT_Z` combined SDs apart; on log scale for LogNormal; outside a uniform's
    bounds by more than CONFLICT_Z SE): where they conflict, an informative prior drives the
    posterior, and a value in another unit (pN/nm given as N/m) is the likeliest cause."""
    out = []
    for name, prior, v, se in zip(names, priors, values, errors):
        v, se = float(v), float(se)
        se = se if math.isfinite(se) else 0.0
        if isinstance(prior, Normal):
            m, sd = float(np.max(prior.mean)), float(np.max(prior.sd))
            z = abs(v - m) / math.hypot(sd, se)
            where = f"Normal({m:.4g}, {sd:.2g})"
        elif isinstance(prior, LogNormal) and v > 0:
            m, sg = float(np.max(prior.median)), float(np.max(prior.sigma))
            z = abs(math.log(v / m)) / math.hypot(sg, se / v)
            where = f"LogNormal(median {m:.4g}, sigma {sg:.2g})"
        elif isinstance(prior, (Uniform, LogUniform)):
            lo, hi = float(np.max(prior.low)), float(np.max(prior.high))
            z = max(lo - v, v - hi, 0.0) / se if se > 0 else 0.0
            where = f"{type(prior).__name__}({lo:.4g}, {hi:.4g})"
        else:
            continue
        if z > CONFLICT_Z:
            out.append(f"prior on {name}, {where}, conflicts with the data: their "
                       f"maximum-likelihood value is {v:.4g} +- {se:.2g} (SI), {z:.3g} combined "
                       "SD away, so the posterior follows the prior there; check its value and "
                       "unit (priors take SI: 1 pN/nm = 1e-3 N/m, 1 pN s/um = 1e-6 N s/m)")
    return out


_TRACER_ERRORS = (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
                  jax.errors.TracerBoolConversionError, jax.errors.TracerIntegerConversionError)


def _check_user_priors(fns, names) -> None:
    """Trace each user log-prior once on abstract scalars (no compilation, no data): a
    function that is not JAX-traceable, reads an unknown name or does not return a scalar
    fails here with a clear message, before any fitting."""
    params = {n: jax.ShapeDtypeStruct((), jnp.float64) for n in names}
    for fn in fns:
        what = getattr(fn, "__name__", type(fn).__name__)
        try:
            out = jax.eval_shape(fn, params)
        except _TRACER_ERRORS as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise TypeError(
                f"priors: the user log-prior {what!r} is not JAX-traceable: it is called with "
                "JAX tracers (params maps each of "
                f"{list(names)} to a traced scalar) and must use jax.numpy only - no float(), "
                "math.*, np.* or Python if/else on parameter values (write jnp.log(p['k']), "
                f"jnp.where(cond, a, b)). JAX said: {first}"
            ) from exc
        except KeyError as exc:
            raise ValueError(f"priors: the user log-prior {what!r} reads params[{exc}], but "
                             f"the parameters of this model are {list(names)}") from exc
        shape = getattr(out, "shape", None)
        if shape is None or math.prod(shape) != 1:
            raise TypeError(f"priors: the user log-prior {what!r} must return one scalar "
                            f"(a log density); it returned shape {shape}")
