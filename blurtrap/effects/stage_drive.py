"""The ``stage_drive`` effect (DESIGN section 3): a known input, its values and hooks."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import numpy as np

from . import injections
from ._base import AbstractEffect, value_field


class StageDrive(AbstractEffect):
    """Sinusoidal stage drive at a known ``frequency`` [Hz] (active calibration;
    Tolic-Norrelykke et al., Rev. Sci. Instrum. 77, 103101 (2006)): a known spike whose height
    fixes gamma and the volts-to-metres factor without assuming Stokes friction.

    It is a known input, not a piece of the noise model: ``calibrate`` fits it from the
    recording's ``drive`` setting (``{"frequency_Hz": f}`` and the recorded stage column;
    ``blurtrap.inference._active``), so a ``TrapModel`` does not take it and ``diagnose`` never
    proposes it (``diagnose_test = ""``).

    Value: ``amplitude`` [m] (>= 0, scalar to simulate); configuration ``frequency`` [Hz],
    ``phase`` [rad] and ``mode`` (``"fluid"``: the stage moves the fluid, the bead responds
    through ``H(f) = i f/(f_c + i f)``; ``"additive"``: the trace holds the stage motion).
    Simulated as ``injections.StageDrive`` (its exact response, blurred over the exposure)."""

    name: ClassVar[str] = "stage_drive"
    kind: ClassVar[str] = "input"
    signature: ClassVar[str] = "a spike at the known drive frequency"
    diagnose_test: ClassVar[str] = ""
    order: ClassVar[float] = 140.0

    amplitude: np.ndarray | None = value_field("m", ">= 0")
    frequency: float = eqx.field(static=True, default=32.0)
    phase: float = eqx.field(static=True, default=0.0)
    mode: str = eqx.field(static=True, default="fluid")

    def __check_init__(self):
        f = self.frequency
        if not (isinstance(f, (int, float)) and not isinstance(f, bool) and math.isfinite(f)
                and f > 0):
            raise ValueError(f"frequency must be a finite number > 0 Hz; got frequency = {f!r}")
        if self.mode not in ("fluid", "additive"):
            raise ValueError(f"mode must be 'fluid' or 'additive'; got mode = {self.mode!r}")

    def to_injection(self) -> injections.StageDrive:
        return injections.StageDrive(self._value("amplitude", scalar=True), self.frequency,
                                     self.phase, self.mode)
