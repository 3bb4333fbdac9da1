"""Active calibration of a bead near a surface, end to end: manifest -> ``blurtrap calibrate
--json``, positions in volts, a recorded stage drive, the bead's radius and distance to the
surface given, so Rd, gamma, k and Rf are all results (Tolic-Norrelykke et al. 2006, eqs. D2,
D3 and D6).

The traces come from tests/_wall_gen.py (numpy only: spectral synthesis of eq. D2 with the
near-wall friction of eq. D6, plus the drive's response of eq. D3 with the same friction),
checked here against mpmath (tests/_hydro_gen.hydro_psd_d6 and the equations written out
below). Tolerances: the fit's own standard errors (3 SE), or machine precision for the
generator.
"""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest
from _hydro_gen import drive_response_d3, hydro_psd_bsf, hydro_psd_d6
from _wall_gen import (
    generate_wall_driven,
    wall_drive_response,
    wall_psd,
    zero_frequency_friction,
)

import blurtrap as bt
from blurtrap.cli import main

T = 295.0
ETA, RHO_F, RHO_B = 0.957812e-3, 997.803, 1050.0  # water at 295 K, polystyrene
R, FS, K, RD, N = 2.0e-6, 78125.0, 1.5e-4, 1e-7, 2**17


def _d3_d6_mpmath(f, k, radius, distance):
    """``x/x_s`` of eq. D3 with eq. D6's friction in the paper's ``e^{-i w t}`` convention,
    in mpmath (40 digits)."""
    with mpmath.workdps(40):
        f, r, h = mpmath.mpf(f), mpmath.mpf(radius), mpmath.mpf(distance)
        gamma0 = 6 * mpmath.pi * ETA * r
        s = mpmath.sqrt(f * mpmath.pi * RHO_F * r**2 / ETA)
        eps = (2 * h - r) / r * s
        g = (1 + (1 - 1j) * s - 2j / 9 * s**2) / (
            1 - 9 * r / (16 * h) * (1 - (1 - 1j) / 3 * s + 2j / 9 * s**2
                                     - 4 * (1 - mpmath.exp(-(1 - 1j) * eps)) / 3))
        fc = k / (2 * mpmath.pi * gamma0)
        f_m = gamma0 / (2 * mpmath.pi * 4 * mpmath.pi * r**3 * RHO_B / 3)
        return complex(-1j * f * g / (fc - f**2 / f_m - 1j * f * g))


@pytest.mark.parametrize("distance", [1.6 * R, 2.0 * R, 5.0 * R])
def test_wall_generator_against_mpmath(distance):
    """The numpy generator's PSD (eq. D2 + D6) and drive response (eq. D3 + D6) against
    mpmath; the bulk limit against the bulk generator (eqs. 12 of BSF 2004 and D3 + D4)."""
    f = np.array([1.0, 32.0, 300.0, 3e3, 3e4])
    ref = hydro_psd_d6(f, K, R, T, ETA, RHO_F, RHO_B, distance)
    np.testing.assert_allclose(wall_psd(f, K, R, T, ETA, RHO_F, RHO_B, distance), ref,
                               rtol=1e-12)
    for fd in (32.0, 300.0):
        want = np.conj(_d3_d6_mpmath(fd, K, R, distance))
        got = wall_drive_response(fd, K, R, ETA, RHO_F, RHO_B, distance)
        assert abs(got / want - 1) < 1e-12
        bulk = wall_drive_response(fd, K, R, ETA, RHO_F, RHO_B)
        assert abs(bulk / drive_response_d3(fd, K, R, ETA, RHO_F, RHO_B) - 1) < 1e-13
        assert abs(got / bulk - 1) > 1e-3  # the wall changes the response
    np.testing.assert_allclose(wall_psd(f, K, R, T, ETA, RHO_F, RHO_B),
                               hydro_psd_bsf(f, K, R, T, ETA, RHO_F, RHO_B), rtol=1e-12)
    # gamma(0) of eq. D6: Faxen to first order in R/h
    assert zero_frequency_friction(R, ETA, distance) == pytest.approx(
        6 * math.pi * ETA * R / (1 - 9 / 16 * R / distance), rel=1e-15)


def _manifest(tmp_path, x, stage, f_d, distance, name):
    meta = {"detector": "photodiode", "anti_aliasing": True, "bead_radius_m": R,
            "viscosity_Pa_s": ETA, "fluid_density_kg_per_m3": RHO_F,
            "drive": {"frequency_Hz": f_d}}
    if distance is not None:
        meta["distance_to_surface_m"] = distance
    rec = bt.Recording(positions=x / RD, frame_interval=1 / FS, exposure=1 / FS,
                       temperature=T, stage=stage, position_unit="V", metadata=meta)
    path = tmp_path / name
    bt.save_manifest(rec, path)
    return path


def _cli_json(path, capsys):
    code = main(["calibrate", str(path), "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    return json.loads(out)


# (h / R, drive frequency, seed): gamma(0)/gamma_0 = 1.39 at h = 2R, 1.54 at h = 1.6R
CASES = [(2.0, 32.0, 0), (1.6, 300.0, 1), (1.6, 32.0, 3)]


@pytest.mark.parametrize("h_over_r,f_d,seed", CASES)
def test_near_wall_active_calibration_from_the_manifest(tmp_path, capsys, h_over_r, f_d, seed):
    """2^17 samples at 78.125 kHz (1.7 s), R = 2 um, k = 0.15 pN/nm, 200 nm drive, Rd = 100
    nm/V. With the distance given: Rd, gamma (the zero-frequency friction of eq. D6), k and
    Rf within 3 SE (measured |z| <= 1.7 on these seeds; SEs ~2.3 % for Rd, ~4.5 % gamma).
    With the wall ignored (distance not given, bulk friction): Rd off by -27 % (-17.7 SE),
    -13 % (-9.3 SE), -26 % (-15.7 SE) on the three cases, k by +89 %, +24 %, +73 %."""
    h = h_over_r * R
    x, stage = generate_wall_driven(N, FS, K, R, seed, amplitude=200e-9, frequency=f_d,
                                    distance=h, eta=ETA, rho_f=RHO_F, rho_b=RHO_B,
                                    tracking_std=0.5e-9, stage_noise=1e-9)
    gamma = zero_frequency_friction(R, ETA, h)
    truth = {"displacement_sensitivity": RD, "gamma": gamma, "k": K, "force_sensitivity": K * RD}
    out = _cli_json(_manifest(tmp_path, x, stage, f_d, h, "wall.json"), capsys)
    z = {n: (out[n] - v) / out[f"{n}_err"] for n, v in truth.items()}
    assert max(abs(v) for v in z.values()) < 3.0, z
    assert any(n.startswith("hydrodynamics: on") and "from the surface (eq. D6)" in n
               for n in out["notes"]), out["notes"]
    assert any(n.startswith("volts: displacement sensitivity") and "stage drive" in n
               for n in out["notes"])
    # the wall ignored: the bulk friction in the fit and in the drive response
    bulk = _cli_json(_manifest(tmp_path, x, stage, f_d, None, "bulk.json"), capsys)
    z_rd = (bulk["displacement_sensitivity"] - RD) / bulk["displacement_sensitivity_err"]
    assert z_rd < -6.0, z_rd
    assert (bulk["k"] - K) / bulk["k_err"] > 3.0
