r"""x/y frames of a bead in an anisotropic trap whose principal axes are turned by ``angle``
from the detector's axes.

The trap's force is ``F = -K r`` with the stiffness matrix
``K = R(phi) diag(k1, k2) R(phi)^T``; with an isotropic friction ``gamma`` the motion along
each principal axis is an independent Ornstein-Uhlenbeck process (``tau_i = gamma/k_i``).
Exposure averaging and sampling act linearly and identically on x and y, so they commute
with the rotation: the frames along the principal axes are two independent blurred OU
sequences (each simulated by :func:`simulate` with the same gamma, exposure and frame times),
and the detector's frames are their rotation. Isotropic tracking noise (std ``tracking_std``
on x and on y, independent) is added after the rotation.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import jax.random as jr

from .._constants import DEFAULT_TEMPERATURE
from ._simulate import simulate


def simulate_xy(k1, k2, gamma, exposure, frame_interval, n_frames: int, *, key, angle=0.0,
                temperature=DEFAULT_TEMPERATURE, tracking_std=0.0, n_traces: int = 1,
                method: str = "exact_frames", **kwargs):
    r"""Simulate (x, y) frames of a bead in an anisotropic, rotated harmonic trap.

    **Arguments:**

    - `k1`, `k2`: principal stiffnesses [N/m] along the axis at `angle` from the detector's
      x axis and along the axis perpendicular to it.
    - `gamma`: friction [N s/m], the same along both axes (one bead).
    - `exposure`, `frame_interval` [s], `n_frames`, `temperature` [K]: as in :func:`simulate`.
    - `key`: a JAX PRNG key (keyword-only); the two axes and the tracking noise use
      independent children of it.
    - `angle`: ``phi`` [rad], counter-clockwise from the detector's x axis to principal
      axis 1.
    - `tracking_std`: std [m] of the isotropic tracking noise added to x and to y.
    - `n_traces`, `method` and other keywords (``substeps``, ``exposure_profile``, ...):
      passed to :func:`simulate` for each principal axis (``tracking_std`` is not).

    **Returns:** array of shape ``(n_traces, n_frames, 2)``: ``[..., 0]`` is x and
    ``[..., 1]`` is y [m]. ``blurtrap.data.xy_from_arrays(out[0, :, 0], out[0, :, 1], ...)``
    makes an :class:`XYRecording` of the first trace.

    **Raises:** ``ValueError`` for bad arguments (from :func:`simulate`), or when
    ``tracking_std`` is passed through `kwargs` twice.
    """
    if "injections" in kwargs:
        raise ValueError("simulate_xy: injections are not supported (they would act on each "
                         "principal axis, not on the detector's axes); add them to the output")
    k_axis1, k_axis2, k_noise = jr.split(key, 3)
    common: dict[str, Any] = dict(temperature=temperature, n_traces=n_traces, method=method,
                                  **kwargs)
    u: Any = simulate(k1, gamma, exposure, frame_interval, n_frames, key=k_axis1, **common)
    v: Any = simulate(k2, gamma, exposure, frame_interval, n_frames, key=k_axis2, **common)
    phi = jnp.asarray(angle, dtype=u.dtype)
    c, s = jnp.cos(phi), jnp.sin(phi)
    x = c * u - s * v
    y = s * u + c * v
    out = jnp.stack([x, y], axis=-1)
    std = jnp.asarray(tracking_std, dtype=u.dtype)
    if jnp.ndim(std) != 0:
        raise ValueError(f"simulate_xy: tracking_std must be a scalar [m]; got shape "
                         f"{jnp.shape(std)}")
    if not float(std) >= 0:
        raise ValueError(f"simulate_xy: tracking_std must be >= 0 [m]; got {float(std)!r}")
    noise = jr.normal(k_noise, out.shape, dtype=out.dtype)
    return jax.block_until_ready(out + std * noise)
