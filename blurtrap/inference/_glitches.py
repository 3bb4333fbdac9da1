"""Isolated tracking glitches: single frames far off the trace (a mis-tracked bead, a lost
particle, a dropped detector sample) or a jump of the trace.

A glitch of a few frames barely moves the power spectrum's shape: its power is white, so
the fit takes it for tracking noise. An independent pass measured a single frame at +300
standard deviations raising eps^2 37 of its standard errors and the standard error of k 3x,
with a goodness of fit of p = 1 and no note; 20 frames at +-20 standard deviations raised
eps^2 8 standard errors. The frame-to-frame changes ``d = diff(y)`` of a stationary Gaussian
trace are Gaussian, and a glitch makes two of them (in and out) as large as itself, so the
check compares each ``|d - median(d)|`` with a robust scale of ``d`` (1.4826 x its median
absolute deviation): above :data:`GLITCH_Z` they are not Gaussian chance (probability
< 1e-14 per change, below 1e-8 for a record of 10^6 frames).
"""

from __future__ import annotations

import numpy as np

#: a frame-to-frame change this many robust standard deviations from the median is a glitch
GLITCH_Z = 8.0
#: the robust scale of the changes is trusted only with this many distinct values among
#: them (coarsely quantised positions have changes of a few grid steps: their MAD is no scale)
_MIN_DISTINCT = 16


def glitch_note(y, where: str) -> str:
    """A note on frame-to-frame changes of ``y`` far beyond Gaussian chance (module
    docstring), naming how many and the largest; ``''`` when there are none."""
    y = np.asarray(y, dtype=float)
    if y.size < 64:
        return ""
    d = np.diff(y)
    centred = np.abs(d - np.median(d))
    scale = 1.4826 * float(np.median(centred))
    if not scale > 0 or np.unique(d[: min(d.size, 4096)]).size < _MIN_DISTINCT:
        return ""
    z = centred / scale
    big = np.flatnonzero(z > GLITCH_Z)
    if big.size == 0:
        return ""
    j = int(big[np.argmax(z[big])])
    frames = ", ".join(str(int(i) + 1) for i in big[:6]) + (", ..." if big.size > 6 else "")
    return (f"{where}: {big.size} frame-to-frame change(s) exceed {GLITCH_Z:g} x the "
            f"typical one (robust scale {scale:.3g}; the largest {z[j]:.3g} x, into frame "
            f"{j + 1}; at frames {frames}): isolated tracking glitches or a jump of the trace, "
            "which a Gaussian trap model takes for tracking noise (eps^2 and the errors of k "
            "and gamma grow; the estimates may move). Remove or interpolate those frames, or "
            "split the record at a jump (robust=True leaves out spectral spikes, not frames)")
