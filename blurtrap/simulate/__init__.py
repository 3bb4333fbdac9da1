"""Brownian dynamics of a bead in an optical trap with in-loop exposure averaging.

``simulate`` is the entry point; injections (tracking noise, drift, timing jitter, photodiode
filter, hydrodynamic friction), exposure
profiles and forces are small composable pieces passed to it. Imports only
``blurtrap.physics``.
"""

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
from ._simulate import (
    ExposureWindows as ExposureWindows,
)
from ._simulate import (
    SubstepBiasWarning as SubstepBiasWarning,
)
from ._simulate import (
    simulate as simulate,
)
