"""Whether the variance of the positions changes across a record: the stiffness changed
while recording (laser power, a bead exchanged or stuck) or two recordings were joined.

An independent pass joined two halves of stiffness k and 2k into one trace: k came out
between them with a goodness of fit of p = 0.26 and no note, and diagnose named
anharmonicity (the mixture's kurtosis). The squared deviations of the frames from their
segment's mean have a mean that is the segment's variance, so the batch-means test of a
moving mean (:func:`._frames.mean_shift`, its own correlation time, sub-blocks >= 20 of it,
p < 1e-6 and a spread above a quarter of their standard deviation) applied to them tests a
moving variance. A step or drift of the mean is named by that test on the positions
themselves; a record that has one is not tested here (its squared deviations move too).
Segments shorter than 50 correlation times are not tested.
"""

from __future__ import annotations

import numpy as np

from ._frames import _SHIFT_SEGMENTS, mean_shift, segment_tau

#: segments must be this many correlation times long: shorter ones (1.3 tau at 4096 frames,
#: tau = 200 frames) lose a varying part of their variance to their own mean, and the test
#: flagged 2 of 399 stationary records at p < 1e-6
_MIN_SEGMENT_TAU = 50.0


def variance_shift(y) -> dict | None:
    """:func:`._frames.mean_shift` of the squared deviations of ``y`` from the means of its
    16 segments (the same segments that test uses), with ``"low"``/``"high"``: the smallest
    and largest segment variance; None where that test makes none."""
    y = np.asarray(y, dtype=float)
    m = y.size // _SHIFT_SEGMENTS
    if m < 32:
        return None
    seg = y[: m * _SHIFT_SEGMENTS].reshape(_SHIFT_SEGMENTS, m)
    seg = seg - seg.mean(axis=1, keepdims=True)
    tau = segment_tau(seg)
    if tau is None or m < _MIN_SEGMENT_TAU * max(tau, 1.0):
        return None  # a segment's own mean would take a part of its variance that varies
    z = seg**2
    out = mean_shift(z.ravel())
    if out is not None:
        v = z.mean(axis=1)
        out = dict(out, low=float(v.min()), high=float(v.max()))
    return out


def variance_shift_sentence(recs, tests=None) -> str:
    """A sentence naming a change of the position variance ('' when there is none, or when
    the record's mean moves: that has its own note); ``tests``: the recordings'
    :func:`._frames.mean_shift` results if the caller has them."""
    tests = tests if tests is not None else [mean_shift(r.positions) for r in recs]
    for i, (r, shift) in enumerate(zip(recs, tests)):
        if shift is not None and shift["significant"]:
            continue
        t = variance_shift(r.positions)
        if t is None or not t["significant"]:
            continue
        where = (f"; it changes most near frame {t['at']}" if t["step"] else "")
        return (f"the variance of recording {i}'s positions is not stationary: the variances "
                f"of {t['dof'] + 1} segments range from {t['low']:.3g} to {t['high']:.3g} "
                f"({t['high'] / t['low']:.3g} x), far beyond their expected scatter (chi^2 = "
                f"{t['chi2']:.4g}, {t['dof']} dof, p = {t['p']:.2g}){where}. The trap changed "
                "during the record (laser power, a bead exchanged or stuck) or recordings were "
                "joined: one k and gamma cannot describe it, and a fit gives values between "
                "the parts. Cut the record where it changes and calibrate the parts")
    return ""
