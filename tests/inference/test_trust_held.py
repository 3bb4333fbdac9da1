"""Held values and given constants are checked against physics and against the data.

- ``fixed`` values outside the plausible range of their quantity (a unit slip: SI into a
  lab-unit CLI option, or lab units in Python) are a ValueError naming the value in both.
- A held value the data disagree with (a bead diameter given as its radius with
  ``friction="stokes"``, a wrong ``fixed`` gamma) gets a note (a score test); a right one
  does not (false-alarm rate checked over seeds).
- Fitted k or gamma outside any trapped bead's range (positions in nm declared as um) get
  a note naming the likely unit.
- A given D that ``method="auto"`` does not use is said to be unused; equipartition says it
  assumes eps^2 = 0 and subtracts a held ``tracking_var``.

Traces: exact camera frames by circulant embedding of the frame autocovariance
(``tests/_circulant.py``, numpy only, not blurtrap's simulator).
"""

import math
import re

import numpy as np
import pytest
from _circulant import circulant_frames

import blurtrap as bt
from blurtrap.inference import FitError
from blurtrap.physics import stokes_friction, water_viscosity

KT = 1.380649e-23 * 295.0
R = 1e-6
GAMMA = float(stokes_friction(R, float(water_viscosity(295.0))))
K = 1e-5
DT = 1 / 1500
W = 1e-4
EPS2 = 4e-18  # 2 nm tracking error


def _rec(x, **meta):
    return bt.Recording(x, frame_interval=DT, exposure=W, metadata=meta)


@pytest.fixture(scope="module")
def x():
    return circulant_frames(K, GAMMA, W, DT, EPS2, 4096, seed=1)


def _held_notes(res):
    return [n for n in res.notes if n.startswith("held values disagree")
            or "fits the spectrum poorly" in n]


# --------------------------------------------------------------------------------------
# held values against the data
# --------------------------------------------------------------------------------------
def test_bead_diameter_given_as_radius_is_noted(x):
    right = bt.calibrate(_rec(x, bead_radius_m=R), friction="stokes")
    assert _held_notes(right) == []
    wrong = bt.calibrate(_rec(x, bead_radius_m=2 * R), friction="stokes")
    (note,) = _held_notes(wrong)
    assert "gamma = " in note and "favour a smaller value" in note
    assert "diameter" in note
    # the note matters: k is biased by many of its SEs with the held wrong gamma
    assert (wrong.k - K) / wrong.k_err > 3


@pytest.mark.parametrize("factor", [1.5, 0.6])
def test_wrong_fixed_gamma_is_noted_with_its_direction(x, factor):
    res = bt.calibrate(_rec(x), fixed={"gamma": factor * GAMMA})
    (note,) = _held_notes(res)
    assert ("smaller" if factor > 1 else "larger") in note


def test_held_value_far_off_is_named_by_the_goodness_of_fit(x):
    # k held 100x too small: locally the data say little about k there; the spectrum is
    # badly fitted and the note names the held value
    res = bt.calibrate(_rec(x), fixed={"k": K / 100})
    (note,) = _held_notes(res)
    assert "k = 1e-07 held" in note


def test_right_held_values_rarely_get_a_note():
    # 1 % false-alarm level per fit: among 12 independent datasets with the true gamma and
    # eps^2 held, at most 1 note (P(>= 2) < 0.7 % at the nominal level)
    recs = circulant_frames(K, GAMMA, W, DT, EPS2, 4096, seed=7, reps=6)
    n = sum(bool(_held_notes(bt.calibrate(_rec(r), fixed={"gamma": GAMMA})))
            for r in recs)
    n += sum(bool(_held_notes(bt.calibrate(_rec(r), fixed={"tracking_var": EPS2})))
             for r in recs)
    assert n <= 1


def test_refusal_with_held_values_names_them(x):
    with pytest.raises(FitError, match=r"Held in this fit: gamma = 1e-10 N s/m \(0.0001 pN "
                                       r"s/um\)"):
        bt.calibrate(_rec(x), fixed={"gamma": 1e-10})


