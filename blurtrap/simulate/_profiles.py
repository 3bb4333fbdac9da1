r"""Non-rectangular exposure weights and non-harmonic forces for the substep simulator.

An *exposure profile* is a callable ``profile(u) -> weights`` of the fraction ``u = t/W`` in
``[0, 1]`` of the exposure; the simulator multiplies it into the trapezoid quadrature weights of
the substep grid and normalises, so the frame is ``int p(t) x(t) dt / int p(t) dt``. Later
effects (``exposure_kernel``) inject their own profile the same way.

A *force* is ``force(x, params) -> F``: `x` positions [m] (any shape, elementwise), `params` a
pytree passed through ``simulate(..., force_params=...)``, `F` the total conservative force [N].
"""

from __future__ import annotations

import equinox as eqx
import numpy as np


class TrapezoidProfile(eqx.Module):
    """Linear rise over the first ``rise_fraction`` of the exposure and linear fall over the
    last; matches ``blurtrap.physics.TrapezoidKernel(exposure, rise=rise_fraction*exposure)``."""

    rise_fraction: float = eqx.field(static=True)

    def __init__(self, rise_fraction):
        r = float(rise_fraction)
        if not (0.0 <= r <= 0.5):
            raise ValueError(f"rise_fraction must be in [0, 0.5]; got rise_fraction = {r!r}")
        self.rise_fraction = r

    def __call__(self, u):
        u = np.asarray(u, dtype=np.float64)
        if self.rise_fraction == 0.0:
            return np.ones_like(u)
        r = self.rise_fraction
        return np.clip(np.minimum(u / r, (1.0 - u) / r), 0.0, 1.0)


class ExponentialProfile(eqx.Module):
    """Exponentially decaying sensitivity within the exposure,
    ``p(t) = exp(-t / (decay_fraction W))`` (a detector response truncated to the window)."""

    decay_fraction: float = eqx.field(static=True)

    def __init__(self, decay_fraction):
        d = float(decay_fraction)
        if not (np.isfinite(d) and d > 0):
            raise ValueError(f"decay_fraction must be > 0; got decay_fraction = {d!r}")
        self.decay_fraction = d

    def __call__(self, u):
        return np.exp(-np.asarray(u, dtype=np.float64) / self.decay_fraction)


def quartic_force(x, params):
    r"""Force of ``U(x) = k x^2/2 + k4 x^4/4``: ``F = -k x - k4 x^3``.

    `params` = ``(k, k4)`` with `k` [N/m] and `k4` [N/m^3]. Use with ``method="euler"``; the
    stationary density is ``exp(-U/kT)`` (the ``anharmonicity`` effect).
    """
    k, k4 = params
    return -k * x - k4 * x * x * x


def harmonic_force(x, params):
    """``F = -k x`` with ``params = k`` [N/m]."""
    return -params * x
