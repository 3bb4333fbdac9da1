"""The eighth independent pass's classes (session 27) for benchmarks/study_trust.py: camera
tracking noise that differs between the recordings of a joint fit, camera frames declared as
an anti-aliased photodiode, point samples declared as an integrating photodiode, a laser
power missing on one recording, a band of the caller's that leaves k and gamma
unidentified, a design total time too short for its recordings, a photon-limited design.
Data from numpy alone: exact frames by circulant embedding of the frame autocovariance."""

from __future__ import annotations

import numpy as np
from _trust_fifth import _judge
from _trust_third import _run
from study_boundary import CirculantSampler, autocovariance

import blurtrap as bt

C8, G8, DT8 = 5e-5, 9.4e-9, 1 / 2000


def _frames(rng, n, k, gamma=G8, w=DT8 / 2, dt=DT8, eps2=0.0):
    return CirculantSampler(autocovariance(k, gamma, w, dt, eps2, n)).draw(rng, 1)[0]


def _powers(rng, eps2s, powers=(0.25, 0.5, 1.0, 2.0)):
    return [bt.Recording(_frames(rng, 16384, C8 * p, eps2=e), frame_interval=DT8, exposure=DT8 / 2,
                         temperature=295.0, laser_power=p) for p, e in zip(powers, eps2s)]


def eighth_pass_cases():
    rng = np.random.default_rng(270)
    recs = _powers(rng, [9e-18 / p for p in (0.25, 0.5, 1.0, 2.0)])
    yield "pooled: camera noise 6-2 nm over four powers", _run(
        lambda: bt.calibrate(recs, k="linear_power"), ("tracking noise differs",))
    cam = _frames(rng, 65536, 2e-5, w=1 / 5000, dt=1 / 5000, eps2=4e-18)
    yield "detector: camera frames declared anti-aliased", _run(
        lambda: bt.calibrate(bt.Recording(cam, frame_interval=1 / 5000, exposure=1 / 5000, temperature=295.0,
                                          metadata={"detector": "photodiode", "anti_aliasing": True})),
        ("fitted as an anti-aliased photodiode",))
    pts = _frames(rng, 65536, 2e-5, gamma=2e-5 * 0.75 / 1500, w=1e-3 / 1500, dt=1 / 1500)
    yield "photodiode: point samples declared W = dt", _run(
        lambda: bt.calibrate(bt.Recording(pts, frame_interval=1 / 1500, exposure=1 / 1500, temperature=295.0),
                             detector="photodiode"), ("rests on the photodiode",))
    part = _powers(rng, [4e-18] * 3, (0.25, 0.5, 1.0))
    part[1] = bt.Recording(part[1].positions, frame_interval=DT8, exposure=DT8 / 2, temperature=295.0)
    yield "powers: laser power missing on one recording", _run(lambda: bt.calibrate(part))
    one = bt.Recording(_frames(rng, 8192, C8), frame_interval=DT8, exposure=DT8 / 2, temperature=295.0)
    yield "band: f_range 20-40 Hz far below f_c", _run(lambda: bt.calibrate(one, f_range=(20.0, 40.0)),
                                                      truth={"k": C8})
    yield "design: total time of 15 frames", _run(
        lambda: bt.design(k=2e-5, radius=0.5e-6, max_fps=1500, total_time=0.01))
    yield "design: photon-limited series", _judge(
        lambda: bt.design(k=2e-5, radius=0.5e-6, max_fps=2000, total_time=20, tracking_std=3e-9,
                          photon_limited=True),
        lambda r: len({w for _, w, _ in r.best.recordings}) == 1 or bool(r.notes),
        lambda r: "a photon-limited series recommended without a word of its noise model")


EXPECTED = {"pooled: camera": "noted", "detector: camera frames": "noted", "photodiode: point": "noted",
            "powers:": "clear error", "band:": ("clear error", "honest"), "design: total": "clear error",
            "design: photon": "honest"}
