"""Active calibration of a bead with hydrodynamic friction (Tolic-Norrelykke et al. 2006,
appendix D): the drive response ``H(f_d)`` with ``gamma(f)`` and the bead's inertia.

References independent of blurtrap's hydrodynamics code: eqs. (D3), (D4) and (D6) evaluated in
mpmath below, and end-to-end traces from tests/_hydro_gen.py (NumPy spectral synthesis of
Berg-Sorensen & Flyvbjerg 2004 eq. 12 plus the drive's peak with the amplitude and phase of
eq. D3).
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from _hydro_gen import drive_response_d3, generate_hydro_driven

import blurtrap as bt
from blurtrap.effects import make_effect
from blurtrap.inference._active import displacement_sensitivity, fluid_response
from blurtrap.inference._hydro_drive import drive_friction
from blurtrap.inference._instrument import prepare_instrument
from blurtrap.inference._models import get_model

T = 295.0
ETA, RHO_F, RHO_B = 0.957812e-3, 997.803, 1050.0  # water at 295 K, polystyrene
mpmath.mp.dps = 40


def _tn_response(f, k, radius, distance=None, eta=ETA, rho_f=RHO_F, rho_b=RHO_B):
    """``x/x_s`` of TN 2006 in their ``e^{-i w t}`` convention, in mpmath: ``g`` of eq. (D4)
    (bulk) or (D6) (a wall at ``distance``), ``gamma_0 = 6 pi eta R``,
    ``f_c = k/(2 pi gamma_0)``, ``f_m = gamma_0/(2 pi m_bead)``; ``|x/x_s|^2`` is eq. (D3)'s
    ``f^2 |g|^2 / ((f_c + f Im g - f^2/f_m)^2 + (f Re g)^2)``."""
    f, r = mpmath.mpf(f), mpmath.mpf(radius)
    eta, rho_f, rho_b = mpmath.mpf(eta), mpmath.mpf(rho_f), mpmath.mpf(rho_b)
    gamma0 = 6 * mpmath.pi * eta * r
    f_nu = eta / (mpmath.pi * rho_f * r**2)
    s = mpmath.sqrt(f / f_nu)
    g = 1 + (1 - 1j) * s - 2j / 9 * s**2
    if distance is not None:
        h = mpmath.mpf(distance)
        eps = (2 * h - r) / r * s
        g = g / (1 - 9 * r / (16 * h) * (1 - (1 - 1j) / 3 * s + 2j / 9 * s**2
                                          - 4 * (1 - mpmath.exp(-(1 - 1j) * eps)) / 3))
    fc = mpmath.mpf(k) / (2 * mpmath.pi * gamma0)
    f_m = gamma0 / (2 * mpmath.pi * 4 * mpmath.pi * r**3 * rho_b / 3)
    resp = -1j * f * g / (fc - f**2 / f_m - 1j * f * g)
    d3 = f**2 * abs(g)**2 / ((fc + f * g.imag - f**2 / f_m)**2 + (f * g.real)**2)
    assert abs(abs(resp)**2 / d3 - 1) < mpmath.mpf(10)**-30
    return resp, gamma0, fc


def _blurtrap_response(f, k, radius, distance=None, fc_shift=0.0):
    """blurtrap's ``H`` (``e^{+i w t}``) at the zero-frequency friction of eq. D6."""
    eff = make_effect("hydrodynamics", distance=distance, viscosity=ETA, fluid_density=RHO_F,
                      bead_density=RHO_B)
    gamma = 6 * math.pi * ETA * radius
    if distance is not None:
        gamma /= 1 - 9 * radius / (16 * distance)
    g, f_m = drive_friction(eff, radius, T, f, gamma)
    return fluid_response(f, k / (2 * math.pi * gamma) + fc_shift, g, f_m), gamma


@pytest.mark.parametrize("radius,distance", [(1.5e-6, None), (2.5e-6, None),
                                             (1.5e-6, 4.5e-6), (2.0e-6, 3.1e-6)])
