"""Camera frames (exposure average, folding) declared as an anti-aliased photodiode: gamma 8 SE
high in 20/20 datasets of an independent pass, no note from calibrate. The folded model is
fitted on the same ordinates and a far better fit is named, with its k and gamma.

Frames by circulant embedding of the exact frame autocovariance (tests/_circulant.py); the
anti-aliased control is point samples at 8x the rate, low-passed at the final Nyquist
frequency (an ideal filter, by FFT) and decimated: neither uses blurtrap's simulator."""

from __future__ import annotations

import re

import numpy as np
import pytest
from _circulant import circulant_frames

import blurtrap as bt

K, GAMMA, TEMP, DT, N = 2e-5, 9.4e-9, 295.0, 1 / 5000, 32768
AA = {"detector": "photodiode", "anti_aliasing": True}


def _note(res):
    return next((n for n in res.notes if n.startswith("detector: the frames were fitted as an anti-aliased")),
                None)


@pytest.mark.parametrize("seed", [1, 2])
def test_camera_frames_declared_anti_aliased_are_named(seed):
    y = circulant_frames(K, GAMMA, DT, DT, 4e-18, 2 * N, seed, temperature=TEMP)  # 65 536 frames
    res = bt.calibrate(bt.Recording(y, frame_interval=DT, exposure=DT, temperature=TEMP, metadata=AA))
    assert (res.gamma - GAMMA) / res.gamma_err > 3  # the bias the note is about
    note = _note(res)
    assert note, res.notes
    k = float(re.search(r"k = ([\d.e+-]+) pN/nm", note)[1]) * 1e-3
    g = float(re.search(r"gamma = ([\d.e+-]+) pN s/um", note)[1]) * 1e-6
    assert abs(k / K - 1) < 3 * res.k_err / res.k and abs(g / GAMMA - 1) < 3 * res.gamma_err / res.gamma


@pytest.mark.parametrize("seed", [3, 4])
def test_an_anti_aliased_photodiode_gets_no_such_note(seed):
    over = 8
    x = circulant_frames(K, GAMMA, 1e-4 * DT / over, DT / over, 0.0, N * over, seed, temperature=TEMP)
    spec = np.fft.rfft(x)
    spec[np.fft.rfftfreq(x.size, DT / over) > 0.5 / DT] = 0.0
    y = np.fft.irfft(spec, x.size)[::over] + 2e-9 * np.random.default_rng(seed).standard_normal(N)
    res = bt.calibrate(bt.Recording(y, frame_interval=DT, exposure=1e-3 * DT, temperature=TEMP, metadata=AA))
    assert _note(res) is None
    assert abs(res.gamma - GAMMA) < 3 * res.gamma_err
