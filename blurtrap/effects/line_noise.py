"""The ``line_noise`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import numpy as np

from ..physics import line_psd
from . import injections
from ._base import AbstractEffect, Param, value_field


class LineNoise(AbstractEffect):
    """A narrow spectral line (mains hum, vibration) at ``frequency`` [Hz] (fixed; diagnose
    finds it as the most significant isolated spike), amplitude ``line_amplitude`` [m].
    Detectable when A^2/2 exceeds ~10 x the PSD at f0 times the frequency resolution.

    Value: ``line_amplitude`` [m] (>= 0); simulated as ``injections.SinusoidDrift`` of that
    amplitude at ``frequency`` with a random phase per trace (power A^2/2, as the model's
    line). ``diagnose`` searches the frequency (``diagnose_test = "line"``): the candidate's
    own ``frequency`` is not used there."""

    name: ClassVar[str] = "line_noise"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("line_amplitude", "m", 1e9, "nm", "line amplitude",
                              bounds=(1e-15, 1e-5),
                              start=lambda c: 0.1 * math.sqrt(c.variance)),)
    signature: ClassVar[str] = "isolated spectral spike"
    frequency: float = eqx.field(static=True, default=50.0)
    width: float = eqx.field(static=True, default=0.0)
    line_amplitude: np.ndarray | None = value_field("m", ">= 0")
    diagnose_test: ClassVar[str] = "line"
    order: ClassVar[float] = 50.0

    def __check_init__(self):
        for nm, v, low in (("frequency", self.frequency, 0.0), ("width", self.width, None)):
            ok = (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                  and (v > low if low is not None else v >= 0))
            if not ok:
                rule = "> 0" if low is not None else ">= 0"
                raise ValueError(f"{nm} must be a finite number {rule} Hz; got {nm} = {v!r}")

    def to_injection(self) -> injections.SinusoidDrift:
        return injections.SinusoidDrift(self._value("line_amplitude"), 1.0 / self.frequency)

    def psd_add(self, f, dt, extras):
        return line_psd(f, self.frequency, extras["line_amplitude"], self.width)
