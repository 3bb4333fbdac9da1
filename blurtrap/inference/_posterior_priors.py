"""The priors of :func:`sample_posterior`: per-parameter :class:`Prior` objects with defaults
on wide physical bounds, and checks of user log-prior functions before any fit."""

from __future__ import annotations

import math
from collections.abc import Callable

import jax
import jax.numpy as jnp

from ._posterior_result import _base
from ._priors import DEFAULT_BOUNDS, LogUniform, Prior, Uniform


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
