"""What the estimators share with blurtrap's other layers (diagnostics, plotting).

Not part of the user-facing API (that is :mod:`blurtrap.inference` and the top-level
``blurtrap`` names) and without a stability promise; it exists so that no other subpackage
imports a private module of ``blurtrap.inference`` (issue 16, clean boundaries). Each name
is the estimators' own object, re-exported unchanged.
"""

from ._detector_check import DETECTOR_DLOGL, MIN_RATE_HZ
from ._fit import chi2_sf
from ._fit_inputs import html_table
from ._frames import _inspect_frames as inspect_frames
from ._frames import mean_shift
from ._instrument import default_model
from ._ml_fits import screen_model
from ._recordings import as_recordings
from ._refusals import refuse_without_temporal_information
from ._spectral import _np_periodogram as np_periodogram
from ._volts import _power_of as volts_power

__all__ = [
    "DETECTOR_DLOGL",
    "MIN_RATE_HZ",
    "as_recordings",
    "chi2_sf",
    "default_model",
    "html_table",
    "inspect_frames",
    "mean_shift",
    "np_periodogram",
    "refuse_without_temporal_information",
    "screen_model",
    "volts_power",
]
