"""The ``aliasing`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

from ._base import AbstractEffect


class Aliasing(AbstractEffect):
    """Folding of the spectrum at the sampling rate. Signature: excess near Nyquist."""

    name: ClassVar[str] = "aliasing"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "excess near Nyquist vs the unfolded model"