# --------------------------------------------------------------------------------------
# held values against physics
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("fixed,match", [
    ({"gamma": 2.7e-14}, r"fixed\['gamma'\] = 2.7e-14 N s/m \(2.7e-08 pN s/um\)"),
    ({"gamma": 0.0095}, r"fixed\['gamma'\] = 0.0095 N s/m"),  # pN s/um given as SI
    ({"k": 50.0}, r"fixed\['k'\] = 50 N/m \(50000 pN/nm\)"),
    ({"k": 5e-14}, r"fixed\['k'\] = 5e-14 N/m"),
    ({"tracking_var": 4e-36}, r"fixed\['tracking_var'\] = 4e-36 m\^2 .* 0 \(negligible"),
    ({"tracking_var": 4.0}, r"fixed\['tracking_var'\] = 4 m\^2 \(4e\+18 nm\^2\)"),
])
def test_implausible_held_values_are_unit_slips(x, fixed, match):
    with pytest.raises(ValueError, match=match) as err:
        bt.calibrate(_rec(x), fixed=fixed)
    assert "unit slip" in str(err.value) and "--fix" in str(err.value)


def test_held_zero_tracking_error_is_plausible(x):
    res = bt.calibrate(_rec(x), fixed={"tracking_var": 0.0})
    assert res.params["tracking_var"] == 0.0


# --------------------------------------------------------------------------------------
# fitted values against physics: positions in another unit than declared
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("k,scale,declared,likely", [(5e-5, 1e9, "um", "nm"),
                                                     (5e-5, 1e3, "m", "mm"),
                                                     (2e-6, 1e6, "nm", "um")])
def test_fitted_values_outside_physics_name_the_unit(k, scale, declared, likely):
    # nm numbers declared as um: positions 1000x too large, k and gamma 1e6 too small. The
    # traps are chosen so that the positions' spread alone (std 9 nm x 1000 = 9 um; 45 nm /
    # 1000 = 0.045 nm) is still within what Recording accepts
    xs = circulant_frames(k, GAMMA, W, DT, EPS2, 4096, seed=2)
    rec = bt.from_arrays(xs * scale, frame_interval=DT, exposure=W, position_unit=declared)
    res = bt.calibrate(rec)
    (note,) = [n for n in res.notes if n.startswith("implausible")]
    assert f"declared in {declared!r}" in note and f"in {likely!r} they would be" in note
    eq = bt.calibrate(rec, method="equipartition")
    assert any(n.startswith("implausible") for n in eq.notes)


def test_fitted_values_in_range_get_no_unit_note(x):
    rec = bt.from_arrays(x * 1e9, frame_interval=DT, exposure=W, position_unit="nm")
    assert not any(n.startswith("implausible") for n in bt.calibrate(rec).notes)


# --------------------------------------------------------------------------------------
# a given D, and equipartition's tracking error
# --------------------------------------------------------------------------------------
def test_diffusion_unused_by_auto_is_said(x):
    res = bt.calibrate(_rec(x), diffusion=KT / GAMMA)
    assert res.method == "likelihood"
    assert any("the given D = " in n and "is not used" in n for n in res.notes)


@pytest.mark.parametrize("d", [1.5e-25, 1e-20])
def test_implausibly_small_diffusion_is_refused(x, d):
    with pytest.raises(ValueError, match=r"implausibly small .* um\^2/s"):
        bt.calibrate(_rec(x), method="equipartition", diffusion=d)


def test_equipartition_subtracts_a_held_tracking_error():
    # a stiff-ish camera case where eps^2 is a large part of the frame variance
    k, n = 2e-4, 65536
    xs = circulant_frames(k, GAMMA, W, DT, EPS2, n, seed=3)
    rec = _rec(xs)
    d = KT / GAMMA
    plain = bt.calibrate(rec, method="equipartition", diffusion=d)
    assert any("assumes no tracking error" in n for n in plain.notes)
    z_plain = (plain.k - k) / plain.k_err
    held = bt.calibrate(rec, method="equipartition", diffusion=d,
                        fixed={"tracking_var": EPS2})
    assert any("subtracted from the frame variance" in n for n in held.notes)
    assert not any("assumes no tracking error" in n for n in held.notes)
    assert z_plain < -5  # biased low without it
    assert abs((held.k - k) / held.k_err) < 4
    with pytest.raises(ValueError, match="not below the frame variance"):
        bt.calibrate(rec, method="equipartition", fixed={"tracking_var": 1e-12})
    with pytest.raises(ValueError, match="fixed = \\['gamma'\\] applies to the likelihood"):
        bt.calibrate(rec, method="equipartition", fixed={"gamma": GAMMA})


