"""The simulator's injections (defined in :mod:`blurtrap.effects.injections`, where each effect's
``to_injection`` hook builds them; re-exported here under their names) and the conversion of
effect objects (``simulate(..., effects=[...])``) into injections and an exposure profile."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ..effects import AbstractEffect
from ..effects.injections import AbstractInjection as AbstractInjection
from ..effects.injections import HydrodynamicFriction as HydrodynamicFriction
from ..effects.injections import PhotodiodeFilter as PhotodiodeFilter
from ..effects.injections import RandomWalkDrift as RandomWalkDrift
from ..effects.injections import SinusoidDrift as SinusoidDrift
from ..effects.injections import TimingJitter as TimingJitter
from ..effects.injections import TrackingNoise as TrackingNoise
from ..effects.injections import TrapezoidProfile as TrapezoidProfile


def from_effects(effects: Sequence, exposure_profile: Callable | None
                 ) -> tuple[tuple, Callable | None]:
    """``(injections, exposure_profile)`` for ``simulate(..., effects=effects)``: each effect's
    ``to_injection()`` in order (``motion_blur`` and ``aliasing`` give ``None``: the simulator
    always averages over the exposure and samples at the frame interval); an exposure profile
    (``exposure_kernel``) becomes the exposure profile, which may then not be given too."""
    if isinstance(effects, AbstractEffect):
        effects = [effects]
    out = []
    profile = exposure_profile
    for e in effects:
        if not isinstance(e, AbstractEffect):
            raise ValueError("effects must be effect objects from blurtrap.effects (e.g. "
                             f"bt.effects.Drift(drift_diffusion=2e-16)); got {e!r}")
        inj = e.to_injection()
        if inj is None:
            continue
        if isinstance(inj, TrapezoidProfile):
            if profile is not None:
                raise ValueError(f"effects: {type(e).__name__} sets the exposure profile, but "
                                 f"exposure_profile = {profile!r} was given too; give one")
            profile = inj
            continue
        out.append(inj)
    return tuple(out), profile
