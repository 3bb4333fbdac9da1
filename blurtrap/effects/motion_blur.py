"""The ``motion_blur`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

from ._base import AbstractEffect


class MotionBlur(AbstractEffect):
    """Rectangular exposure average over W (paper eq. 1). Signature: PSD deficit rising
    toward fs/2; variance falls with W. A single blurred record looks like an unblurred one
    with a *negative* white-noise variance: with eps^2 >= 0 the naive model fails clearly.

    In ``simulate(..., effects=[...])`` it is accepted and does nothing: the simulator's
    frames always average over ``exposure`` (the detector's property)."""

    name: ClassVar[str] = "motion_blur"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "PSD deficit rising toward fs/2"
    order: ClassVar[float] = 10.0

    def to_injection(self) -> None:
        return None  # the simulator always averages over the exposure
