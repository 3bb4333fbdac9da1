"""The ``tracking_noise`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import injections
from ._base import AbstractEffect, Param, value_field


class TrackingNoise(AbstractEffect):
    """White tracking error of variance eps^2. Signature: flat excess floor in the PSD.

    Value: ``tracking_var`` [m^2] (>= 0); simulated as ``injections.TrackingNoise`` of
    standard deviation ``sqrt(tracking_var)``."""

    name: ClassVar[str] = "tracking_noise"
    kind: ClassVar[str] = "flag"
    params: ClassVar = (Param("tracking_var", "m^2", 1e18, "nm^2", "tracking-error variance eps^2",
                              bounds=(0.0, 1e-10)),)
    signature: ClassVar[str] = "flat excess floor at high frequency"
    order: ClassVar[float] = 30.0

    tracking_var: np.ndarray | None = value_field("m^2", ">= 0")

    def to_injection(self) -> injections.TrackingNoise:
        return injections.TrackingNoise(np.sqrt(self._value("tracking_var")))
