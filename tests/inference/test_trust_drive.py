"""Active calibration's drive response checked for what it can show is wrong (issue 18's
class "a required check skipped"): a response not clearly above the thermal noise (a drive
that never reached the bead, or one too small) is refused, and a response whose phase
disagrees with the model's (an inverted detector, a trace of the bead relative to the
stage, a timing offset between the stage and the positions) is named in a note.

Data from numpy alone (not blurtrap's simulator): exact AR(1) frames of the trap at 100 kHz
plus 2 nm white noise, and the bead's response to the stage drive ``Re[H(f_d) S e^{2 pi i
f_d t}]`` with ``H = i f_d/(f_c + i f_d)`` (Tolic-Norrelykke et al. 2006, eq. 4), in volts
through a detector of 200 nm/V.
"""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import blurtrap as bt

KT = 1.380649e-23 * 295.0
K = 5e-5
GAMMA = 6 * math.pi * 9.5e-4 * 1.53e-6
DT = 1e-5
N = 65536
RD = 2e-7  # m per V
FD = 32.0
FC = K / (2 * math.pi * GAMMA)
H = 1j * FD / (FC + 1j * FD)
T = np.arange(N) * DT


def thermal(seed, k=K):
    rng = np.random.default_rng(seed)
    a = math.exp(-k * DT / GAMMA)
    e = rng.standard_normal(N) * math.sqrt(KT / k)
    e[1:] *= math.sqrt(1 - a * a)
    return lfilter([1.0], [1.0, -a], e) + 2e-9 * rng.standard_normal(N)


def drive(amplitude, delay=0.0):
    """The stage (sampled ``delay`` s late) and the complex stage sinusoid at the bead."""
    s = amplitude * np.exp(0.3j) * np.exp(2j * math.pi * FD * T)
    stage = np.real(amplitude * np.exp(0.3j) * np.exp(2j * math.pi * FD * (T - delay)))
    return stage, s


def calibrate(volts, stage):
    rec = bt.Recording(volts, frame_interval=DT, exposure=1e-9 * DT, temperature=295.0,
                       stage=stage, position_unit="V",
                       metadata={"drive": {"frequency_Hz": FD}, "detector": "photodiode"})
    return bt.calibrate(rec)


def phase_notes(res):
    return [s for s in res.notes if s.startswith("drive: the phase")]


@pytest.mark.parametrize("amplitude, at_bead", [(150e-9, 0.0), (1e-9, 1.0)],
                         ids=["drive never reached the bead", "1 nm drive"])
def test_a_response_within_the_noise_is_refused(amplitude, at_bead):
    # k came back 280 SE low (drive absent) or 90x high (1 nm) with no note: Rd ~ 1/|x/x_s|
    # from a response of 1-2 SE
    stage, s = drive(amplitude)
    volts = (thermal(4) + at_bead * np.real(H * s)) / RD
    with pytest.raises(ValueError, match="did not reach the bead .* too small"):
        calibrate(volts, stage)


def test_correct_drives_give_rd_within_errors_and_no_phase_note():
    stage, s = drive(150e-9)
    for seed in (10, 11, 12):
        res = calibrate((thermal(seed) + np.real(H * s)) / RD, stage)
        rd = res["displacement_sensitivity"]
        assert abs(rd.value - RD) < 3 * rd.error
        assert not phase_notes(res), phase_notes(res)


def test_a_trace_relative_to_the_stage_is_named():
    # (H - 1) x_s: Rd 186 SE low, k 8 SE high, no note before
    stage, s = drive(150e-9)
    res = calibrate((thermal(5) + np.real((H - 1) * s)) / RD, stage)
    (note,) = phase_notes(res)
    assert "relative to the stage" in note and "NOT TRUSTWORTHY" in note
    factor = float(note.split("wrong, Rd ")[1].split("x too small")[0])
    assert factor == pytest.approx(abs(H - 1) / abs(H), rel=0.1)  # ~ f_c / f_d


def test_an_inverted_detector_is_named():
    # bit-identical results to the right sign before
    stage, s = drive(150e-9)
    res = calibrate(-(thermal(6) + np.real(H * s)) / RD, stage)
    (note,) = phase_notes(res)
    assert "inverted" in note


