"""The fifth independent pass's classes (session 25) for benchmarks/study_trust.py: an active
calibration in volts whose stage is in another unit, a friction given beside a drive,
calibrate_xy on positions in volts, diagnose on a correctly declared anti-aliased photodiode,
priors in lab units, rounded time stamps, design inputs in lab units and an NPZ column
vector. Data from numpy alone: exact AR(1) samples of the trap (a photodiode sampling the
position every 10 us), the bead's steady response to the stage drive, exact OU frames."""

from __future__ import annotations

import math
import warnings

import numpy as np
from _trust_third import GAMMA, _run, ou

import blurtrap as bt

K5, DT_PD, RD, FD = 5e-5, 1e-5, 1e-7, 32.0
BEAD = {"bead_radius_m": 1.53e-6, "viscosity_Pa_s": 9.5e-4, "hydrodynamics": False}


def _driven(rng, n=2**16):
    """Volts of a photodiode trace with the bead's response to a 150 nm stage drive, and the
    stage [m] (Tolic-Norrelykke et al. 2006, eq. 4)."""
    t = np.arange(n) * DT_PD
    fc = K5 / (2 * math.pi * GAMMA)
    s = 150e-9 * np.exp(0.3j) * np.exp(2j * math.pi * FD * t)
    volts = (ou(n, DT_PD, K5, rng) + np.real(1j * FD / (fc + 1j * FD) * s)) / RD
    return volts, np.real(s)


def _volts(volts, stage, **meta):
    return bt.Recording(volts, frame_interval=DT_PD, exposure=1e-9 * DT_PD, temperature=295.0,
                        position_unit="V", stage=stage,
                        metadata={"detector": "photodiode", "drive": {"frequency_Hz": FD},
                                  **meta})


def _judge(fn, ok, why):
    """honest when ``ok(result)``, else a silent failure saying ``why``; errors as _run."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = fn()
    except (bt.FitError, ValueError) as exc:
        return {"outcome": "clear error", "error": f"{type(exc).__name__}: {str(exc)[:200]}"}
    except Exception as exc:  # noqa: BLE001
        return {"outcome": "crash", "error": f"{type(exc).__name__}: {exc}"}
    return {"outcome": "honest"} if ok(r) else {"outcome": "silent failure", "why": why(r)}


def fifth_pass_cases():
    rng = np.random.default_rng(250)
    volts, stage = _driven(rng)
    yield "drive: stage in um read as nm", _run(
        lambda: bt.calibrate(_volts(volts, 1e-3 * stage, **BEAD)), ("implausible",))
    yield "drive: friction='stokes' beside a drive", _run(
        lambda: bt.calibrate(_volts(volts, stage, friction="stokes", **BEAD)), ("is not used",))
    a, b = (ou(2**16, DT_PD, 6e-5, rng) for _ in range(2))
    xy = bt.xy_from_arrays(a / RD, b / RD, frame_interval=DT_PD, exposure=1e-9 * DT_PD,
                           position_unit="V", metadata={"detector": "photodiode",
                                                        "friction": "stokes", **BEAD})
    yield "xy: isotropic trap in volts", _judge(
        lambda: bt.calibrate_xy(xy, separate=False), lambda r: not r.resolved,
        lambda r: f"resolved with anisotropy z = {r.anisotropy_z:.3g}")
    pd = bt.Recording(ou(2**16, DT_PD, K5, rng), frame_interval=DT_PD, exposure=DT_PD,
                      temperature=295.0, metadata={"detector": "photodiode",
                                                   "anti_aliasing": True, **BEAD})
    yield "diagnose: correct data of a declared photodiode", _judge(
        lambda: bt.diagnose(pd), lambda d: d.adequate, lambda d: d.summary()[:200])
    cam = bt.Recording(ou(16384, 1 / 1500, K5, rng), frame_interval=1 / 1500,
                       exposure=1e-9 / 1500, temperature=295.0)
    yield "prior: gamma in pN s/um", _run(
        lambda: bt.sample_posterior(cam, priors={"gamma": bt.Normal(0.0268, 5e-4)},
                                    n_steps=50))
    yield "prior: k in pN/nm (a plausible N/m)", _run(
        lambda: bt.sample_posterior(cam, priors={"k": bt.Normal(0.05, 0.001)}, n_steps=50,
                                    n_walkers=8), ("conflicts with the data",))
    t = np.round(np.arange(4096) / 1500, 4)  # time stamps written to 0.1 ms at 1500 fps
    yield "loader: time stamps rounded to 0.1 ms", _run(
        lambda: bt.Recording(ou(4096, 1 / 1500, K5, rng), frame_interval=1 / 1500,
                             exposure=1 / 1500, times=t))
    yield "design: bead radius in um", _run(
        lambda: bt.design(k=5e-5, radius=1.53, max_fps=1500, n_frames=65536))
    col = ou(16384, 1 / 1500, K5, rng)[:, None]
    yield "loader: an (N, 1) column", _run(
        lambda: bt.calibrate(bt.from_arrays(col, frame_interval=1 / 1500,
                                            exposure=1e-9 / 1500)),
        truth={"k": K5, "gamma": GAMMA})


EXPECTED = {"drive:": "noted", "xy: isotropic": "honest", "diagnose:": "honest",
            "prior: gamma": "clear error", "prior: k": "noted", "loader: time": "clear error",
            "design:": "clear error", "loader: an": "honest"}
