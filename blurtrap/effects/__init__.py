"""Physical effects, one module each, by their canonical names (DESIGN section 3).

Each effect is an ``eqx.Module`` subclass of :class:`AbstractEffect` with its canonical
``name``, its ``kind`` (where it enters the signal chain), its parameters (:class:`Param`:
SI unit, lab unit, description, bounds of the default prior) and its hooks (additive PSD term,
transfer function, friction). :data:`QUANTITIES` is the single table of units and ranges that
results, reports, plots and priors read.
"""

from __future__ import annotations

from ._base import AbstractEffect as AbstractEffect
from ._base import Param as Param
from ._base import StartContext as StartContext
from ._quantities import CORE, DERIVED
from .aliasing import Aliasing as Aliasing
from .anharmonicity import Anharmonicity as Anharmonicity
from .detector_filter import DetectorFilter as DetectorFilter
from .drift import Drift as Drift
from .exposure_kernel import ExposureKernel as ExposureKernel
from .hydrodynamics import Hydrodynamics as Hydrodynamics
from .laser_heating import LaserHeating as LaserHeating
from .line_noise import LineNoise as LineNoise
from .motion_blur import MotionBlur as MotionBlur
from .power_offset import PowerOffset as PowerOffset
from .timing_jitter import TimingJitter as TimingJitter
from .tracking_noise import TrackingNoise as TrackingNoise

EFFECTS: dict[str, type[AbstractEffect]] = {
    cls.name: cls
    for cls in (MotionBlur, Aliasing, TrackingNoise, Drift, ExposureKernel, DetectorFilter,
                Hydrodynamics, Anharmonicity, LaserHeating, PowerOffset, LineNoise,
                TimingJitter)
}

#: every quantity by name: core parameters, effect parameters, derived quantities
QUANTITIES: dict[str, Param] = {
    p.name: p
    for p in (*CORE, *(q for cls in EFFECTS.values() for q in cls.params), *DERIVED)
}


def make_effect(effect, **config) -> AbstractEffect:
    """An effect instance from a canonical name (or pass an instance through)."""
    if isinstance(effect, AbstractEffect):
        return effect
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; canonical names: {sorted(EFFECTS)}")
    return EFFECTS[effect](**config)


def lab_units(name: str) -> tuple[float, str]:
    """``(factor, unit)``: a value in lab units is ``factor`` x its SI value. Per-recording
    names (``k[P=100 mW]``) use their base name; unknown names give ``(1.0, "SI")``."""
    q = QUANTITIES.get(name.split("[")[0])
    return (q.lab_factor, q.lab_unit) if q is not None else (1.0, "SI")


__all__ = [
    "EFFECTS", "QUANTITIES", "AbstractEffect", "Aliasing", "Anharmonicity", "DetectorFilter",
    "Drift", "ExposureKernel", "Hydrodynamics", "LaserHeating", "LineNoise", "MotionBlur",
    "Param", "PowerOffset", "StartContext", "TimingJitter", "TrackingNoise", "lab_units",
    "make_effect",
]
