"""What the data layer's plausibility checks share with blurtrap's other layers.

Not part of the user-facing API (that is :mod:`blurtrap.data` and the top-level ``blurtrap``
names) and without a stability promise; it exists so that no other subpackage imports a
private module of ``blurtrap.data`` (issue 16, clean boundaries). Each name is the data
layer's own object, re-exported unchanged: the unit-slip limits of :class:`Recording` and
its instrument metadata (for design, calibrate_batch's rows and the CLI's option checks),
the helpers that name the likely unit, and the resolution of rounded time stamps (the
irregular-time likelihood).
"""

from ._instrument import _MAX_BEAD_RADIUS_M as MAX_BEAD_RADIUS_M
from ._plausible import _MAX_PLAUSIBLE_INTERVAL_S as MAX_PLAUSIBLE_INTERVAL_S
from ._plausible import _MAX_PLAUSIBLE_LASER_POWER_W as MAX_PLAUSIBLE_LASER_POWER_W
from ._plausible import _MAX_PLAUSIBLE_POSITION_STD_M as MAX_PLAUSIBLE_POSITION_STD_M
from ._plausible import _MAX_PLAUSIBLE_TEMPERATURE_K as MAX_PLAUSIBLE_TEMPERATURE_K
from ._plausible import _MIN_PLAUSIBLE_POSITION_STD_M as MIN_PLAUSIBLE_POSITION_STD_M
from ._plausible import _MIN_PLAUSIBLE_TEMPERATURE_K as MIN_PLAUSIBLE_TEMPERATURE_K
from ._plausible import _check_temperature as check_temperature
from ._plausible import _likely_unit as likely_position_unit
from ._plausible import in_ms_message
from ._timing import stamp_quantum

__all__ = [
    "MAX_BEAD_RADIUS_M",
    "MAX_PLAUSIBLE_INTERVAL_S",
    "MAX_PLAUSIBLE_LASER_POWER_W",
    "MAX_PLAUSIBLE_POSITION_STD_M",
    "MAX_PLAUSIBLE_TEMPERATURE_K",
    "MIN_PLAUSIBLE_POSITION_STD_M",
    "MIN_PLAUSIBLE_TEMPERATURE_K",
    "check_temperature",
    "in_ms_message",
    "likely_position_unit",
    "stamp_quantum",
]