def test_a_late_stage_clock_is_named_with_its_delay():
    stage, s = drive(150e-9, delay=1e-3)  # 11.5 deg at 32 Hz
    res = calibrate((thermal(6) + np.real(H * s)) / RD, stage)
    (note,) = phase_notes(res)
    delay_ms = float(note.split("timing offset of ")[1].split(" ms")[0])
    # the measured phase has an SE of ~2 deg here (0.17 ms)
    assert abs(delay_ms - 1.0) < 0.5
    rd = res["displacement_sensitivity"]
    assert abs(rd.value - RD) < 3 * rd.error  # a delay does not change |x/x_s|


def test_an_effect_the_data_do_not_show_is_named_when_the_fit_wanders():
    # diode_filter='fit' on a photodiode trace without a filter: the fit did not converge
    # and the message named only outliers, drift or a wrong exposure
    from blurtrap.inference import FitError

    rec = bt.Recording(thermal(12), frame_interval=DT, exposure=1e-9 * DT, temperature=295.0,
                       metadata={"detector": "photodiode", "diode_filter": "fit"})
    with pytest.raises(FitError) as err:
        bt.calibrate(rec)
    msg = str(err.value)
    assert "f3db = " in msg and "diode_alpha = " in msg
    assert "detector filter on a trace without one" in msg


@pytest.mark.parametrize("declared", [31.0, 32000.0], ids=["typo", "kHz as Hz"])
def test_a_declared_frequency_the_stage_does_not_show_is_refused(declared):
    # 31 Hz for a 32 Hz drive biased Rd by 2.4 SE with no note; 32000 Hz passed the stage
    # check on a noiseless stage
    stage, s = drive(150e-9)
    volts = (thermal(7) + np.real(H * s)) / RD
    rec = bt.Recording(volts, frame_interval=DT, exposure=1e-9 * DT, temperature=295.0,
                       stage=stage, position_unit="V",
                       metadata={"drive": {"frequency_Hz": declared}, "detector": "photodiode"})
    with pytest.raises(ValueError, match=r"declared at .* but the stage \(its drift removed\) "
                                         r"moves at 32 Hz"):
        bt.calibrate(rec)


def test_a_creeping_stage_with_the_right_frequency_is_accepted():
    # the frequency check looked at the stage's largest periodogram peak: 300 nm of piezo
    # creep put it at 0.02 Hz and refused a correct drive, advising 0.02 Hz
    stage, s = drive(150e-9)
    creep = 300e-9 * (1.0 - np.exp(-T / 0.2))
    res = calibrate((thermal(8) + np.real(H * s)) / RD, stage + creep)
    rd = res["displacement_sensitivity"]
    assert abs(rd.value - RD) < 3 * rd.error


def test_wald_intervals_of_positive_parameters_stay_positive():
    # where no profile interval is available (results in volts, interval_source None), a k
    # or gamma with an SE above half its value had a Wald interval reaching below 0 (the CLI
    # printed negative stiffnesses); it is taken on log scale there, same SE
    import dataclasses

    dt = 1 / 1500
    rng = np.random.default_rng(3)
    a = math.exp(-K * dt / GAMMA)
    e = rng.standard_normal(8192) * math.sqrt(KT / K)
    e[1:] *= math.sqrt(1 - a * a)
    res = bt.calibrate(bt.Recording(lfilter([1.0], [1.0, -a], e), frame_interval=dt,
                                    exposure=1e-9 * dt), model="blur")
    wide = dataclasses.replace(res, covariance=np.asarray(res.covariance) * (
        (0.8 * res.k / res.k_err) ** 2), interval_source=None)
    lo, hi = wide.intervals["k"]
    assert wide.interval_kinds["k"] == "log-wald" and lo > 0
    assert lo * hi == pytest.approx(wide.k**2, rel=1e-9)  # symmetric on log scale
    assert math.log(hi / wide.k) == pytest.approx(1.959963984540054 * 0.8)  # SE = 0.8 k
    narrow = dataclasses.replace(res, interval_source=None)
    assert narrow.interval_kinds["k"] == "wald"


