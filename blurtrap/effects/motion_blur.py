"""The ``motion_blur`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

from ._base import AbstractEffect


class MotionBlur(AbstractEffect):
    """Rectangular exposure average over W (paper eq. 1). Signature: PSD deficit rising
    toward fs/2; variance falls with W. A single blurred record looks like an unblurred one
    with a *negative* white-noise variance: with eps^2 >= 0 the naive model fails clearly."""

    name: ClassVar[str] = "motion_blur"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "PSD deficit rising toward fs/2"
