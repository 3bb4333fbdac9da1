"""Active calibration: drive_response and displacement_sensitivity (inference._active).

Independent references: the fluid-driven OU (``x' = -x/tau + x_s'``) integrated with its exact
discretisation on a substep grid, and exact OU substeps for the thermal motion; frames are
means of the substeps in the exposure ending at the frame time.
"""

import zlib

import numpy as np
import pytest
from scipy.signal import lfilter

from blurtrap.inference._active import DriveResponse, displacement_sensitivity, drive_response

KT = 4.11e-21
K = 5e-5
RD = 2e-7  # m per volt: the data are in volts


def gamma_for(fc, k=K):
    return k / (2 * np.pi * fc)


def substep_times(dt, exposure, n, substeps):
    """Grid times: midpoints of the substeps (W > 0) or the frame times themselves (W = 0)."""
    h = dt / substeps
    off = 0.5 * h if exposure > 0 else h
    return np.arange(n * substeps) * h + off - dt


def frames_from_substeps(x, exposure, dt, substeps):
    q = int(round(exposure / (dt / substeps)))
    assert abs(q * dt / substeps - exposure) < 1e-9 * dt
    x = x.reshape(*x.shape[:-1], -1, substeps)
    return x[..., substeps - max(q, 1):].mean(axis=-1)


def thermal_substeps(k, gamma, h, shape, rng):
    """Exact OU on a grid of spacing h, stationary start: shape (records, substeps)."""
    tau, var = gamma / k, KT / k
    c = np.exp(-h / tau)
    xi = rng.standard_normal(shape) * np.sqrt(var * (1 - c * c))
    x0 = rng.standard_normal((shape[0], 1)) * np.sqrt(var)
    return lfilter([1.0], [1.0, -c], xi, axis=1, zi=c * x0)[0]


def driven_response_exact(tau, amp, freq, phase, t):
    """Deterministic part of the fluid-driven OU, integrated exactly on the grid ``t`` (uniform)
    from x = 0 at t[0]: over one step ``x <- e^{-h/tau} x + Re[i w S e^{i w t} (e^{i w h} -
    e^{-h/tau}) / (1/tau + i w)]``, S = amp e^{i phase}, for the stage ``Re[S e^{i w t}]``."""
    h, w = t[1] - t[0], 2 * np.pi * freq
    c = np.exp(-h / tau)
    s = amp * np.exp(1j * phase)
    g = np.real(1j * w * s * np.exp(1j * w * t) * (np.exp(1j * w * h) - c) / (1 / tau + 1j * w))
    return lfilter([0.0, 1.0], [1.0, -c], g)


def steady_response(fc, amp, freq, phase, t):
    """The analytic steady state Re[H S e^{i w t}], H = i f/(f_c + i f) (checked below)."""
    hval = 1j * freq / (fc + 1j * freq)
    return np.real(hval * amp * np.exp(1j * (2 * np.pi * freq * t + phase)))


def test_exact_integration_matches_the_transfer_function():
    fc, amp, freq, phase = 835.0, 1e-7, 300.0, 0.4
    tau = 1 / (2 * np.pi * fc)
    t = np.arange(200_000) * (tau / 50)
    x = driven_response_exact(tau, amp, freq, phase, t)
    late = t > 40 * tau  # transient e^{-t/tau} gone
    np.testing.assert_allclose(x[late], steady_response(fc, amp, freq, phase, t[late]), rtol=0, atol=1e-12 * amp)
    assert np.ptp(x[late]) > 0.5 * amp  # f ~ f_c/3: |H| ~ 0.34