def test_the_driven_recordings_own_stiffness_gives_rd():
    # with k per recording and the drive on recording 1 (recording 0 softer), Rd used the
    # first k: f_c and with it |H(f_d)| of the wrong recording
    stage, s = drive(150e-9)
    meta = {"detector": "photodiode"}
    soft = bt.Recording(thermal(30, k=K / 4) / RD, frame_interval=DT, exposure=1e-9 * DT,
                        temperature=295.0, position_unit="V", metadata=meta)
    driven = bt.Recording((thermal(31) + np.real(H * s)) / RD, frame_interval=DT,
                          exposure=1e-9 * DT, temperature=295.0, stage=stage,
                          position_unit="V", metadata={**meta, "drive": {"frequency_Hz": FD}})
    res = bt.calibrate([soft, driven], k="per_recording")
    rd = res["displacement_sensitivity"]
    assert abs(rd.value - RD) < 3 * rd.error, (rd.value, rd.error)
    assert abs(res.k_per_recording[1] - K) < 3 * res.k_per_recording_err[1]
    assert not phase_notes(res)


def test_a_trace_in_metres_gets_the_same_phase_check():
    # positions in metres: the drive checks the position calibration (drive_check) and the
    # phase is checked as in volts (the fit's friction in metres for the bead's H)
    stage, s = drive(150e-9)

    def fit(sign):
        rec = bt.Recording(sign * (thermal(50) + np.real(H * s)), frame_interval=DT,
                           exposure=1e-9 * DT, temperature=295.0, stage=stage,
                           metadata={"detector": "photodiode", "drive": {"frequency_Hz": FD}})
        return bt.calibrate(rec)

    right = fit(1.0)
    assert not phase_notes(right)
    assert any("position scale" in n and "SE from 1)" in n for n in right.notes)
    (note,) = phase_notes(fit(-1.0))
    assert "inverted" in note


def _driven(seed, stage_scale=1.0, **meta):
    stage, s = drive(150e-9)
    rec = bt.Recording((thermal(seed) + np.real(H * s)) / RD, frame_interval=DT,
                       exposure=1e-9 * DT, temperature=295.0, stage=stage_scale * stage,
                       position_unit="V", metadata={"detector": "photodiode",
                                                    "drive": {"frequency_Hz": FD}, **meta})
    return bt.calibrate(rec)


@pytest.mark.parametrize("scale, factor", [(1e-3, "1000"), (250.0, None)],
                         ids=["stage in um read as nm", "stage 250 x too large"])
def test_a_stage_in_another_unit_is_named(scale, factor):
    # a fifth independent pass: k = 112 N/m and gamma 1e6 x Stokes (um read as nm) with no
    # note: the plausibility and Stokes checks did not run on positions in volts. A stage
    # 250 x too large gives k and gamma 250^2 x too small, still in a trapped bead's range:
    # the known bead's Stokes friction names it
    res = _driven(60, scale, bead_radius_m=1.53e-6, viscosity_Pa_s=9.5e-4)
    assert any("x the Stokes friction" in n for n in res.notes)
    implausible = [n for n in res.notes if n.startswith("implausible")]
    if factor is None:
        assert not implausible
    else:
        assert f"stage positions {factor} x what was given" in implausible[0]


def test_a_correct_drive_gets_no_unit_or_stokes_note():
    for seed in (61, 62):
        res = _driven(seed, bead_radius_m=1.53e-6, viscosity_Pa_s=9.5e-4)
        assert not [n for n in res.notes if n.startswith("implausible") or "Stokes friction"
                    in n], res.notes


def test_a_friction_given_beside_a_drive_is_named_as_not_used():
    # friction='stokes' with a drive was silently ignored (gamma fitted, the result equal to
    # friction='free'); the note was cut off mid-sentence
    meta = {"bead_radius_m": 1.53e-6, "viscosity_Pa_s": 9.5e-4, "friction": "stokes"}
    res = _driven(63, **meta)
    (note,) = [n for n in res.notes if "is not used" in n]
    assert "consistent (z = " in note
    assert any(n.startswith("friction: Stokes") and n.endswith(")") for n in res.notes)
    wrong = _driven(63, **{**meta, "bead_radius_m": 3 * 1.53e-6})  # a diameter as radius
    (note,) = [n for n in wrong.notes if "is not used" in n]
    assert "they disagree" in note
