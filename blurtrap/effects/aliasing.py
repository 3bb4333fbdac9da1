"""The ``aliasing`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

from ._base import AbstractEffect


class Aliasing(AbstractEffect):
    """Folding of the spectrum at the sampling rate. Signature: excess near Nyquist.

    In ``simulate(..., effects=[...])`` it is accepted and does nothing: the simulator always
    samples every ``frame_interval`` (the detector's property)."""

    name: ClassVar[str] = "aliasing"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "excess near Nyquist vs the unfolded model"
    order: ClassVar[float] = 20.0

    def to_injection(self) -> None:
        return None  # the simulator always samples at the frame interval