@pytest.mark.parametrize("exposure_frac", [1.0, 0.5, 0.0])
def test_noise_free_drive_recovers_rd_and_phase(exposure_frac):
    """Exact ODE frames at a drive where blur matters (f_d W = 0.137): Rd and phase exact."""
    dt, n, sub, fc, amp, fd, phase = 1e-3, 4096, 64, 835.0, 1e-7, 137.0, 0.9
    w = exposure_frac * dt
    tau = 1 / (2 * np.pi * fc)
    t = substep_times(dt, w, n, sub)
    warm = np.arange(-int(60 * tau / (dt / sub)), 0) * (dt / sub) + t[0]  # start 60 tau earlier
    x = driven_response_exact(tau, amp, fd, phase, np.r_[warm, t])[warm.size:]
    pos = frames_from_substeps(x, w, dt, sub) / RD
    stage = amp * np.cos(2 * np.pi * fd * np.arange(n) * dt + phase)
    resp = drive_response(pos, stage, dt, w, frequency=fd)
    assert isinstance(resp, DriveResponse) and resp.noise_bins >= 60
    assert np.isclose(resp.stage_amplitude, amp, rtol=1e-9) and np.isclose(resp.stage_phase, phase, atol=1e-9)
    rd = displacement_sensitivity(resp.ratio, resp.ratio_se, fc, 0.0, fd, w)
    # the substep average differs from the box average by ~ (pi f W)^2 / (6 sub^2) ~ 1e-5
    assert abs(rd.value / RD - 1) < 1e-4
    assert abs(rd.phase_mismatch) < 1e-4
    # estimating the drive frequency from the (noise-free) stage changes nothing
    resp2 = drive_response(pos, stage, dt, w)
    assert abs(resp2.frequency - fd) < 1e-8 and abs(resp2.ratio / resp.ratio - 1) < 1e-6
    if w > 0:  # without the exposure's factor the sensitivity is off by 1/sinc
        wrong = displacement_sensitivity(resp.ratio, resp.ratio_se, fc, 0.0, fd, 0.0)
        assert abs(wrong.value / RD - 1 / np.sinc(fd * w)) < 1e-4 and abs(wrong.phase_mismatch) > 0.1