def test_naive_equipartition_notes_blur_and_tracking_noise(x):
    res = bt.calibrate(_rec(x), method="equipartition")
    assert any("biased high by motion blur" in n for n in res.notes)
    assert any("assumes no tracking error" in n for n in res.notes)
    assert math.isnan(res.gamma) and np.isfinite(res.k)


# --------------------------------------------------------------------------------------
# a step or drift of the mean position (the stationary models cannot hold it)
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def camera():
    k, gamma = 5e-5, 1.88e-8
    return k, circulant_frames(k, gamma, 1e-6, DT, EPS2, 65536, seed=1)


def test_step_is_named_in_the_notes_and_refusals(camera):
    k, xs = camera
    n = xs.size
    step = np.where(np.arange(n) > n // 2, 30e-9, 0.0)  # 3.3 x the std of the frames
    rec = bt.Recording(xs + step, frame_interval=DT, exposure=1e-6)
    res = bt.calibrate(rec, method="psd")
    (note,) = [s for s in res.notes if "is not stationary" in s]
    jump = float(re.search(r"a step: the mean jumps by ([0-9.e+-]+) m near frame 32768",
                           note).group(1))
    assert jump == pytest.approx(30e-9, rel=0.1)
    with pytest.raises(FitError, match="not stationary \\(a step") as err:
        bt.calibrate(rec)  # the default fit reads the step as a slow relaxation
    assert "nothing in the frames points" not in str(err.value)
    # the remedy the message names: a drift term absorbs the step, k is back in its errors
    fixed = bt.calibrate(rec, model="standard+drift")
    assert abs(fixed.k - k) < 3 * fixed.k_err
    assert not any("is not stationary" in s for s in fixed.notes)


def test_ramp_is_named_as_drift(camera):
    _, xs = camera
    ramp = np.linspace(0.0, 100e-9, xs.size)
    rec = bt.Recording(xs + ramp, frame_interval=DT, exposure=1e-6)
    for method in ("psd", "likelihood"):
        with pytest.raises(FitError, match="not stationary \\(a drift\\)"):
            bt.calibrate(rec, method=method)


@pytest.mark.parametrize("span", [20e-9, 1e-6])  # ~2 and ~100 x the frames' std (9 nm)
def test_gentle_and_steep_ramps_are_named_and_the_named_remedy_works(camera, span):
    # a 2-std ramp was blamed on "frames far less correlated than a freely diffusing
    # bead's" (lag-1 correlation below the free-diffusion level); a ramp steep enough to
    # dominate each of the 16 segments stretched the autocovariance past the test's lags
    # and was not named at all
    k, xs = camera
    rec = bt.Recording(xs + np.linspace(0.0, span, xs.size), frame_interval=DT, exposure=1e-6)
    with pytest.raises(FitError, match="not stationary \\(a drift\\)") as err:
        bt.calibrate(rec)
    assert "far less correlated" not in str(err.value)
    fixed = bt.calibrate(rec, model="standard+drift")
    assert abs(fixed.k - k) < 3 * fixed.k_err


def test_stationary_frames_raise_no_mean_shift():
    from blurtrap.inference._frames import mean_shift

    # 200 stationary records at two relaxation times: the test's p is calibrated (p < 0.01
    # in about 1 %) and none is flagged
    ps, flagged = [], 0
    for k in (5e-5, 2e-6):
        for x in circulant_frames(k, 1.88e-8, 1e-6, DT, EPS2, 65536, seed=11, reps=50):
            t = mean_shift(x)
            ps.append(t["p"])
            flagged += t["significant"]
    assert flagged == 0
    assert np.mean(np.array(ps) < 0.01) < 0.05
    # slow relaxation under white noise (which shortens a lag-1 estimate of tau, and so the
    # batch means, so that stationary records looked like drifting ones): no flag
    from scipy.signal import lfilter

    rng = np.random.default_rng(12)
    for tau in (30.0, 300.0, 2000.0):
        rho = math.exp(-1.0 / tau)
        for _ in range(10):
            y = lfilter([1.0], [1.0, -rho], rng.standard_normal(65536) * math.sqrt(1 - rho**2))
            t = mean_shift(y + math.sqrt(0.3) * rng.standard_normal(65536))
            assert t is None or not t["significant"], (tau, t)


# --------------------------------------------------------------------------------------
# recordings of different stiffness pooled into one k
# --------------------------------------------------------------------------------------
def test_pooling_recordings_of_different_stiffness_is_noted():
    g = 1.88e-8
    a = circulant_frames(5e-5, g, 1e-6, DT, EPS2, 8192, seed=1)
    b = circulant_frames(2e-5, g, 1e-6, DT, EPS2, 8192, seed=2)
    c = circulant_frames(5e-5, g, 1e-6, DT, EPS2, 8192, seed=3)

    def fit(*xs):
        return bt.calibrate([bt.Recording(x, frame_interval=DT, exposure=1e-6) for x in xs])

    (note,) = [s for s in fit(a, b).notes if "sharing one stiffness" in s]
    assert "recording 0" in note and "stiffer" in note
    assert "recording 1" in note and "softer" in note and "per_recording" in note
    assert not any("sharing one stiffness" in s for s in fit(a, c).notes)


def test_stiffness_not_proportional_to_power_is_noted_under_linear_power():
    # k = c (P - 30 mW) fitted as k = c P: gamma 4 SE off and k per power 20 SE off with no
    # note before; with k = c P itself no note
    g, powers = 1.88e-8, (0.05, 0.1, 0.15, 0.2)

    def fit(offset):
        recs = [bt.Recording(circulant_frames(5e-4 * (p - offset), g, 1e-6, DT, EPS2, 16384,
                                              seed=40 + i), frame_interval=DT, exposure=1e-6,
                             laser_power=p) for i, p in enumerate(powers)]
        return bt.calibrate(recs, k="linear_power")

    (note,) = [s for s in fit(0.03).notes if "k = c P does not fit" in s]
    assert "likelihood ratio" in note and "k='per_power'" in note
    # the per-power stiffnesses it quotes are the truth's, k = c (P - P0), within ~10 %
    number = r"([0-9]+\.?[0-9]*(?:e[+-]?[0-9]+)?)"
    quoted = [float(v) for v in re.findall(r"k\[P=[0-9.]+ mW\]: " + number, note)]
    np.testing.assert_allclose(quoted, [5e-4 * (p - 0.03) * 1e3 for p in powers], rtol=0.1)
    assert not any("k = c P does not fit" in s for s in fit(0.0).notes)


def test_a_misfit_shared_by_all_recordings_is_not_called_pooling():
    # both recordings below the joint spectrum at low frequency and above it elsewhere (a
    # model misfit they share): no pooling note; one above and one below: the note
    from blurtrap.inference._ml_fits import shared_k_note
    from blurtrap.inference._problems import make_layout

    recs = [bt.Recording(circulant_frames(5e-5, 1.88e-8, 1e-6, DT, EPS2, 512, seed=s),
                         frame_interval=DT, exposure=1e-6) for s in (1, 2)]
    layout = make_layout(recs, "shared", True)
    m = 4096
    low = np.arange(m) < m // 20
    one_side = np.where(low, 0.7, 1.3)
    w = np.ones((2, m))
    assert shared_k_note(layout, np.stack([one_side, one_side]), w, 1e-30) is None
    note = shared_k_note(layout, np.stack([one_side, np.where(low, 1.5, 0.8)]), w, 1e-30)
    assert note is not None and "stiffer" in note and "softer" in note
    assert shared_k_note(layout, np.stack([one_side, one_side]), w, 0.5) is None


def test_diagnose_refuses_white_frames_like_calibrate():
    # white noise (no trap relaxation resolved): calibrate refuses; diagnose must not call
    # the unidentifiable model "adequate"
    rng = np.random.default_rng(5)
    rec = bt.Recording(10e-9 * rng.standard_normal(16384), frame_interval=DT, exposure=W)
    with pytest.raises(FitError, match="cannot identify gamma"):
        bt.calibrate(rec)
    with pytest.raises(FitError, match="cannot identify gamma"):
        bt.diagnose(rec)


def test_diagnose_with_a_known_friction_refuses_white_frames_like_calibrate():
    # with friction='stokes' k follows from the blurred variance, which one exposure cannot
    # split from eps^2: calibrate refuses; diagnose called the unidentifiable model
    # "adequate" (its k moved 7-9 SE between candidates). A model without tracking noise
    # is identified: not refused (its fits compile ~60 s here, so the refusal is checked
    # directly)
    rng = np.random.default_rng(5)
    rec = bt.Recording(10e-9 * rng.standard_normal(16384), frame_interval=DT, exposure=W,
                       metadata={"friction": "stokes", "bead_radius_m": 1.53e-6})
    with pytest.raises(FitError, match="cannot separate k from the tracking-error"):
        bt.calibrate(rec)
    with pytest.raises(FitError, match="cannot separate k from the tracking-error"):
        bt.diagnose(rec)
    from blurtrap.inference.internal import refuse_without_temporal_information

    refuse_without_temporal_information([rec], noise=False)  # no FitError
    with pytest.raises(FitError, match="cannot separate k"):
        refuse_without_temporal_information([rec], noise=True)


def test_integer_nm_positions_are_not_called_saturated():
    # positions rounded to whole nm (std ~9 nm): a few frames on the outermost level are
    # chance; the old rule (>= 3 frames, more than twice the next level) called 2.5 % of
    # such records saturated. A real clip on the same grid is still refused.
    from blurtrap.inference._frames import _inspect_frames

    xs = circulant_frames(5e-5, 1.88e-8, 1e-6, DT, EPS2, 16384, seed=21, reps=40)
    called = 0
    for x in xs:
        rec = bt.from_arrays(np.round(x * 1e9), frame_interval=DT, exposure=1e-6,
                             position_unit="nm")
        called += any("saturated" in s for s in _inspect_frames([rec], True))
    assert called == 0
    y = np.round(np.minimum(xs[0] * 1e9, 2.5 * np.std(xs[0] * 1e9)))
    with pytest.raises(ValueError, match="saturated"):
        bt.calibrate(bt.from_arrays(y, frame_interval=DT, exposure=1e-6, position_unit="nm"))


def test_the_same_frames_twice_are_refused(x):
    # one file listed at two laser powers: the joint fit would count its frames twice
    a = bt.Recording(x, frame_interval=DT, exposure=W, laser_power=0.1)
    b = bt.Recording(x.copy(), frame_interval=DT, exposure=W, laser_power=0.2)
    with pytest.raises(ValueError, match="recordings 0 and 1 hold identical positions"):
        bt.calibrate([a, b])
    res = bt.calibrate([a, b], strict=False)
    assert any("identical positions" in n for n in res.notes)


def test_a_held_parameter_without_an_input_error_has_the_interval_kind_held():
    """friction='stokes' without a radius error: gamma's interval is its value twice; it said
    "wald" (a reviewer read it as a fitted interval)."""
    import math

    import numpy as np
    from scipy.signal import lfilter

    kt, k, g, dt = 1.380649e-23 * 295, 5e-5, 6 * math.pi * 9.3e-4 * 1.5e-6, 1 / 1500
    rng = np.random.default_rng(0)
    rho, sig = math.exp(-dt * k / g), math.sqrt(kt / k)
    x = lfilter([1.0], [1.0, -rho], rng.standard_normal(16384) * sig * math.sqrt(1 - rho**2))
    r = bt.Recording(x + 2e-9 * rng.standard_normal(16384), frame_interval=dt, exposure=1e-5, temperature=295.0,
                     metadata={"bead_radius_m": 1.5e-6})
    kinds = bt.calibrate(r, friction="stokes").to_dict()["interval_kinds"]
    assert kinds["gamma"] == "held" and kinds["k"] != "held"
