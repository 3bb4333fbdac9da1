"""calibrate(..., hydrodynamics=...): frequency-dependent friction of a known bead.

References are independent of blurtrap's physics: Berg-Sorensen & Flyvbjerg (2004) eq. (12)
in NumPy and Tolic-Norrelykke et al. (2006) eqs. (D2)/(D6) in mpmath (tests/_hydro_gen.py);
the end-to-end data come from a NumPy spectral-synthesis generator of that PSD.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from _hydro_gen import BOLTZMANN, generate_hydro, hydro_psd_bsf, hydro_psd_d6
from _instrument_gen import generate

import blurtrap as bt
from blurtrap._config import float64_scope
from blurtrap.inference._instrument import prepare_instrument
from blurtrap.inference._models import get_model

T = 295.0
ETA_W, RHO_W = 0.957812e-3, 997.803  # water at 295 K (IAPWS 2008, Kell)
R = 1.5e-6
FS = 78125.0
K = 1e-4  # N/m (0.1 pN/nm): f_c ~ 590 Hz with R = 1.5 um
GAMMA0 = 6 * math.pi * ETA_W * R


def _photodiode(x, **meta):
    md = dict(detector="photodiode", anti_aliasing=True, bead_radius_m=R, **meta)
    return bt.Recording(positions=x, frame_interval=1 / FS, exposure=1 / FS, temperature=T,
                        metadata=md)


@float64_scope
def _plan_psd(rec, f, k, gamma, **kw):
    plan = prepare_instrument([rec], get_model(None), False, "auto", hydrodynamics=True, **kw)
    assert plan.model.has("hydrodynamics") and plan.fixed["hydro_radius"][0] == R
    out = plan.model.psd(np.asarray(f)[None, :], np.array([k]), gamma, 0.0,
                         np.array([1 / FS]), np.array([1 / FS]), np.array([T]),
                         extras={"hydro_radius": plan.fixed["hydro_radius"][0]})
    return np.asarray(out)[0], plan


@pytest.mark.parametrize("eta,rho_f,rho_b", [(None, None, None), (1.3e-3, 1100.0, 1500.0)])
def test_model_spectrum_bulk_matches_bsf_eq12(eta, rho_f, rho_b):
    x = 1e-8 * np.random.default_rng(0).standard_normal(4096)
    meta = {k: v for k, v in (("viscosity_Pa_s", eta), ("fluid_density_kg_per_m3", rho_f),
                              ("bead_density_kg_per_m3", rho_b)) if v is not None}
    e, rf, rb = eta or ETA_W, rho_f or RHO_W, rho_b or 1050.0
    gamma = 6 * math.pi * e * R
    f = np.geomspace(1.0, 0.5 * FS, 60)
    got, _ = _plan_psd(_photodiode(x, **meta), f, K, gamma)
    ref = hydro_psd_bsf(f, K, R, T, e, rf, rb)
    np.testing.assert_allclose(got, ref, rtol=2e-6)
    # the correction is not small at the top of the band (so the check can fail)
    lor = BOLTZMANN * T / gamma / (2 * math.pi**2) / ((K / (2 * math.pi * gamma))**2 + f**2)
    assert np.max(np.abs(ref / lor - 1)) > 0.1


def test_model_spectrum_near_wall_matches_d6():
    x = 1e-8 * np.random.default_rng(0).standard_normal(4096)
    h = 3.0 * R
    f = np.geomspace(1.0, 0.5 * FS, 25)
    gamma = GAMMA0 / (1 - 9 * R / (16 * h))  # zero-frequency limit of D6
    got, _ = _plan_psd(_photodiode(x, distance_to_surface_m=h), f, K, gamma)
    np.testing.assert_allclose(got, hydro_psd_d6(f, K, R, T, ETA_W, RHO_W, 1050.0, h),
                               rtol=1e-6)


def test_volts_inertia_uses_known_friction():
    """In volts the fitted gamma is in V units: the bead's inertia must use the known one."""
    rd = 1e-7  # m/V
    x = 1e-8 / rd * np.random.default_rng(0).standard_normal(4096)
    rec = bt.Recording(positions=x, frame_interval=1 / FS, exposure=1 / FS, temperature=T,
                       position_unit="V", metadata=dict(detector="photodiode", anti_aliasing=True,
                                                        bead_radius_m=R, friction="stokes"))
    f = np.geomspace(1.0, 0.5 * FS, 40)
    got, plan = _plan_psd(rec, f, K * rd**2, GAMMA0 * rd**2)
    assert plan.gamma_known is not None
    np.testing.assert_allclose(got * rd**2, hydro_psd_bsf(f, K, R, T, ETA_W, RHO_W, 1050.0),
                               rtol=2e-6)


def _z(res, name, truth):
    i = res.param_names.index(name)
    return (res.values[i] - truth) / math.sqrt(res.covariance[i, i])