def _zscores(dt, w, n, sub, fd, amp, n_seeds, seed, fc=835.0, fc_rel_se=0.05):
    """z of Rd (f_c exact; f_c with an error), of the phase, over seeds (vectorised generation)."""
    rng = np.random.default_rng(seed)
    gamma, phase = gamma_for(fc), 0.7
    out = {"rd": [], "rd_fc": [], "phase": [], "fc_rel": []}
    for _ in range(n_seeds // 50):
        t = substep_times(dt, w, n, sub)
        x = thermal_substeps(K, gamma, dt / sub, (50, n * sub), rng) + steady_response(fc, amp, fd, phase, t)
        pos = frames_from_substeps(x, w, dt, sub) / RD + 1e-3 * rng.standard_normal((50, n))  # + 1 mV noise
        stage = amp * np.cos(2 * np.pi * fd * np.arange(n) * dt + phase) + 0.3e-9 * rng.standard_normal((50, n))
        for r in range(50):
            resp = drive_response(pos[r], stage[r], dt, w, frequency=fd)
            a = displacement_sensitivity(resp.ratio, resp.ratio_se, fc, 0.0, fd, w)
            fc_hat = fc * (1 + fc_rel_se * rng.standard_normal())
            b = displacement_sensitivity(resp.ratio, resp.ratio_se, fc_hat, fc_rel_se * fc, fd, w)
            out["rd"].append((a.value - RD) / a.se)
            out["rd_fc"].append((b.value - RD) / b.se)
            out["phase"].append(a.phase_mismatch / a.phase_mismatch_se)
            out["fc_rel"].append(a.se / a.value)
    return {key: np.array(v) for key, v in out.items()}


@pytest.mark.parametrize(
    "dt, w, n, sub, fd, amp",
    [(1e-3, 1e-3, 16384, 8, 32.0, 100e-9), (1e-3, 0.0, 16384, 1, 32.0, 100e-9),
     (1e-5, 1e-5, 32768, 2, 320.0, 30e-9), (1e-5, 0.0, 32768, 1, 320.0, 30e-9)],
    ids=["1 kHz W=dt", "1 kHz W=0", "100 kHz W=dt", "100 kHz W=0"],
)
def test_rd_errors_are_honest(dt, w, n, sub, fd, amp):
    seeds = 200
    z = _zscores(dt, w, n, sub, fd, amp, seeds, zlib.crc32(f"{dt}{w}".encode()))
    assert 0.005 < np.median(z["fc_rel"]) < 0.2  # a test of the SE, not of rounding
    for key in ("rd", "rd_fc", "phase"):
        m, s = z[key].mean(), z[key].std(ddof=1)
        assert abs(m) < 3.2 / np.sqrt(seeds) and 0.85 < s < 1.15, (key, m, s)


def test_estimated_frequency_error_is_honest():
    rng = np.random.default_rng(5)
    dt, n, fd, amp, reps = 1e-3, 8192, 31.3, 100e-9, 40
    t = substep_times(dt, dt, n, 4)
    x = thermal_substeps(K, gamma_for(835.0), dt / 4, (reps, n * 4), rng) + steady_response(835.0, amp, fd, 0.2, t)
    pos = frames_from_substeps(x, dt, dt, 4) / RD
    stage = amp * np.cos(2 * np.pi * fd * np.arange(n) * dt + 0.2) + 3e-9 * rng.standard_normal((reps, n))
    z = []
    for r in range(reps):
        resp = drive_response(pos[r], stage[r], dt, dt)
        given = drive_response(pos[r], stage[r], dt, dt, frequency=fd)
        z.append((resp.frequency - fd) / resp.frequency_se)
        assert abs(resp.ratio - given.ratio) < 0.05 * given.ratio_se
    z = np.array(z)
    assert abs(z.mean()) < 3.5 / np.sqrt(reps) and 0.65 < z.std() < 1.4, (z.mean(), z.std())


def test_phase_flags_a_trace_of_the_stage_motion_and_an_inverted_detector():
    rng = np.random.default_rng(9)
    dt, n, fc, fd, amp, phase = 1e-3, 16384, 835.0, 32.0, 100e-9, 0.3
    t = substep_times(dt, dt, n, 4)
    thermal = thermal_substeps(K, gamma_for(fc), dt / 4, (1, n * 4), rng)[0]
    stage_sub = amp * np.cos(2 * np.pi * fd * t + phase)
    bead = thermal + steady_response(fc, amp, fd, phase, t)
    stage = amp * np.cos(2 * np.pi * fd * np.arange(n) * dt + phase)
    good = drive_response(frames_from_substeps(bead, dt, dt, 4) / RD, stage, dt, dt)
    ok = displacement_sensitivity(good.ratio, good.ratio_se, fc, 0.02 * fc, fd, dt)
    assert abs(ok.phase_mismatch) < 4 * ok.phase_mismatch_se
    # the bead relative to the stage, (H - 1) x_s: phase off by +pi/2 ((H - 1)/H = i f_c/f_d)
    rel = drive_response(frames_from_substeps(bead - stage_sub, dt, dt, 4) / RD, stage, dt, dt)
    bad = displacement_sensitivity(rel.ratio, rel.ratio_se, fc, 0.02 * fc, fd, dt)
    assert abs(bad.phase_mismatch - np.pi / 2) < 0.01 and abs(bad.phase_mismatch) > 20 * bad.phase_mismatch_se
    # a detector of the opposite sign: off by pi, |Rd| unchanged
    inv = drive_response(-frames_from_substeps(bead, dt, dt, 4) / RD, stage, dt, dt)
    flip = displacement_sensitivity(inv.ratio, inv.ratio_se, fc, 0.02 * fc, fd, dt)
    assert abs(abs(flip.phase_mismatch) - np.pi) < 0.1 and np.isclose(flip.value, ok.value, rtol=1e-9)


def test_detector_transfer():
    """A photodiode low-pass T(f) = 1/(1 + i f/f3): given as value or callable, Rd is recovered."""
    dt, n, fc, fd, amp, f3 = 1e-5, 8192, 835.0, 2000.0, 1e-7, 5000.0
    tf = lambda f: 1 / (1 + 1j * f / f3)
    tt = np.arange(n) * dt
    hval = 1j * fd / (fc + 1j * fd)
    pos = np.real(tf(fd) * hval * amp * np.exp(2j * np.pi * fd * tt)) / RD  # W = 0
    stage = amp * np.cos(2 * np.pi * fd * tt)
    resp = drive_response(pos, stage, dt, 0.0)
    for t_arg in (tf, tf(fd)):
        rd = displacement_sensitivity(resp.ratio, resp.ratio_se, fc, 0.0, fd, 0.0, detector_transfer=t_arg)
        assert abs(rd.value / RD - 1) < 1e-9 and abs(rd.phase_mismatch) < 1e-9
    plain = displacement_sensitivity(resp.ratio, resp.ratio_se, fc, 0.0, fd, 0.0)
    assert np.isclose(plain.value / RD, 1 / abs(tf(fd)), rtol=1e-9)


@pytest.mark.parametrize(
    "change, match",
    [(dict(stage=np.zeros(500)), r"stage must have one sample per frame of positions \(1000\); got 500"),
     (dict(frequency=600.0), r"frequency must be below the Nyquist frequency 500 Hz .* got 600.0 Hz"),
     (dict(frequency=0.0), r"frequency must be a positive, finite number \[Hz\]; got 0.0"),
     (dict(exposure=2e-3), r"exposure must be in \[0, frame_interval = 0.001\] s; got 0.002"),
     (dict(exposure=-1e-4), r"exposure must be in \[0, frame_interval"),
     (dict(exposure="long"), r"exposure must be in \[0, frame_interval = 0.001\] s; got 'long'"),
     (dict(positions=np.zeros((1000, 2))), r"positions must be a 1-D trace"),
     (dict(stage=np.r_[np.ones(999), np.inf]), r"stage must be finite; frame 999 is inf"),
     (dict(stage=np.random.default_rng(1).standard_normal(1000) * 1e-9), r"stage shows no clear drive"),
     (dict(frame_interval=-1.0), r"frame_interval must be a positive, finite number \[s\]; got -1.0")],
)
def test_drive_response_errors(change, match):
    tt = np.arange(1000) * 1e-3
    args = dict(positions=np.random.default_rng(0).standard_normal(1000), stage=1e-7 * np.cos(2 * np.pi * 30 * tt),
                frame_interval=1e-3, exposure=1e-3, frequency=None)
    args.update(change)
    with pytest.raises(ValueError, match=match):
        drive_response(args["positions"], args["stage"], args["frame_interval"], args["exposure"],
                       frequency=args["frequency"])


@pytest.mark.parametrize(
    "change, match",
    [(dict(ratio=0.0), r"ratio must be finite and non-zero; got 0.0"),
     (dict(ratio="x"), r"ratio must be a complex number"),
     (dict(ratio_se=-1.0), r"ratio_se must be a finite number >= 0 \[unit/m\]; got -1.0"),
     (dict(corner_frequency=0.0), r"corner_frequency must be a positive, finite number \[Hz\]; got 0.0"),
     (dict(corner_frequency_se=np.nan), r"corner_frequency_se must be a finite number >= 0 \[Hz\]; got nan"),
     (dict(drive_frequency=-5.0), r"drive_frequency must be a positive, finite number \[Hz\]; got -5.0"),
     (dict(exposure=-1e-3), r"exposure must be a finite number >= 0 \[s\]; got -0.001"),
     (dict(detector_transfer=0.0), r"detector_transfer at the drive frequency 30 Hz must be finite and non-zero"),
     (dict(detector_transfer="abc"), r"detector_transfer must be a complex number or a callable")],
)
def test_displacement_sensitivity_errors(change, match):
    args = dict(ratio=1e6 + 2e6j, ratio_se=1e4, corner_frequency=800.0, corner_frequency_se=10.0,
                drive_frequency=30.0, exposure=1e-3, detector_transfer=None)
    args.update(change)
    with pytest.raises(ValueError, match=match):
        displacement_sensitivity(**args)
