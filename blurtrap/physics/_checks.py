"""Input validation for physics functions.

Concrete inputs (Python scalars, numpy arrays, concrete JAX arrays) are checked eagerly and
raise ``ValueError`` naming the parameter, the offending value and the allowed range. Traced
values (inside ``jit``/``vmap``/``grad``) are checked with ``eqx.error_if``, whose returned
value is always used so the check cannot be removed by dead-code elimination.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


def is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)  # pyright: ignore[reportAttributeAccessIssue]


def as_float(x, name: str | None = None):
    """``jnp.asarray`` that promotes integers/bools to the default float dtype.

    With ``name``, non-numeric or complex input raises naming the parameter."""
    if name is not None and not isinstance(x, jax.Array):
        try:
            kind = np.asarray(x).dtype.kind
        except (TypeError, ValueError):  # ragged or exotic input
            kind = "O"
        if kind not in "biufc":
            raise TypeError(
                f"{name} must be a real number or array of numbers; got {type(x).__name__} "
                f"{x!r:.60}"
            )
    x = jnp.asarray(x)
    if jnp.issubdtype(x.dtype, jnp.complexfloating):
        if name is None:
            raise TypeError(f"expected real values; got dtype {x.dtype}")
        raise TypeError(f"{name} must be real; got complex dtype {x.dtype}")
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    return x


def _fmt(values) -> str:
    arr = np.asarray(values).ravel()
    if arr.size == 1:
        return f"{arr[0]:.6g}"
    shown = ", ".join(f"{v:.6g}" for v in arr[:4])
    return f"[{shown}{', ...' if arr.size > 4 else ''}]"


def _bad(arr, ok):
    return np.asarray(arr)[~np.asarray(ok)]


def check_finite(name: str, x, unit: str = ""):
    x = as_float(x, name)
    if is_concrete(x):
        arr = np.asarray(x)
        ok = np.isfinite(arr)
        if not ok.all():
            raise ValueError(
                f"{name} must be finite{f' [{unit}]' if unit else ''}; got {name} = {_fmt(_bad(arr, ok))}"
            )
        return x
    return eqx.error_if(x, ~jnp.isfinite(x), f"{name} must be finite")


def check_positive(name: str, x, unit: str = "", *, what: str = ""):
    """``x > 0`` and finite."""
    x = as_float(x, name)
    desc = f" ({what})" if what else ""
    u = f" {unit}" if unit else ""
    if is_concrete(x):
        arr = np.asarray(x)
        ok = np.isfinite(arr) & (arr > 0)
        if not ok.all():
            raise ValueError(
                f"{name}{desc} must be finite and > 0{u}; got {name} = {_fmt(_bad(arr, ok))}{u}"
            )
        return x
    return eqx.error_if(x, ~(jnp.isfinite(x) & (x > 0)), f"{name}{desc} must be finite and > 0{u}")


def check_nonnegative(name: str, x, unit: str = "", *, what: str = ""):
    """``x >= 0`` and finite."""
    x = as_float(x, name)
    desc = f" ({what})" if what else ""
    u = f" {unit}" if unit else ""
    if is_concrete(x):
        arr = np.asarray(x)
        ok = np.isfinite(arr) & (arr >= 0)
        if not ok.all():
            raise ValueError(
                f"{name}{desc} must be finite and >= 0{u}; got {name} = {_fmt(_bad(arr, ok))}{u}"
            )
        return x
    return eqx.error_if(x, ~(jnp.isfinite(x) & (x >= 0)), f"{name}{desc} must be finite and >= 0{u}")


def check_exposure_le_interval(exposure, frame_interval):
    """``exposure <= frame_interval`` (a frame cannot integrate longer than it lasts)."""
    if is_concrete(exposure) and is_concrete(frame_interval):
        w, dt = np.broadcast_arrays(np.asarray(exposure), np.asarray(frame_interval))
        ok = w <= dt * (1 + 1e-12)
        if not ok.all():
            raise ValueError(
                f"exposure must be <= frame_interval; got exposure = {_fmt(w[~ok])} s with "
                f"frame_interval = {_fmt(dt[~ok])} s (is the exposure in ms instead of s?)"
            )
        return exposure
    return eqx.error_if(
        exposure, exposure > frame_interval * (1 + 1e-12), "exposure must be <= frame_interval"
    )


def check_integer(name: str, x, *, what: str = ""):
    """Integer-valued (any integer dtype, or a float holding a finite whole number)."""
    if not isinstance(x, jax.Array):
        try:
            kind = np.asarray(x).dtype.kind
        except (TypeError, ValueError):
            kind = "O"
        if kind not in "biuf":
            raise TypeError(f"{name} must be an integer or array of integers; got {x!r:.60}")
    x = jnp.asarray(x)
    if jnp.issubdtype(x.dtype, jnp.integer) or x.dtype == jnp.bool_:
        return x
    desc = f" ({what})" if what else ""
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise ValueError(f"{name}{desc} must be an integer; got dtype {x.dtype}")
    if is_concrete(x):
        arr = np.asarray(x)
        ok = np.isfinite(arr) & (arr == np.round(arr))
        if not ok.all():
            raise ValueError(f"{name}{desc} must be an integer; got {name} = {_fmt(_bad(arr, ok))}")
        return x
    return eqx.error_if(x, ~(jnp.isfinite(x) & (x == jnp.round(x))), f"{name}{desc} must be an integer")


def check_count(name: str, n, minimum: int = 0, *, allowed: str = "") -> int:
    """A static (Python) integer >= minimum (0 or 1), e.g. a number of terms or panels."""
    try:
        ok = not isinstance(n, bool) and int(n) == n and int(n) >= minimum
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        kind = "a non-negative integer" if minimum == 0 else f"an integer >= {minimum}"
        raise ValueError(f"{name} must be {kind}{allowed}; got {name} = {n!r}")
    return int(n)
