"""Physical effects, one module each, by their canonical names (DESIGN section 3).

Each effect is an ``eqx.Module`` subclass of :class:`AbstractEffect` with its canonical
``name``, its ``kind`` (where it enters the signal chain), its parameters (:class:`Param`:
SI unit, lab unit, description, bounds of the default prior) and its hooks (additive PSD term,
transfer function, friction, the simulator's injection ``to_injection``, and how ``diagnose``
tests it), and optional parameter values as array fields (``Drift(drift_diffusion=2e-16)``).
The registry :data:`EFFECTS` is found by :func:`discover`: a new effect is one new module here
(one ``AbstractEffect`` subclass with a canonical ``name``) plus its tests. :data:`QUANTITIES`
is the single table of units and ranges that results, reports, plots and priors read.
"""

from __future__ import annotations

import importlib
import math
import pkgutil

from . import injections as injections
from ._base import AbstractEffect as AbstractEffect
from ._base import DataContext as DataContext
from ._base import Param as Param
from ._base import StartContext as StartContext
from ._base import value_field as value_field
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
from .stage_drive import StageDrive as StageDrive
from .timing_jitter import TimingJitter as TimingJitter
from .tracking_noise import TrackingNoise as TrackingNoise

#: public modules of this package that hold no effect (the simulator's injection classes)
_SUPPORT_MODULES = frozenset({"injections"})

#: every effect by canonical name, in signal-chain order (``order``), found by :func:`discover`
EFFECTS: dict[str, type[AbstractEffect]] = {}

#: every quantity by name: core parameters, effect parameters, derived quantities
QUANTITIES: dict[str, Param] = {}

#: names bound in this namespace by discover() (classes not imported above)
_BOUND: set[str] = set()


def _module_effect(module) -> type[AbstractEffect]:
    """The one effect class a module defines (with a non-empty canonical ``name``)."""
    found = [c for c in vars(module).values()
             if isinstance(c, type) and issubclass(c, AbstractEffect)
             and c.__module__ == module.__name__ and c.name]
    if len(found) != 1:
        raise ImportError(f"effect module {module.__name__} must define exactly one "
                          f"AbstractEffect subclass with a canonical name; found "
                          f"{[c.__name__ for c in found]}")
    return found[0]


def discover() -> dict[str, type[AbstractEffect]]:
    """(Re)build :data:`EFFECTS` and :data:`QUANTITIES` in place from the modules of this
    package (every module on ``blurtrap.effects.__path__`` whose name does not start with an
    underscore defines one effect), so that a new effect is one new module: its class is found
    here and reaches ``TrapModel``/``calibrate``, ``simulate(..., effects=...)`` and
    ``diagnose`` with no other edit. Also binds each class as ``blurtrap.effects.<Class>``.
    Raises ``ImportError`` for a module without exactly one named effect and ``ValueError``
    for two modules claiming one canonical name."""
    classes: dict[str, type[AbstractEffect]] = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_") or info.name in _SUPPORT_MODULES:
            continue
        cls = _module_effect(importlib.import_module(f"{__name__}.{info.name}"))
        if cls.name in classes and classes[cls.name] is not cls:
            raise ValueError(f"effect name {cls.name!r} is defined twice: by "
                             f"{classes[cls.name].__module__} and {cls.__module__}")
        classes[cls.name] = cls
    for stale in _BOUND - {c.__name__ for c in classes.values()}:
        globals().pop(stale, None)
        _BOUND.discard(stale)
    for cls in classes.values():
        if cls.__name__ not in globals():
            globals()[cls.__name__] = cls
            _BOUND.add(cls.__name__)
    EFFECTS.clear()
    EFFECTS.update(sorted(classes.items(), key=lambda kv: (kv[1].order, kv[0])))
    QUANTITIES.clear()
    QUANTITIES.update({p.name: p for p in (*CORE, *(q for cls in EFFECTS.values()
                                                    for q in cls.params), *DERIVED)})
    return EFFECTS


discover()


def make_effect(effect, **config) -> AbstractEffect:
    """An effect instance from a canonical name or an effect class (an instance passes
    through unchanged; ``config`` is then ignored)."""
    if isinstance(effect, AbstractEffect):
        return effect
    if isinstance(effect, type) and issubclass(effect, AbstractEffect):
        return effect(**config)
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; canonical names: {sorted(EFFECTS)}")
    return EFFECTS[effect](**config)


def lab_units(name: str) -> tuple[float, str]:
    """``(factor, unit)``: a value in lab units is ``factor`` x its SI value. Per-recording
    names (``k[P=100 mW]``) use their base name; unknown names give ``(1.0, "SI")``."""
    q = QUANTITIES.get(name.split("[")[0])
    return (q.lab_factor, q.lab_unit) if q is not None else (1.0, "SI")


#: the fitted quantities whose plausible ranges reveal positions in another unit than
#: declared (k, c and gamma scale as 1/s^2 when the positions are s x too large)
UNIT_SLIP_QUANTITIES = ("k", "c", "gamma")


def implausible(name: str, value: float) -> Param | None:
    """The quantity of ``name`` (per-recording names use their base name) when the finite,
    positive ``value`` (SI) lies outside its plausible range (``Param.bounds``: the range of
    a trapped bead in a liquid, the default prior's support), else None. Results, batch rows,
    held values and priors all ask this one question (a unit slip, almost always)."""
    q = QUANTITIES.get(name.split("[")[0])
    if q is None or not (math.isfinite(value) and value > 0) or not q.outside(value):
        return None
    return q


__all__ = [
    "EFFECTS", "QUANTITIES", "UNIT_SLIP_QUANTITIES", "AbstractEffect", "Aliasing", "Anharmonicity",
    "DataContext", "implausible",
    "DetectorFilter", "Drift", "ExposureKernel", "Hydrodynamics", "LaserHeating", "LineNoise",
    "MotionBlur", "Param", "PowerOffset", "StageDrive", "StartContext", "TimingJitter",
    "TrackingNoise", "discover", "injections", "lab_units", "make_effect", "value_field",
]
