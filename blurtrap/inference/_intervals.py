"""The result's 95 % intervals: the Wald table with the profile intervals merged in."""

from __future__ import annotations

import math


def merge(ivs: dict, kinds: dict, more: dict, more_kinds: dict) -> None:
    """Put the intervals ``more`` (a profile's, ``(low, high)`` with NaN for an end whose
    root find or profile fit did not converge) into the Wald table ``ivs`` / ``kinds``, in
    place. Both ends converged: the profile interval. One end: that end, and the Wald (or
    log-Wald) end on the other side, labelled ``"profile (upper end wald: its profile did not
    converge)"``; a converged end was discarded with its twin before (intervals of records a
    few relaxation times long). None: the Wald interval, labelled ``"wald (profile did not
    converge)"``."""
    for n, iv in more.items():
        ends = [math.isfinite(e) for e in iv]
        if all(ends):
            ivs[n], kinds[n] = iv, more_kinds[n]
        elif any(ends):
            ivs[n] = tuple(e if ok else w for e, ok, w in zip(iv, ends, ivs[n]))
            side = "lower" if ends[1] else "upper"
            kinds[n] = f"{more_kinds[n]} ({side} end {kinds[n]}: its {more_kinds[n]} did not converge)"
        else:
            kinds[n] += f" ({more_kinds[n]} did not converge)"
