"""x/y calibration with positions in volts (and in every length unit the loaders take): the
statistics of the data (eigenvalue gap of the frame covariance, lag-1 coupling, the frame
covariance itself) must be in metres like the model's autocovariances. An independent pass
found them in volts: correct data got a coupling note at z ~ 1e13 and an isotropic trap came
back 'resolved' (gap 1/Rd^2 too large). Frames from tests/_xy_gen.py (exact frame law of
exposure-averaged OU per principal axis, numpy only)."""

import math
import os
import re
import sys

import numpy as np
import pytest

import blurtrap as bt

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))
from _xy_gen import xy_frames  # noqa: E402

GAMMA, ETA, DT, W, EPS, N = 1e-8, 9.3e-4, 1e-4, 8e-5, 3e-9, 16384
RD = 2e-7  # true displacement sensitivity [m/V]
#: the bead whose Stokes friction is GAMMA (volts need the friction for Rd)
MD = {"bead_radius_m": GAMMA / (6 * math.pi * ETA), "viscosity_Pa_s": ETA, "friction": "stokes",
      "hydrodynamics": False}
COUPLED = "principal axes are coupled"


def _frames(seed, k1, k2, phi, gain=1.0):
    x, y = xy_frames(N, k1, k2, GAMMA, W, DT, phi, EPS, np.random.default_rng(seed))
    return x, gain * y


def _metres(x, y):
    return bt.xy_from_arrays(x, y, frame_interval=DT, exposure=W)


def _volts(x, y):
    return bt.xy_from_arrays(x / RD, y / RD, frame_interval=DT, exposure=W, position_unit="V",
                             metadata=MD)


def _rd(fit):
    """``(Rd, SE)`` [m/V] of a CalibrationResult."""
    p = fit["displacement_sensitivity"]
    return p.value, p.error


@pytest.mark.parametrize(("seed", "k1", "k2", "phi"), [
    (0, 3e-5, 3e-5, 0.5), (1, 3e-5, 3e-5, 0.0), (2, 2e-5, 5e-5, 0.5), (3, 2e-5, 5e-5, 0.0)])
def test_volts_statistics_match_metres(seed, k1, k2, phi):
    """Correct data in volts: the same anisotropy z as the data in metres (z compares the
    variance gap with the model's SE; both scale with the position unit squared), no coupling
    or disagreement note (null), the isotropic trap not resolved, the anisotropic one resolved
    with k1, k2 and Rd within 4 SE of the truth, and the frame covariance in m^2."""
    x, y = _frames(seed, k1, k2, phi)
    m = bt.calibrate_xy(_metres(x, y), separate=False)
    v = bt.calibrate_xy(_volts(x, y), separate=False)
    rd, rd_err = _rd(v.joint)
    assert abs(rd - RD) < 4 * rd_err, (rd, rd_err)
    assert v.anisotropy_z == pytest.approx(m.anisotropy_z, rel=1e-4, abs=1e-6)
    np.testing.assert_allclose(v.frame_covariance, m.frame_covariance * (rd / RD) ** 2,
                               rtol=1e-9)
    for r in (m, v):
        assert not any(COUPLED in n or "fitted together disagree" in n for n in r.notes), r.notes
    if k1 == k2:
        assert not v.resolved and v.anisotropy_z < 3.5
        assert any("phi is undefined" in n for n in v.notes)
    else:
        assert v.resolved and v.anisotropy_z > 3.5
        assert not any("phi is undefined" in n for n in v.notes)
        assert abs(v.k1 - k1) < 4 * v.k1_err and abs(v.k2 - k2) < 4 * v.k2_err
        wrapped = (v.phi - phi + math.pi / 2) % math.pi - math.pi / 2
        assert abs(wrapped) < 4 * v.phi_err


def _csv(path, x, y, unit, scale):
    t = np.arange(N) * DT
    rows = [f"t_s,x_{unit},y_{unit}"] + [f"{a!r},{b!r},{c!r}" for a, b, c in
                                         zip(t.tolist(), (x / scale).tolist(), (y / scale).tolist())]
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize(("unit", "scale"), [("nm", 1e-9), ("um", 1e-6), ("px", 7e-8), ("V", RD)])
def test_every_unit_gives_the_metres_statistics(tmp_path, unit, scale):
    """An isotropic trap loaded from CSV in nm, um, px (pixel_size_m) or V: the anisotropy z
    of the data in metres, not resolved, no coupling note."""
    x, y = _frames(7, 3e-5, 3e-5, 0.3)
    m = bt.calibrate_xy(_metres(x, y), separate=False)
    path = tmp_path / f"xy_{unit}.csv"
    _csv(path, x, y, unit, scale)
    xy = bt.load_xy_csv(path, exposure=W, frame_interval=DT, temperature=295.0,
                        pixel_size_m=scale if unit == "px" else None,
                        metadata=MD if unit == "V" else None)
    r = bt.calibrate_xy(xy, separate=False)
    assert r.anisotropy_z == pytest.approx(m.anisotropy_z, rel=1e-4, abs=1e-6)
    assert not r.resolved and not any(COUPLED in n for n in r.notes)


def _coupling_z(res):
    (note,) = [n for n in res.notes if COUPLED in n]
    found = re.search(r"lag-1 correlations ([-+0-9.e]+) and ([-+0-9.e]+) standard errors", note)
    assert found, note
    return float(found.group(1)), float(found.group(2))


def test_unequal_gains_in_volts_couple_at_the_metres_z():
    """y with 1.3x the x gain and the principal axes at 0.5 rad: the coupling note fires in
    volts as in metres, with the same finite z (not ~1e13)."""
    x, y = _frames(4, 2e-5, 5e-5, 0.5, gain=1.3)
    zm = _coupling_z(bt.calibrate_xy(_metres(x, y), separate=False))
    zv = _coupling_z(bt.calibrate_xy(_volts(x, y), separate=False))
    assert 4.5 < max(map(abs, zm)) < 100, zm
    np.testing.assert_allclose(zv, zm, rtol=1e-2, atol=0.2)


@pytest.mark.parametrize("unit", ["m", "V"])
def test_disagreement_names_unequal_gains(unit):
    """y with 1.5x the x gain and the principal axes along the detector's: the axes disagree
    on gamma and eps^2 (no lag-1 coupling). The note names unequal detector sensitivities,
    not another bead or exposure, and its gain ratio is within 4 SE of 1.5 (SE from the two
    single-axis fits: gamma in metres, Rd in volts)."""
    x, y = _frames(2, 2e-5, 5e-5, 0.0, gain=1.5)
    r = bt.calibrate_xy(_metres(x, y) if unit == "m" else _volts(x, y))
    (note,) = [n for n in r.notes if "fitted together disagree" in n]
    assert "on gamma" in note and "unequal detector sensitivities along x and y" in note
    assert "another bead" not in note and "shorter exposures" not in note
    assert not any(COUPLED in n for n in r.notes)
    ratio = float(re.search(r"need axis 2's gain ([0-9.]+) times", note).group(1))
    a, b = r.separate
    if unit == "m":
        rel = 0.5 * math.hypot(a.gamma_err / a.gamma, b.gamma_err / b.gamma)
    else:
        (ra, ea), (rb, eb) = _rd(a), _rd(b)
        rel = math.hypot(ea / ra, eb / rb)
    assert abs(ratio - 1.5) < 4 * rel * ratio + 0.005, (ratio, rel)
