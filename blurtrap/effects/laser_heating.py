"""The ``laser_heating`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ._base import AbstractEffect, DataContext, Param, value_field


class LaserHeating(AbstractEffect):
    """Heating ``T = T0 + b P`` at the focus (``heating`` b [K/W]); gamma follows the water
    viscosity eta(T) and kT rises. Signature: curvature in variance-vs-power fits and gamma
    falling with power. Typical b ~ 10-20 K/W at 1064 nm: detectable across >= 4 powers up to
    ~1 W."""

    name: ClassVar[str] = "laser_heating"
    kind: ClassVar[str] = "relation"
    params: ClassVar = (Param("heating", "K/W", 1.0, "K/W", "heating coefficient b",
                              bounds=(1e-3, 1e4), start=lambda c: 10.0),)
    signature: ClassVar[str] = "gamma falls with laser power"
    order: ClassVar[float] = 110.0
    simulate_note: ClassVar[str] = (
        "it relates recordings at several laser powers: simulate one per power with "
        "temperature T0 + b P and gamma scaled by water_viscosity(T)/water_viscosity(T0)")
    heating: np.ndarray | None = value_field("K/W", ">= 0")

    @classmethod
    def applies(cls, ctx: DataContext) -> bool:
        return ctx.multi_power and ctx.k_mode == "linear_power"
