r"""Composable injections: additive effects applied to simulated frames, and timing jitter.

An injection is a small ``eqx.Module`` with array parameters (SI units). Additive injections
implement :meth:`AbstractInjection.apply`, called once after the frame scan, per grid point,
with the frames in metres; they never touch the Brownian-dynamics loop. :class:`TimingJitter`
is the one effect that must act inside the loop (it moves the frame start times); it is passed
in the same ``injections=`` tuple and picked out by :func:`blurtrap.simulate.simulate`.

Canonical effect names (DESIGN section 3): ``tracking_noise`` (:class:`TrackingNoise`),
``drift`` (:class:`RandomWalkDrift`, :class:`SinusoidDrift`), ``timing_jitter``
(:class:`TimingJitter`).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, Float


def _nonneg(name, value, unit):
    arr = np.asarray(value, dtype=np.float64)
    if not (np.all(np.isfinite(arr)) and np.all(arr >= 0)):
        raise ValueError(f"{name} must be finite and >= 0 {unit}; got {name} = {arr!r} {unit}")
    return jnp.asarray(value)


def _pos(name, value, unit):
    arr = np.asarray(value, dtype=np.float64)
    if not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
        raise ValueError(f"{name} must be finite and > 0 {unit}; got {name} = {arr!r} {unit}")
    return jnp.asarray(value)


class AbstractInjection(eqx.Module):
    """An additive effect applied after the scan.

    ``apply(x, times, key)``: `x` frames [m] of shape ``(..., n_traces, n_frames)`` (one grid
    point; a leading windows axis may be present), `times` frame start times [s] broadcastable
    to `x`, `key` a PRNG key owned by this injection. Returns the new frames (same shape/dtype).
    """

    name: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def apply(self, x, times, key):
        ...


class TrackingNoise(AbstractInjection):
    """White tracking noise (``tracking_noise``): i.i.d. ``N(0, std^2)`` added to every frame.

    - `std`: tracking-error standard deviation eps [m], >= 0.
    """

    std: Float[Array, ""]
    name = "tracking_noise"

    def __init__(self, std):
        self.std = _nonneg("std", std, "m")

    def apply(self, x, times, key):
        return x + self.std.astype(x.dtype) * jr.normal(key, x.shape, x.dtype)


class RandomWalkDrift(AbstractInjection):
    """Random-walk drift (``drift``): ``d(t)`` with ``var(d(t) - d(s)) = 2 D |t - s|``, d(0) = 0,
    sampled at the frame start times; each trace (and each window axis entry shares the
    trace's drift) gets its own walk.

    - `diffusion`: drift diffusion coefficient D_drift [m^2/s], >= 0.
    """

    diffusion: Float[Array, ""]
    name = "drift"

    def __init__(self, diffusion):
        self.diffusion = _nonneg("diffusion", diffusion, "m^2/s")

    def apply(self, x, times, key):
        t = jnp.broadcast_to(times, x.shape[-2:]).astype(x.dtype)
        dt = jnp.diff(t, axis=-1, prepend=t[..., :1])
        steps = jnp.sqrt(2.0 * self.diffusion.astype(x.dtype) * jnp.maximum(dt, 0.0))
        walk = jnp.cumsum(steps * jr.normal(key, t.shape, x.dtype), axis=-1)
        return x + walk


class SinusoidDrift(AbstractInjection):
    """Slow sinusoidal drift (``drift``): ``amplitude * sin(2 pi t / period + phase)``.

    - `amplitude` [m] (>= 0); `period` [s] (> 0);
    - `phase` [rad] or ``None`` (default): a uniform random phase per trace.
    """

    amplitude: Float[Array, ""]
    period: Float[Array, ""]
    phase: Float[Array, ""] | None

    name = "drift"

    def __init__(self, amplitude, period, phase=None):
        self.amplitude = _nonneg("amplitude", amplitude, "m")
        self.period = _pos("period", period, "s")
        self.phase = None if phase is None else jnp.asarray(phase)

    def apply(self, x, times, key):
        n_traces = x.shape[-2]
        if self.phase is None:
            phase = jr.uniform(key, (n_traces, 1), x.dtype, 0.0, 2.0 * jnp.pi)
        else:
            phase = self.phase.astype(x.dtype)
        t = jnp.asarray(times).astype(x.dtype)
        w = (2.0 * jnp.pi / self.period).astype(x.dtype)
        return x + self.amplitude.astype(x.dtype) * jnp.sin(w * t + phase)


class TimingJitter(eqx.Module):
    """Irregular frame times (``timing_jitter``): frame n starts at ``n dt + delta_n``,
    ``delta_n ~ N(0, std^2)`` i.i.d. per frame and trace; the exposure keeps its length and the
    dead time between frames absorbs the jitter (``dt - W + delta_{n+1} - delta_n``, clipped at 0).

    Acts inside the frame scan (the Brownian motion is simulated at the jittered times);
    ``simulate(..., return_times=True)`` returns the actual start times.

    - `std`: timing-jitter standard deviation [s], >= 0; should be well below ``dt - W``.
    """

    std: Float[Array, ""]
    name = "timing_jitter"

    def __init__(self, std):
        self.std = _nonneg("std", std, "s")
