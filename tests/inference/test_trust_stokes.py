"""A fitted gamma far from Stokes' 6 pi eta r of a bead of known radius
(``metadata['bead_radius_m']``) is flagged in ``result.notes``.

Traces: exact AR(1) recursion plus white noise (independent of blurtrap's simulator).
"""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import blurtrap as bt
from blurtrap.physics._effects import water_viscosity

KT = 1.380649e-23 * 295.0
R = 1.53e-6
GAMMA = 6 * math.pi * float(water_viscosity(295.0)) * R
K = 5e-5
DT = 1 / 1500


@pytest.fixture(scope="module")
def x():
    rng = np.random.default_rng(3)
    sig = math.sqrt(KT / K)
    rho = math.exp(-DT * K / GAMMA)
    e = rng.standard_normal(4096) * sig * math.sqrt(1.0 - rho * rho)
    e[0] = rng.standard_normal() * sig
    return lfilter([1.0], [1.0, -rho], e) + 0.1 * sig * rng.standard_normal(4096)


def _fit(x, meta, scale=1.0):
    rec = bt.Recording(x * scale, frame_interval=DT, exposure=1e-5, metadata=meta)
    return bt.calibrate(rec, method="likelihood", likelihood="exact")


def _stokes(res):
    return [n for n in res.notes if "Stokes friction" in n]


def test_gamma_consistent_with_stokes_is_not_flagged(x):
    assert _stokes(_fit(x, {"bead_radius_m": R})) == []
    assert _stokes(_fit(x, {})) == []  # no radius: nothing to compare with


@pytest.mark.parametrize("meta,scale,ratio", [
    ({"bead_radius_m": 10 * R}, 1.0, 0.1),  # radius wrong by 10x
    ({"bead_radius_m": R / 5}, 1.0, 5.0),
    ({"bead_radius_m": R}, 2.0, 0.25),  # positions 2x too large: k and gamma / 4
    ({"bead_radius_m": R, "viscosity_Pa_s": 0.1}, 1.0, 0.0096),  # glycerol-like viscosity
])
def test_gamma_far_from_stokes_is_flagged(x, meta, scale, ratio):
    res = _fit(x, meta, scale)
    (note,) = _stokes(res)
    got = res.gamma / (6 * math.pi * meta.get("viscosity_Pa_s", water_viscosity(295.0))
                       * meta["bead_radius_m"])
    assert got == pytest.approx(ratio, rel=0.5)
    assert f"{got:.3g} x the Stokes friction" in note
    assert f"r = {meta['bead_radius_m']:.4g} m" in note


@pytest.mark.parametrize("rad", [-1e-6, 0.0, float("nan"), "1.5um", True, 1.53])
def test_bad_bead_radius_is_refused(x, rad):
    rec = bt.Recording(x, frame_interval=DT, exposure=1e-5, metadata={"bead_radius_m": rad})
    with pytest.raises(ValueError, match=r"metadata\['bead_radius_m'\]"):
        bt.calibrate(rec, method="equipartition")
