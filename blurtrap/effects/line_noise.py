"""The ``line_noise`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx

from ..physics._effects import line_psd
from ._base import AbstractEffect, Param


class LineNoise(AbstractEffect):
    """A narrow spectral line (mains hum, vibration) at ``frequency`` [Hz] (fixed; diagnose
    finds it as the most significant isolated spike), amplitude ``line_amplitude`` [m].
    Detectable when A^2/2 exceeds ~10 x the PSD at f0 times the frequency resolution."""

    name: ClassVar[str] = "line_noise"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("line_amplitude", "m", 1e9, "nm", "line amplitude",
                              bounds=(1e-15, 1e-5),
                              start=lambda c: 0.1 * math.sqrt(c.variance)),)
    signature: ClassVar[str] = "isolated spectral spike"
    frequency: float = eqx.field(static=True, default=50.0)
    width: float = eqx.field(static=True, default=0.0)

    def psd_add(self, f, dt, extras):
        return line_psd(f, self.frequency, extras["line_amplitude"], self.width)
