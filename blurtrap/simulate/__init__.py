"""Brownian dynamics of a bead in an optical trap with in-loop exposure averaging.

``simulate`` is the entry point; injections (tracking noise, drift, timing jitter), exposure
profiles and forces are small composable pieces passed to it. Imports only
``blurtrap.physics``.
"""

from ._injections import (
    AbstractInjection as AbstractInjection,
    RandomWalkDrift as RandomWalkDrift,
    SinusoidDrift as SinusoidDrift,
    TimingJitter as TimingJitter,
    TrackingNoise as TrackingNoise,
)
from ._profiles import (
    ExponentialProfile as ExponentialProfile,
    TrapezoidProfile as TrapezoidProfile,
    harmonic_force as harmonic_force,
    quartic_force as quartic_force,
)
from ._simulate import (
    ExposureWindows as ExposureWindows,
    SubstepBiasWarning as SubstepBiasWarning,
    simulate as simulate,
)
