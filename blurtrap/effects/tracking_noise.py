"""The ``tracking_noise`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

from ._base import AbstractEffect, Param


class TrackingNoise(AbstractEffect):
    """White tracking error of variance eps^2. Signature: flat excess floor in the PSD."""

    name: ClassVar[str] = "tracking_noise"
    kind: ClassVar[str] = "flag"
    params: ClassVar = (Param("tracking_var", "m^2", 1e18, "nm^2", "tracking-error variance eps^2",
                              bounds=(0.0, 1e-10)),)
    signature: ClassVar[str] = "flat excess floor at high frequency"
