"""Brownian dynamics of a bead in an optical trap with in-loop exposure averaging.

``simulate`` is the entry point; injections (tracking noise, drift, timing jitter, photodiode
filter, hydrodynamic friction, stage drive, volts sensitivity), exposure
profiles and forces are small composable pieces passed to it. ``simulate_photodiode`` is the
oversampling, anti-aliasing photodiode instrument. Imports only
``blurtrap.physics``.
"""

from ._antialias import (
    antialias_gain as antialias_gain,
)
from ._antialias import (
    antialias_taps as antialias_taps,
)
from ._antialias import (
    simulate_photodiode as simulate_photodiode,
)
from ._exposure import (
    ExposureWindows as ExposureWindows,
)
from ._injections import (
    AbstractInjection as AbstractInjection,
)
from ._injections import (
    HydrodynamicFriction as HydrodynamicFriction,
)
from ._injections import (
    PhotodiodeFilter as PhotodiodeFilter,
)
from ._injections import (
    RandomWalkDrift as RandomWalkDrift,
)
from ._injections import (
    SinusoidDrift as SinusoidDrift,
)
from ._injections import (
    TimingJitter as TimingJitter,
)
from ._injections import (
    TrackingNoise as TrackingNoise,
)
from ._instruments import (
    Sensitivity as Sensitivity,
)
from ._instruments import (
    StageDrive as StageDrive,
)
from ._instruments import (
    stage_positions as stage_positions,
)
from ._labelled import (
    LabelledFrames as LabelledFrames,
)
from ._profiles import (
    ExponentialProfile as ExponentialProfile,
)
from ._profiles import (
    TrapezoidProfile as TrapezoidProfile,
)
from ._profiles import (
    harmonic_force as harmonic_force,
)
from ._profiles import (
    quartic_force as quartic_force,
)
from ._scan_coefs import (
    SubstepBiasWarning as SubstepBiasWarning,
)
from ._simulate import (
    simulate as simulate,
)
from ._xy import simulate_xy as simulate_xy
