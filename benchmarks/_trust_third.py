"""The third independent pass's classes (session 23) for benchmarks/study_trust.py: active
calibration's drive response (absent, too small, relative to the stage, inverted, a late
stage clock, a wrong declared frequency), x/y axes of unequal sensitivity, k = c P with a
power offset, a diode filter fitted to a trace without one, stiff/soft white frames with a
known friction in diagnose. Data from numpy alone (exact AR(1) frames at 100 kHz and the
analytic response H = i f_d/(f_c + i f_d) to the drive)."""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.signal import lfilter

import blurtrap as bt
from blurtrap.inference import FitError

KT = 1.380649e-23 * 295.0
GAMMA = 6 * math.pi * 9.5e-4 * 1.53e-6
K5, DT_PD, N_PD, RD, FD = 5e-5, 1e-5, 65536, 2e-7, 32.0


def ou(n, dt, k, rng, eps=2e-9):
    a = math.exp(-k * dt / GAMMA)
    e = rng.standard_normal(n) * math.sqrt(KT / k)
    e[1:] *= math.sqrt(1 - a * a)
    return lfilter([1.0], [1.0, -a], e) + eps * rng.standard_normal(n)


def _run(fn, note_words=(), truth=None):
    """clear error / noted / honest (``truth``: {name: value} within 5 SE) / silent failure."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = fn()
    except (FitError, ValueError) as exc:
        return {"outcome": "clear error", "error": f"{type(exc).__name__}: {str(exc)[:200]}"}
    except Exception as exc:  # noqa: BLE001
        return {"outcome": "crash", "error": f"{type(exc).__name__}: {exc}"}
    notes = " ".join(getattr(r, "notes", ())).lower()
    if note_words and any(w in notes for w in note_words):
        return {"outcome": "noted"}
    if truth:
        z = {n: (float(getattr(r, n)) - v) / float(getattr(r, n + "_err"))
             for n, v in truth.items()}
        ok = all(math.isfinite(t) and abs(t) < 5 for t in z.values())
        return {"outcome": "honest" if ok else "silent failure", "z": z}
    return {"outcome": "silent failure", "why": "no error and no note"}


def third_pass_cases():
    rng = np.random.default_rng(230)
    t = np.arange(N_PD) * DT_PD
    fc = K5 / (2 * math.pi * GAMMA)
    h = 1j * FD / (fc + 1j * FD)
    s = 150e-9 * np.exp(0.3j) * np.exp(2j * math.pi * FD * t)
    stage = np.real(s)
    x = ou(N_PD, DT_PD, K5, rng)

    def active(volts, stage_trace, declared=FD):
        return lambda: bt.calibrate(bt.Recording(
            volts, frame_interval=DT_PD, exposure=1e-9 * DT_PD, temperature=295.0,
            stage=stage_trace, position_unit="V",
            metadata={"drive": {"frequency_Hz": declared}, "detector": "photodiode"}))

    yield "drive: response absent", _run(active(x / RD, stage))
    yield "drive: 1 nm drive", _run(active((x + np.real(h * s) / 150) / RD, stage / 150))
    yield "drive: trace relative to the stage", _run(
        active((x + np.real((h - 1) * s)) / RD, stage), ("relative to the stage",))
    yield "drive: inverted detector", _run(active(-(x + np.real(h * s)) / RD, stage),
                                           ("inverted",))
    late = np.real(150e-9 * np.exp(0.3j) * np.exp(2j * math.pi * FD * (t - 1e-3)))
    yield "drive: stage clock 1 ms late", _run(active((x + np.real(h * s)) / RD, late),
                                               ("timing offset",))
    for declared in (31.0, 32000.0):
        yield f"drive: declared {declared:g} Hz", _run(
            active((x + np.real(h * s)) / RD, stage, declared))
    yield "drive control: correct", _run(active((x + np.real(h * s)) / RD, stage),
                                         truth={"k": K5, "gamma": GAMMA})
    dt = 1 / 1500
    u, v = ou(65536, dt, 2e-5, rng, 0.0), ou(65536, dt, 5e-5, rng, 0.0)
    xs = math.cos(0.5) * u - math.sin(0.5) * v + 2e-9 * rng.standard_normal(65536)
    ys = math.sin(0.5) * u + math.cos(0.5) * v + 2e-9 * rng.standard_normal(65536)
    yield "xy: y gain 1.3", _run(lambda: bt.calibrate_xy(bt.xy_from_arrays(
        xs, 1.3 * ys, frame_interval=dt, exposure=1e-9 * dt, temperature=295.0),
        separate=False), ("principal axes are coupled",))
    rng_p = np.random.default_rng(231)
    recs = [bt.Recording(ou(32768, dt, 5e-4 * (p - 0.02), rng_p), frame_interval=dt,
                         exposure=1e-9 * dt, temperature=295.0, laser_power=p)
            for p in (0.05, 0.1, 0.15, 0.2)]
    yield "power: k = c (P - 20 mW) as linear_power", _run(
        lambda: bt.calibrate(recs, k="linear_power"), ("k = c p does not fit",))
    yield "filter: diode_filter fit on a trace without one", _run(
        lambda: bt.calibrate(bt.Recording(x * RD / RD, frame_interval=DT_PD,
                                          exposure=1e-9 * DT_PD, temperature=295.0,
                                          metadata={"detector": "photodiode",
                                                    "diode_filter": "fit"})),
        truth={"k": K5, "gamma": GAMMA})
    white = bt.Recording(10e-9 * rng.standard_normal(16384), frame_interval=dt, exposure=dt,
                         metadata={"friction": "stokes", "bead_radius_m": 1.53e-6})
    yield "known friction: white frames, diagnose", _run(lambda: bt.diagnose(white))


EXPECTED = {"drive: response": "clear error", "drive: 1 nm": "clear error",
            "drive: trace": "noted", "drive: inverted": "noted", "drive: stage clock": "noted",
            "drive: declared": "clear error", "drive control": "honest", "xy:": "noted",
            "power:": "noted", "filter:": ("clear error", "honest"), "known friction": "clear error"}