@pytest.mark.parametrize("friction", ["free", "stokes"])
def test_photodiode_fit_unbiased_with_and_biased_without(friction):
    """3 seeds, 2^17 samples at 78.125 kHz, R = 1.5 um: with the correction k and gamma within
    3 SE of the truth; without it gamma is +23 % off (~26 SE, friction free) and k is
    ~ -1.7 % off with gamma held (about 1 SE per record: shown paired, on the same traces)."""
    zs_on, zs_off, shift = [], [], []
    names = ["k"] + (["gamma"] if friction == "free" else [])
    truth = {"k": K, "gamma": GAMMA0}
    for seed in range(3):
        x = generate_hydro(2**17, FS, K, R, seed, eta=ETA_W, rho_f=RHO_W, tracking_std=0.5e-9)
        rec = _photodiode(x, friction=friction)
        on = bt.calibrate(rec)  # "auto"
        assert any(n.startswith("hydrodynamics: on (auto") for n in on.notes), on.notes
        off = bt.calibrate(rec, hydrodynamics=False)
        assert "hydro_radius" not in off.param_names
        zs_on += [_z(on, n, truth[n]) for n in names]
        zs_off.append(_z(off, names[-1], truth[names[-1]]))
        shift.append(off.values[0] / on.values[0] - 1)
    assert max(abs(z) for z in zs_on) < 3.0, zs_on
    if friction == "free":
        assert min(zs_off) > 5.0, zs_off  # gamma without the correction
    else:
        assert max(shift) < -0.005, shift  # k without the correction, paired


@float64_scope
def _auto_note(rec, hydrodynamics=None):
    plan = prepare_instrument([rec], get_model(None), False, "auto",
                              hydrodynamics=hydrodynamics)
    return plan.model.has("hydrodynamics"), [n for n in plan.notes
                                             if n.startswith("hydrodynamics")]


def test_auto_on_for_photodiode_off_for_1khz_camera():
    x = generate_hydro(2**17, FS, K, R, 7, eta=ETA_W, rho_f=RHO_W, tracking_std=0.5e-9)
    on, note = _auto_note(_photodiode(x))
    assert on and "on (auto" in note[0], note
    dt = 1e-3
    (pos,), _ = generate(K, GAMMA0, dt, dt, 2**14, 3, temperature=T)
    cam = bt.Recording(positions=pos, frame_interval=dt, exposure=dt, temperature=T,
                       metadata=dict(detector="camera", bead_radius_m=R))
    on, note = _auto_note(cam)
    assert not on and "off (auto)" in note[0], note
    # no bead radius: nothing changes and nothing is said
    cam = bt.Recording(positions=pos, frame_interval=dt, exposure=dt, temperature=T,
                       metadata=dict(detector="camera"))
    assert _auto_note(cam) == (False, [])


def test_setting_from_metadata_and_argument_wins():
    x = generate_hydro(2**12, FS, K, R, 1)
    rec = _photodiode(x, hydrodynamics=False)
    on, note = _auto_note(rec)
    assert not on and note == ["hydrodynamics: off (hydrodynamics=False): friction "
                               "independent of frequency"]
    on, note = _auto_note(rec, hydrodynamics=True)
    assert on and note[0].startswith("hydrodynamics: on (hydrodynamics=True)")
    # an explicit exact likelihood keeps "auto" off (the closed-form model), with a note
    plan = float64_scope(prepare_instrument)([_photodiode(x)], get_model(None), False, "auto",
                                             likelihood="exact")
    assert not plan.model.has("hydrodynamics")
    assert any(n.startswith("hydrodynamics: off (auto): the exact") for n in plan.notes)


@pytest.mark.parametrize("kw,msg", [
    (dict(hydrodynamics="yes"), "hydrodynamics must be None"),
    (dict(hydrodynamics=1), "hydrodynamics must be None"),
    (dict(hydrodynamics=True, method="equipartition"), "spectral fits"),
    (dict(hydrodynamics=True, likelihood="exact"), "exact time-domain likelihood"),
])
def test_bad_arguments(kw, msg):
    x = generate_hydro(2**12, FS, K, R, 1)
    with pytest.raises(ValueError, match=msg):
        bt.calibrate(_photodiode(x), **kw)


def test_bad_settings():
    x = generate_hydro(2**12, FS, K, R, 1)
    rec = bt.Recording(positions=x, frame_interval=1 / FS, exposure=1 / FS, temperature=T)
    with pytest.raises(ValueError, match="needs the bead radius"):
        bt.calibrate(rec, hydrodynamics=True)
    with pytest.raises(ValueError, match="distance_to_surface_m = .* below 1.5 bead radii"):
        bt.calibrate(_photodiode(x, distance_to_surface_m=1.2 * R), hydrodynamics=True)
    with pytest.raises(ValueError, match="recording.*hydrodynamics must be"):
        bt.calibrate(_photodiode(x, hydrodynamics="on"))
    with pytest.raises(ValueError, match="viscosity must be a finite number > 0"):
        bt.effects.Hydrodynamics(viscosity=-1.0)
