"""The ``power_offset`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ._base import AbstractEffect, DataContext, Param, value_field


class PowerOffset(AbstractEffect):
    """``k = c (P - P0)``: the stiffness-vs-power line misses the origin by ``power_offset``
    [W] (a power threshold or a calibration offset of the power meter)."""

    name: ClassVar[str] = "power_offset"
    kind: ClassVar[str] = "relation"
    params: ClassVar = (Param("power_offset", "W", 1e3, "mW", "power offset P0",
                              bounds=(1e-9, 10.0),
                              start=lambda c: 0.05 * min(c.powers) if c.powers else 1e-3),)
    signature: ClassVar[str] = "k-vs-power line misses the origin"
    order: ClassVar[float] = 100.0
    simulate_note: ClassVar[str] = (
        "it relates k across laser powers: simulate one recording per power with "
        "k = c (P - P0)")
    power_offset: np.ndarray | None = value_field("W", ">= 0")

    @classmethod
    def applies(cls, ctx: DataContext) -> bool:
        return ctx.multi_power and ctx.k_mode == "linear_power"
