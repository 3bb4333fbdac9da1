"""Argument checks of :func:`blurtrap.simulate.simulate`: parameters, keys, dtype, and which
injections and options go with which method."""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._injections import (
    AbstractInjection,
    HydrodynamicFriction,
    PhotodiodeFilter,
    TimingJitter,
)
from ._instruments import Sensitivity, StageDrive, check_drives

METHODS = ("exact", "euler", "exact_frames", "spectral")


def _concrete(name, value, unit):
    if isinstance(value, jax.core.Tracer):  # pyright: ignore[reportAttributeAccessIssue]
        raise ValueError(
            f"simulate needs concrete parameter values (it sets loop lengths from them); "
            f"{name} [{unit}] is traced. Call simulate outside jit/vmap/grad; it is vectorised "
            "over parameter grids by broadcasting instead."
        )
    arr = np.asarray(value, dtype=np.float64)
    return arr


def _positive(name, value, unit, what):
    arr = _concrete(name, value, unit)
    bad = ~(np.isfinite(arr) & (arr > 0))
    if bad.any():
        raise ValueError(
            f"{name} ({what}) must be finite and > 0 {unit}; got {name} = "
            f"{arr[bad].ravel()[0]:.6g} {unit}"
        )
    return arr


def _nonnegative(name, value, unit, what):
    arr = _concrete(name, value, unit)
    bad = ~(np.isfinite(arr) & (arr >= 0))
    if bad.any():
        raise ValueError(
            f"{name} ({what}) must be finite and >= 0 {unit}; got {name} = "
            f"{arr[bad].ravel()[0]:.6g} {unit}"
        )
    return arr


def count(name, value, minimum=1):
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {name} = {value!r}")
    return int(value)


def as_keys(key):
    if key is None:
        raise ValueError(
            "key must be a JAX PRNG key, e.g. key=jax.random.key(0); got key=None "
            "(simulate never falls back to a hidden global seed)"
        )
    key = jnp.asarray(key)
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key
    if key.dtype == jnp.uint32 and key.ndim >= 1 and key.shape[-1] == 2:
        return jr.wrap_key_data(key)
    raise ValueError(
        f"key must be a JAX PRNG key (jax.random.key(seed)); got an array of dtype {key.dtype} "
        f"and shape {key.shape}"
    )


def resolve_dtype(dtype):
    if dtype is None:
        dtype = jnp.result_type(float)
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be float32 or float64; got dtype = {dt.name}")
    if dt == np.float64 and not jax.config.jax_enable_x64:  # pyright: ignore[reportAttributeAccessIssue]
        raise ValueError(
            "dtype = float64 needs 64-bit JAX: call blurtrap.enable_x64() first, or pass "
            "dtype=jnp.float32"
        )
    return dt


class Params(NamedTuple):
    """The checked physical parameters (float64 arrays) and their broadcast grid shape."""

    k: np.ndarray
    gamma: np.ndarray
    frame_interval: np.ndarray
    temperature: np.ndarray
    tracking_std: np.ndarray
    exposure: np.ndarray  # the longest window with ExposureWindows
    windows: np.ndarray | None  # ExposureWindows durations [s] (user order), or None
    shape: tuple


def check_params(k, gamma, exposure, frame_interval, temperature, tracking_std,
                 windows) -> Params:
    """Check the physical parameters (`windows`: the durations of an :class:`ExposureWindows`
    passed as `exposure`, else None) and ``exposure <= frame_interval`` on their grid."""
    k_ = _positive("k", k, "N/m", "trap stiffness")
    g_ = _positive("gamma", gamma, "N s/m", "friction coefficient")
    dt_ = _positive("frame_interval", frame_interval, "s", "frame interval dt")
    t_ = _positive("temperature", temperature, "K", "absolute temperature")
    eps_ = _nonnegative("tracking_std", tracking_std, "m", "tracking-error std")
    if windows is not None:
        w_ = np.asarray(windows.max())
    else:
        w_ = _positive("exposure", exposure, "s", "exposure time W")
    shape = np.broadcast_shapes(k_.shape, g_.shape, dt_.shape, t_.shape, eps_.shape, w_.shape)
    bad = np.broadcast_to(w_, shape) > np.broadcast_to(dt_, shape) * (1 + 1e-12)
    if bad.any():
        ww = np.broadcast_to(w_, shape)[bad].ravel()[0]
        dd = np.broadcast_to(dt_, shape)[bad].ravel()[0]
        raise ValueError(
            f"exposure must be <= frame_interval; got exposure = {ww:.6g} s with "
            f"frame_interval = {dd:.6g} s (is the exposure in ms instead of s?)"
        )
    return Params(k_, g_, dt_, t_, eps_, w_, windows, shape)


