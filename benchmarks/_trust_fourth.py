"""The fourth independent pass's classes (session 24) for benchmarks/study_trust.py: a
goodness of fit that fails with no note (repeated frames, a wrong declared exposure, an
undeclared diode filter, a strong random-walk drift), an exposure series whose tracking
error grows at short exposures (photon-limited), isolated tracking glitches, two
stiffnesses joined into one trace, profile intervals of short records, and the posterior
of a trace with a line. Data from numpy alone: exact Ornstein-Uhlenbeck substeps, averaged
over the exposure for a camera."""

from __future__ import annotations

import math
import warnings

import numpy as np
from _trust_third import GAMMA, KT, _run, ou
from scipy.signal import lfilter

import blurtrap as bt

K5, DT = 5e-5, 1 / 1500


def camera(n, rng, k=K5, w=DT, eps=2e-9, m=20):
    """``n`` frames every DT, each the mean of ``m`` exact OU substeps over the exposure ``w``
    (the rest of the interval in one exact step), plus white tracking noise ``eps``."""
    h, gap = w / m, DT - w
    a, b = math.exp(-k * h / GAMMA), math.exp(-k * gap / GAMMA)
    s = math.sqrt(KT / k)
    x = s * rng.standard_normal()
    out = np.empty(n)
    for i in range(n):
        acc = 0.0
        for _ in range(m):
            x = a * x + s * math.sqrt(1 - a * a) * rng.standard_normal()
            acc += x
        out[i] = acc / m
        x = b * x + s * math.sqrt(1 - b * b) * rng.standard_normal()
    return out + eps * rng.standard_normal(n)


def _rec(x, w=DT, **kw):
    return bt.Recording(x, frame_interval=DT, exposure=w, temperature=295.0, **kw)


def _intervals_finite(fn):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = fn()
    except bt.FitError as exc:
        return {"outcome": "clear error", "error": str(exc)[:200]}
    bad = {n: iv for n, iv in r.intervals.items() if not all(map(math.isfinite, iv))}
    return {"outcome": "honest"} if not bad else {"outcome": "silent failure",
                                                  "why": f"non-finite intervals {bad}"}


def _posterior_gamma(rec):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = bt.sample_posterior(rec, n_steps=300, n_walkers=8)
    st = post.stats()["gamma"]
    z = (st["median"] - GAMMA) / st["sd"]
    return {"outcome": "honest" if abs(z) < 5 else "silent failure", "z": {"gamma": z}}


def fourth_pass_cases():
    rng = np.random.default_rng(240)
    x = camera(32768, rng)
    rep = x.copy()
    rep[1::2] = rep[0::2]
    words = ("does not fit the data",)
    yield "misfit: camera repeating every other frame", _run(lambda: bt.calibrate(_rec(rep)),
                                                             words)
    yield "misfit: exposure declared 0.3 dt (it is dt)", _run(
        lambda: bt.calibrate(_rec(x, w=0.3 * DT)), words, truth={"k": K5, "gamma": GAMMA})
    walk = np.cumsum(rng.standard_normal(x.size))
    walk *= 1.0 * x.std() / walk.std()
    yield "misfit: random-walk drift of 1 std", _run(
        lambda: bt.calibrate(_rec(x + walk)), words + ("not stationary",))
    pd = ou(2**17, 1e-5, K5, rng)
    bb = math.exp(-2 * math.pi * 5e3 * 1e-5)
    filt = 0.3 * pd + 0.7 * lfilter([1 - bb], [1, -bb], pd)
    yield "misfit: undeclared diode filter (volts, friction known)", _run(
        lambda: bt.calibrate(bt.Recording(filt / 1e-7, frame_interval=1e-5, exposure=1e-5,
                                          position_unit="V", metadata={
                                              "detector": "photodiode", "friction": "stokes",
                                              "bead_radius_m": 1.53e-6,
                                              "viscosity_Pa_s": 9.5e-4,
                                              "hydrodynamics": False})), words)
    photon = [_rec(camera(16384, rng, w=f * DT, eps=2e-9 / math.sqrt(f)), w=f * DT)
              for f in (0.1, 0.3, 1.0)]
    same = [_rec(camera(16384, rng, w=f * DT), w=f * DT) for f in (0.1, 0.3, 1.0)]
    disagree = ("disagree on tracking_var",)
    yield "pooled: photon-limited exposure series", _run(
        lambda: bt.calibrate(bt.RecordingSet(photon)), disagree)
    yield "pooled: photon-limited, variance_vs_exposure", _run(
        lambda: bt.calibrate(bt.RecordingSet(photon), method="variance_vs_exposure"),
        disagree)
    yield "exposure series control: equal tracking noise", _run(
        lambda: bt.calibrate(bt.RecordingSet(same)), truth={"k": K5, "gamma": GAMMA})
    g = x.copy()
    g[12345] += 300 * x.std()
    yield "glitch: one frame at +300 sd", _run(lambda: bt.calibrate(_rec(g)),
                                              ("frame-to-frame",))
    joined = np.concatenate([x[:16384], camera(16384, rng, k=2 * K5)])
    yield "changed: halves of k and 2k joined", _run(lambda: bt.calibrate(_rec(joined)),
                                                     ("variance of recording",))
    soft = 5e-7  # tau = 80 frames, T = 10 tau
    yield "intervals: a record of 10 tau", _intervals_finite(
        lambda: bt.calibrate(_rec(ou(804, DT, soft, rng))))
    t = np.arange(x.size) * DT
    yield "posterior: a 50 Hz line of 1 sd", _posterior_gamma(
        _rec(x + x.std() * np.sin(2 * np.pi * 50 * t)))


EXPECTED = {"misfit:": "noted", "pooled:": "noted", "exposure series control": "honest",
            "glitch:": "noted", "changed:": "noted", "intervals:": ("honest", "clear error"),
            "posterior:": "honest"}