@pytest.mark.parametrize("f_d", [32.0, 300.0, 3000.0])
def test_response_matches_tn_d3_d4_d6_in_mpmath(radius, distance, f_d):
    k = 1.2e-4
    ref, gamma0, _ = _tn_response(f_d, k, radius, distance)
    (h, dlog, darg), gamma = _blurtrap_response(f_d, k, radius, distance)
    ref = complex(mpmath.conj(ref))  # e^{-i w t} -> blurtrap's e^{+i w t}
    np.testing.assert_allclose([h.real, h.imag], [ref.real, ref.imag], rtol=1e-11,
                               atol=1e-12 * abs(ref))
    # not the Lorentzian at the same f_c, by 1e8 times the tolerance above (H/H_lorentz - 1:
    # 2 % at 32 Hz, 6 % at 300 Hz for 1.5 um in bulk; near the wall D6 flattens gamma(f):
    # 0.1 % at 3 kHz, 1.55 radii out)
    lor = fluid_response(f_d, k / (2 * math.pi * gamma))[0]
    assert abs(h / lor - 1) > 1e-3
    # the slopes in f_c against mpmath's numerical derivative of eq. D3 (f_c of D3 is
    # blurtrap's f_c times the zero-frequency factor of D6: the same derivative scaled)
    scale = 1.0 if distance is None else 1 / (1 - 9 * radius / (16 * distance))

    def ln_abs(kk):
        return mpmath.log(abs(_tn_response(f_d, kk, radius, distance)[0]))

    def arg(kk):
        return mpmath.arg(mpmath.conj(_tn_response(f_d, kk, radius, distance)[0]))

    dk_dfc = 2 * math.pi * gamma0 * scale
    assert dlog == pytest.approx(float(mpmath.diff(ln_abs, k)) * dk_dfc, rel=1e-9)
    assert darg == pytest.approx(float(mpmath.diff(arg, k)) * dk_dfc, rel=1e-9)


def test_generator_response_is_tn_d3():
    """The end-to-end generator's peak (NumPy) against the mpmath eq. D3 above."""
    for f_d in (32.0, 300.0):
        ref = complex(mpmath.conj(_tn_response(f_d, 1.5e-4, 2e-6)[0]))
        got = drive_response_d3(f_d, 1.5e-4, 2e-6, ETA, RHO_F, RHO_B)
        assert abs(got / ref - 1) < 1e-12


@pytest.mark.parametrize("f_d", [0.5, 32.0])
def test_small_bead_or_low_frequency_gives_the_lorentzian(f_d):
    """A 20 nm bead (f_nu ~ 760 MHz) or f_d << f_nu: the Lorentzian ``i f/(f_c + i f)``; the
    difference is the leading ``sqrt(f/f_nu)`` term (it halves when f/f_nu falls 4x)."""
    k = 1e-5
    devs = []
    for radius in (20e-9, 80e-9):
        (h, _, _), gamma = _blurtrap_response(f_d, k, radius)
        fc = k / (2 * math.pi * gamma)
        lor = 1j * f_d / (fc + 1j * f_d)
        s = math.sqrt(f_d * math.pi * RHO_F * radius**2 / ETA)
        dev = abs(h / lor - 1)
        assert dev < 2 * s, (dev, s)
        devs.append(dev)
    assert devs[1] / devs[0] == pytest.approx(4.0, rel=0.05)  # R 4x: sqrt(f/f_nu) 4x
    # the defaults are exactly the Lorentzian
    fc = 700.0
    assert fluid_response(f_d, fc)[0] == 1j * f_d / (fc + 1j * f_d)


def test_displacement_sensitivity_with_friction_and_phase_check():
    """Rd, its SE and the phase check with the hydrodynamic H: a ratio made from the TN
    response gives Rd back and no phase mismatch; the Lorentzian H misreads both."""
    radius, k, f_d, w, rd = 2e-6, 1.5e-4, 300.0, 0.0, 1e-7
    (h, dlog, darg), gamma = _blurtrap_response(f_d, k, radius)
    fc = k / (2 * math.pi * gamma)
    eff = make_effect("hydrodynamics", viscosity=ETA, fluid_density=RHO_F)
    g, f_m = drive_friction(eff, radius, T, f_d, gamma)
    ratio = complex(mpmath.conj(_tn_response(f_d, k, radius)[0])) / rd
    out = displacement_sensitivity(ratio, 1e-3 * abs(ratio), fc, 10.0, f_d, w, friction=g,
                                   dissipation_frequency=f_m)
    assert out.value == pytest.approx(rd, rel=1e-12)
    assert abs(out.phase_mismatch) < 1e-12
    assert out.se == pytest.approx(rd * math.hypot(1e-3, dlog * 10.0), rel=1e-12)
    assert out.phase_mismatch_se == pytest.approx(math.hypot(1e-3, darg * 10.0), rel=1e-12)
    old = displacement_sensitivity(ratio, 1e-3 * abs(ratio), fc, 10.0, f_d, w)
    assert old.value / rd - 1 < -0.05 and abs(old.phase_mismatch) > 0.02
    for bad, msg in ((complex("nan"), "friction must be"), (-1.0, "friction must be")):
        with pytest.raises(ValueError, match=msg):
            displacement_sensitivity(ratio, 0.0, fc, 0.0, f_d, w, friction=bad)
    with pytest.raises(ValueError, match="dissipation_frequency"):
        displacement_sensitivity(ratio, 0.0, fc, 0.0, f_d, w, friction=g,
                                 dissipation_frequency=0.0)


