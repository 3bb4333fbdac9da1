"""Precision policy.

blurtrap guarantees float64 for inference in two ways:

1. ``blurtrap.enable_x64()`` switches JAX to 64-bit globally. The CLI, the notebooks and the
   test-suite call it first.
2. Every public estimator (``calibrate``, the likelihoods, ``sample_posterior``, ``diagnose``)
   runs inside :func:`float64_scope`, i.e. ``jax.enable_x64(True)`` (``jax.experimental.enable_x64``
   on jax < 0.8, see :func:`x64_context`), so it computes in float64 even when the user never
   called ``enable_x64``. If the *data* arrive as float32 the precision is already lost, so
   :func:`warn_if_float32` warns.

The physics functions follow the dtype of their inputs and are written to stay accurate in
float32 as well (series branches, ``expm1``, no catastrophic cancellation).
"""

from __future__ import annotations

import functools
import warnings

import jax
import numpy as np


def enable_x64(enable: bool = True) -> None:
    """Switch JAX to float64 (``jax_enable_x64``) for the whole process."""
    jax.config.update("jax_enable_x64", bool(enable))


def x64_enabled() -> bool:
    return bool(jax.config.jax_enable_x64)  # pyright: ignore[reportAttributeAccessIssue]  # set at runtime


def x64_context(enable: bool = True):
    """Context manager: 64-bit JAX types on (or off) inside the ``with`` block only.

    ``jax.enable_x64`` (jax >= 0.8), else ``jax.experimental.enable_x64`` (older jax, which
    has no ``jax.enable_x64``); both are thread-local and restore the previous setting."""
    ctx = getattr(jax, "enable_x64", None)
    if ctx is None:  # older jax: the context manager lives in jax.experimental
        from jax.experimental import enable_x64 as ctx  # pyright: ignore[reportAttributeAccessIssue]
    return ctx(bool(enable))


def float64_scope(fn):
    """Decorator: run ``fn`` with 64-bit JAX types enabled."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with x64_context(True):
            return fn(*args, **kwargs)

    return wrapper


class Float32DataWarning(UserWarning):
    """Data reached an estimator in float32; estimates are limited to float32 precision."""


def warn_if_float32(name: str, x) -> None:
    dtype = getattr(x, "dtype", None)
    if dtype is not None and np.dtype(dtype) in (np.dtype(np.float32), np.dtype(np.float16)):
        warnings.warn(
            f"{name} has dtype {np.dtype(dtype).name}; blurtrap computes in float64 but the "
            "input has already lost precision. Pass float64 arrays.",
            Float32DataWarning,
            stacklevel=3,
        )


def enable_compilation_cache(path: str | None = None) -> str:
    """Keep compiled XLA programs on disk (``jax_compilation_cache_dir``) so that a second
    run of the same calibration skips compilation. Default folder:
    ``$BLURTRAP_CACHE_DIR`` or ``~/.cache/blurtrap/jax``. Returns the folder used."""
    import os

    path = path or os.environ.get("BLURTRAP_CACHE_DIR") or os.path.join(
        os.path.expanduser("~"), ".cache", "blurtrap", "jax"
    )
    os.makedirs(path, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    return path


#: XLA:CPU flag that ``faster_compilation`` adds: the classic loop emitters instead of the
#: newer MLIR fusion emitters. Measured on blurtrap's programs (benchmarks/RESULTS.md,
#: "Compilation flags"): first call (compilation + one run) 1.2-1.7x faster, warm run times
#: within 10 %; the Brownian-dynamics scan pins XLA's default emitters per program
#: (``simulate._core``), where the flag made it 35 % slower warm.
FAST_COMPILE_FLAG = "--xla_cpu_use_fusion_emitters=false"
#: jaxlib releases known to accept the flag (checked in their binaries: 0.5.1 lacks it,
#: 0.5.3 to 0.10 have it). XLA aborts the process on an unknown flag, so releases outside
#: this range are left alone.
_FAST_COMPILE_JAXLIB = ((0, 5, 3), (0, 11, 0))
#: set (to anything but "" or "0") to keep XLA's default flags in the CLI and the tests
NO_FAST_COMPILE_ENV = "BLURTRAP_DEFAULT_XLA"


def _jaxlib_release() -> tuple[int, ...]:
    """The installed jaxlib's (major, minor, micro); (0,) where it cannot be read."""
    import re
    from importlib.metadata import PackageNotFoundError, version

    try:
        return tuple(int(p) for p in re.findall(r"\d+", version("jaxlib"))[:3]) or (0,)
    except PackageNotFoundError:
        return (0,)


def fusion_emitters_option_known() -> bool:
    """Whether this jaxlib knows ``xla_cpu_use_fusion_emitters`` (as a flag or as a per-jit
    compiler option)."""
    low, high = _FAST_COMPILE_JAXLIB
    return low <= _jaxlib_release() < high


def _flag_value(flags: str) -> str | None:
    """The value ``$XLA_FLAGS`` gives ``xla_cpu_use_fusion_emitters`` (the last one wins, as
    in XLA), lower case; None where it does not name it."""
    value = None
    for token in flags.split():
        name, _, val = token.lstrip("-").partition("=")
        if name == "xla_cpu_use_fusion_emitters":
            value = (val or "true").lower()
    return value


def faster_compilation() -> bool:
    """Add :data:`FAST_COMPILE_FLAG` to ``$XLA_FLAGS`` for this process (and the processes
    it starts) when that is safe: the installed jaxlib accepts the flag, JAX has not yet
    started its backends (the flags are read once, then), ``$XLA_FLAGS`` does not set it
    already and ``$BLURTRAP_DEFAULT_XLA`` is not set. The CLI and the test-suite call it
    before their first computation; ``import blurtrap`` does not (XLA's flags are
    process-wide). Results are unchanged to rounding. Returns whether the flag is in effect
    for this process."""
    import os

    flags = os.environ.get("XLA_FLAGS", "")
    named = _flag_value(flags)
    if named is not None:  # the user's own setting wins
        return named in ("false", "0")
    if os.environ.get(NO_FAST_COMPILE_ENV, "") not in ("", "0"):
        return False
    if not fusion_emitters_option_known():
        return False
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - a jax without this private module
        return False
    started = getattr(xla_bridge, "backends_are_initialized", None)
    if started is None or started():
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FAST_COMPILE_FLAG}".strip()
    return True