class Injections(NamedTuple):
    """The injections sorted by where they act."""

    jitter: Any  # TimingJitter with a nonzero std, or None
    photodiode: PhotodiodeFilter | None
    hydro: HydrodynamicFriction | None
    drives: list
    sensitivity: Sensitivity | None
    additive: list  # AbstractInjection, applied after the scan in order


def sort_injections(injections, force, exposure_profile) -> Injections:
    """Sort `injections` by kind; at most one TimingJitter, PhotodiodeFilter and
    HydrodynamicFriction; anything else must be an AbstractInjection."""
    jitters = [inj for inj in injections if isinstance(inj, TimingJitter)]
    diodes = [inj for inj in injections if isinstance(inj, PhotodiodeFilter)]
    hydros = [inj for inj in injections if isinstance(inj, HydrodynamicFriction)]
    drives = [inj for inj in injections if isinstance(inj, StageDrive)]
    sens = [inj for inj in injections if isinstance(inj, Sensitivity)]
    additive = [inj for inj in injections
                if not isinstance(inj, (TimingJitter, PhotodiodeFilter, HydrodynamicFriction,
                                        StageDrive, Sensitivity))]
    for inj in additive:
        if not isinstance(inj, AbstractInjection):
            raise ValueError(
                "injections must be AbstractInjection, TimingJitter, PhotodiodeFilter, "
                f"HydrodynamicFriction, StageDrive or Sensitivity objects; got {inj!r}"
            )
    check_drives(drives, sens, hydros[0] if hydros else None, force, exposure_profile)
    for name, found in (("TimingJitter", jitters), ("PhotodiodeFilter", diodes),
                        ("HydrodynamicFriction", hydros)):
        if len(found) > 1:
            raise ValueError(f"at most one {name} may be given in injections")
    jitter = bool(jitters) and float(np.max(np.asarray(jitters[0].std))) > 0
    return Injections(jitters[0] if jitter else None, diodes[0] if diodes else None,
                      hydros[0] if hydros else None, drives, sens[0] if sens else None, additive)


def check_method_options(method, inj: Injections, windows, substeps, exposure_profile, force):
    """Which injections and options the method supports."""
    special = method == "spectral" or inj.photodiode is not None
    if inj.hydro is not None and method != "spectral":
        raise ValueError(
            "HydrodynamicFriction (frequency-dependent friction) has no Markovian simulation in "
            f"the position alone: use method='spectral'; got method = {method!r}"
        )
    if inj.photodiode is not None and method not in ("exact_frames", "spectral"):
        raise ValueError(
            "PhotodiodeFilter needs method='exact_frames' (exact joint linear system) or "
            f"'spectral'; got method = {method!r}"
        )
    if special:
        what = f"method={method!r}" if method == "spectral" else "PhotodiodeFilter"
        if windows:
            raise ValueError(f"{what} supports a single exposure window, not ExposureWindows")
        if inj.jitter is not None:
            raise ValueError(f"{what} does not support TimingJitter (regular frames only)")
        if method == "spectral" and substeps is not None:
            raise ValueError("substeps is not used by method='spectral' (it has none); got "
                             f"substeps = {substeps!r}")
        if method == "spectral" and exposure_profile is not None:
            raise ValueError("exposure_profile needs a substep method ('exact' or 'euler')")
    if method == "exact_frames":
        if substeps is not None:
            raise ValueError(
                f"substeps is not used by method='exact_frames' (it has none); got "
                f"substeps = {substeps!r}"
            )
        if exposure_profile is not None:
            raise ValueError("exposure_profile needs a substep method ('exact' or 'euler')")
    if force is not None and method != "euler":
        raise ValueError(f"force needs method='euler'; got method = {method!r}")
    if exposure_profile is not None and windows:
        raise ValueError("exposure_profile supports a single exposure window only")
    return special