# ---- end to end: an anti-aliased photodiode in volts, R = 2 um, stage drive -------------------
R, FS, K, RD, N = 2.0e-6, 78125.0, 1.5e-4, 1e-7, 2**17
GAMMA0 = 6 * math.pi * ETA * R


def _driven(f_d, seed, volts=True):
    x, stage = generate_hydro_driven(N, FS, K, R, seed, amplitude=200e-9, frequency=f_d,
                                     eta=ETA, rho_f=RHO_F, rho_b=RHO_B, tracking_std=0.5e-9,
                                     stage_noise=1e-9)
    return bt.Recording(positions=x / RD if volts else x, frame_interval=1 / FS,
                        exposure=1 / FS, temperature=T, stage=stage,
                        position_unit="V" if volts else "m",
                        metadata=dict(detector="photodiode", anti_aliasing=True,
                                      bead_radius_m=R, viscosity_Pa_s=ETA,
                                      fluid_density_kg_per_m3=RHO_F,
                                      drive={"frequency_Hz": f_d}))


def _z(res, name, truth):
    i = res.param_names.index(name)
    return (res.values[i] - truth) / math.sqrt(res.covariance[i, i])


@pytest.mark.parametrize("f_d,seed", [(32.0, 0), (300.0, 1)])
def test_active_photodiode_recovers_rd_gamma_k(f_d, seed):
    """2^17 samples at 78.125 kHz (1.7 s), f_c ~ 600 Hz, drive 200 nm. Corrected ("auto"
    turns it on): Rd, gamma, k within 3 SE (measured |z| < 1.5 on these seeds). Ignoring the
    hydrodynamics biases Rd by ~+30 % (32 Hz) / ~+15 % (300 Hz), 8-10 SE; at 300 Hz the drive
    response's own correction (the passive fit corrected) is ~7 %, > 3 SE of Rd."""
    rec = _driven(f_d, seed)
    on = bt.calibrate(rec)
    assert any(n.startswith("hydrodynamics: on (auto: ignoring it would bias Rd")
               for n in on.notes), on.notes
    truth = {"displacement_sensitivity": RD, "gamma": GAMMA0, "k": K,
             "force_sensitivity": K * RD}
    zs = {n: _z(on, n, v) for n, v in truth.items()}
    assert max(abs(z) for z in zs.values()) < 3.0, zs
    off = bt.calibrate(rec, hydrodynamics=False)
    assert _z(off, "displacement_sensitivity", RD) > 5.0
    if f_d == 300.0:
        # the same passive fit with the Lorentzian drive response: Rd off by > 3 SE
        names = list(on.param_names)
        fc = on.values[names.index("k")] / (2 * math.pi * on.values[names.index("gamma")])
        h1 = drive_response_d3(f_d, 2 * math.pi * GAMMA0 * fc, R, ETA, RHO_F, RHO_B)
        rd_lor = RD * abs(1j * f_d / (fc + 1j * f_d)) / abs(h1)
        i = names.index("displacement_sensitivity")
        assert (RD - rd_lor) / math.sqrt(on.covariance[i, i]) > 3.0


def test_drive_check_in_metres_agrees_with_the_hydrodynamic_response():
    """Positions in metres: the drive checks the position scale (1 within 3 SE); with the
    Lorentzian response it would read ~7 % low at 300 Hz."""
    on = bt.calibrate(_driven(300.0, 2, volts=False), hydrodynamics=True)
    note = next(n for n in on.notes if n.startswith("drive: the stage drive gives"))
    assert "SE from 1)" in note and "disagree" not in note, note


def test_volts_active_plan_uses_the_beads_friction_for_inertia():
    """In volts the fitted gamma is in V units: the effect carries the bead's Stokes friction
    (its inertia and the drive response's added mass), and hydrodynamics=True is accepted."""
    t = np.arange(4096) / FS
    stage = 200e-9 * np.sin(2 * np.pi * 300.0 * t)
    # white frames with a response to the drive (a drive that never reached the bead is
    # refused: check_drive_response)
    x = (1e-8 * np.random.default_rng(0).standard_normal(4096) + 0.5 * stage) / RD
    rec = bt.Recording(positions=x, frame_interval=1 / FS, exposure=1 / FS, temperature=T,
                       stage=stage, position_unit="V",
                       metadata=dict(detector="photodiode", anti_aliasing=True, bead_radius_m=R,
                                     viscosity_Pa_s=ETA, drive={"frequency_Hz": 300.0}))
    plan = prepare_instrument([rec], get_model(None), False, "auto", hydrodynamics=True)
    eff = next(e for e in plan.model.extra if e.name == "hydrodynamics")
    assert eff.bead_friction == pytest.approx(GAMMA0, rel=1e-12)
    assert any("drive response with the same friction" in n for n in plan.notes)
