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

from ..effects.injections import TrapezoidProfile as TrapezoidProfile


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
