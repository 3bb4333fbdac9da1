"""Narrow lines: find_lines, remove_lines, line_mask, excluded_ranges_mask (inference._lines).

Data come from an independent NumPy generator: the exact OU update on a grid of substeps
(``x <- c x + sqrt(kT/k (1 - c^2)) xi``, ``c = exp(-h/tau)``), frames = mean of the substeps in
the exposure ending at the frame time (W = 0: the value at the frame time).
"""

import zlib

import numpy as np
import pytest
from scipy.signal import lfilter

from blurtrap.inference import _lines
from blurtrap.inference._lines import Line, excluded_ranges_mask, find_lines, line_mask, remove_lines

KT = 4.11e-21
K = 5e-5  # 0.05 pN/nm


def gamma_for(fc, k=K):
    return k / (2 * np.pi * fc)


def ou_frames(k, gamma, dt, exposure, n, n_rec, rng, substeps=4):
    """(n_rec, n) exposure-averaged frames of the exact OU process (vectorised over records)."""
    tau, var, h = gamma / k, KT / k, dt / substeps
    q = int(round(exposure / h))
    assert abs(q * h - exposure) < 1e-9 * dt
    c = np.exp(-h / tau)
    xi = rng.standard_normal((n_rec, n * substeps)) * np.sqrt(var * (1 - c * c))
    x0 = rng.standard_normal((n_rec, 1)) * np.sqrt(var)
    x = lfilter([1.0], [1.0, -c], xi, axis=1, zi=c * x0)[0].reshape(n_rec, n, substeps)
    return x[..., substeps - max(q, 1):].mean(axis=-1)


def min_adjusted_p(x, dt):
    """Smallest Bonferroni-adjusted p-value of each record (the scan find_lines runs)."""
    return _lines._scan(x, dt, 0.5)[1].min(axis=-1)


# ------------------------------------------------------------------ (a) no false lines

N_SHORT, N_REC = 2048, 1000
FALSE_ALARM_CASES = {
    # dt/tau ~ 10 (issue 17's camera), instantaneous frames
    "ou 500 fps": lambda rng: (ou_frames(K, gamma_for(835), 2e-3, 0.0, N_SHORT, N_REC, rng, 1), 2e-3),
    "blurred ou W=dt": lambda rng: (ou_frames(K, gamma_for(835), 2e-3, 2e-3, N_SHORT, N_REC, rng), 2e-3),
    "blurred ou + white": lambda rng: (ou_frames(K, gamma_for(835), 2e-4, 2e-4, N_SHORT, N_REC, rng)
                                       + 4e-9 * rng.standard_normal((N_REC, N_SHORT)), 2e-4),
    # slow corner: the Lorentzian's plateau and 1/f^2 fall inside the record's band
    "slow corner 50 Hz at 50 kHz": lambda rng: (ou_frames(K, gamma_for(50), 2e-5, 0.0, N_SHORT, N_REC, rng, 1),
                                                2e-5),
    # drift: a random walk (1/f^2) stronger than the thermal motion at low frequency
    "ou + random-walk drift": lambda rng: (ou_frames(K, gamma_for(835), 2e-3, 2e-3, N_SHORT, N_REC, rng)
                                           + 2e-9 * np.cumsum(rng.standard_normal((N_REC, N_SHORT)), axis=1),
                                           2e-3),
}


@pytest.mark.parametrize("case", sorted(FALSE_ALARM_CASES))
def test_no_false_lines_and_calibrated_false_alarm_rate(case):
    rng = np.random.default_rng(zlib.crc32(case.encode()))
    x, dt = FALSE_ALARM_CASES[case](rng)
    p = min_adjusted_p(x, dt)
    # the default level: not one false line in 1000 records
    assert p.min() >= 1e-6, p.min()
    # the construction is calibrated: P(min p < a) <= 1 - exp(-a) (independent bins) + 3 MC SE,
    # and not vacuous (a test that never fires would pass the line above trivially)
    for a in (0.1, 0.5):
        rate, expect = np.mean(p < a), 1 - np.exp(-a)
        assert rate <= expect + 3 * np.sqrt(expect * (1 - expect) / N_REC), (a, rate)
    assert np.mean(p < 0.5) >= 0.2
    # the public function on a subset agrees: no lines
    assert all(find_lines(xi, dt) == () for xi in x[:60])


# ------------------------------------------------------------------ (b) issue 17


def _autocov1(x):
    x = x - x.mean()
    return np.mean(x[1:] * x[:-1])


def test_issue17_drive_found_refined_and_removed():
    rng = np.random.default_rng(17)
    dt, n, f0, amp = 2e-3, 32768, 16.8, 500e-9
    x = ou_frames(K, gamma_for(835), dt, dt, n, 1, rng, 8)[0]
    y = x + amp * np.sin(2 * np.pi * f0 * np.arange(n) * dt + 0.4)
    lines = find_lines(y, dt)
    assert len(lines) == 1
    (line,) = lines
    assert isinstance(line, Line) and not line.known
    assert abs(line.frequency - f0) < 3 * line.frequency_se
    assert line.frequency_se < 1e-3 / (n * dt)  # far finer than the Fourier grid
    assert abs(line.amplitude - amp) < 4 * line.amplitude_se
    assert abs(np.angle(np.exp(1j * (line.phase - (0.4 - np.pi / 2))))) < 1e-3
    assert line.power_ratio > 1e6 and line.p_value < 1e-100
    clean = remove_lines(y, dt, lines)
    assert np.isclose(clean.mean(), y.mean(), rtol=0, atol=1e-12)  # the mean is left in
    # variance and lag-1 autocovariance: the cleaned trace equals the thermal one far within the
    # Monte Carlo error of either statistic (var(s^2) ~ (2/N) sum C(n)^2 ~ 2 C(0)^2/N here)
    c0, c1 = np.var(x), _autocov1(x)
    mc = np.sqrt(2.0 / n) * c0
    assert abs(np.var(clean) - c0) < 0.05 * mc
    assert abs(_autocov1(clean) - c1) < 0.05 * mc
    assert np.var(y) > 1000 * c0  # ... which the line had buried


# ------------------------------------------------------------------ (c) photodiode, slow corner


def test_line_on_slow_corner_photodiode_spectrum():
    rng = np.random.default_rng(3)
    dt, n = 2e-5, 65536
    x = ou_frames(K, gamma_for(50), dt, 0.0, n, 1, rng, 1)[0]
    assert find_lines(x, dt) == ()
    f, power = _lines.periodogram(x, dt)
    t = np.arange(n) * dt
    y = x.copy()
    truth = []
    # a line 40x its local spectrum exactly on a bin in the 1/f^2 part, and a stronger one on the
    # Lorentzian's plateau below the corner (fewer bins there for the median)
    for j0, ratio, phase in ((2000, 40.0, 0.3), (40, 400.0, -1.0)):
        psd = power[j0 - 30:j0 + 30].mean()
        a = np.sqrt(4 * ratio * psd / (n * dt))
        y += a * np.cos(2 * np.pi * j0 / (n * dt) * t + phase)
        truth.append((j0 / (n * dt), a))
    lines = find_lines(y, dt)
    assert len(lines) == 2
    for (f0, a), line in zip(sorted(truth), sorted(lines)):
        assert abs(line.frequency - f0) < 4 * line.frequency_se
        assert abs(line.amplitude - a) < 4 * line.amplitude_se
        assert line.p_value < 1e-6


# ------------------------------------------------------------------ more behaviour


def test_strong_off_bin_line_leakage_is_one_line_and_known_lines_are_modelled():
    rng = np.random.default_rng(8)
    dt, n = 1e-3, 8192
    x = ou_frames(K, gamma_for(300), dt, dt, n, 1, rng)[0]
    t = np.arange(n) * dt
    f_mains, f_weak = 50.0 + 0.37 / (n * dt), 123.4
    y = x + 1e-6 * np.cos(2 * np.pi * f_mains * t) + 3e-7 * np.cos(2 * np.pi * 3 * f_mains * t + 1.0)
    lines = find_lines(y, dt)
    assert len(lines) == 2 and lines[0].amplitude > lines[1].amplitude  # strongest first
    for line, f0 in zip(lines, (f_mains, 3 * f_mains)):
        assert abs(line.frequency - f0) < 4 * line.frequency_se
    # a known frequency is always modelled, with its single-frequency p-value
    lines = find_lines(y, dt, known=[f_weak], max_lines=0)
    assert len(lines) == 1 and lines[0].known and lines[0].p_value > 1e-3
    assert abs(lines[0].frequency - f_weak) <= 1 / (n * dt)
    lines = find_lines(y, dt, known=(f_mains,))
    assert [line.known for line in lines] == [True, False]
    assert abs(lines[0].frequency - f_mains) < 4 * lines[0].frequency_se


def test_frequency_and_amplitude_errors_are_honest():
    rng = np.random.default_rng(21)
    dt, n, reps = 2e-3, 4096, 60
    x = ou_frames(K, gamma_for(835), dt, dt, n, reps, rng)
    _, power = _lines.periodogram(x, dt)
    j0 = 700
    psd = power[:, j0 - 200:j0 + 200].mean()
    f0 = (j0 + 0.3) / (n * dt)
    amp = np.sqrt(4 * 300 * psd / (n * dt))  # a line 300x its local spectrum
    t = np.arange(n) * dt
    zf, za = [], []
    for i in range(reps):
        (line,) = find_lines(x[i] + amp * np.cos(2 * np.pi * f0 * t + i), dt)
        zf.append((line.frequency - f0) / line.frequency_se)
        za.append((line.amplitude - amp) / line.amplitude_se)
    for z in (np.array(zf), np.array(za)):
        assert abs(z.mean()) < 3.5 / np.sqrt(reps) and 0.7 < z.std() < 1.35, (z.mean(), z.std())


def test_remove_lines_is_exact_least_squares():
    dt, n = 1e-3, 1000
    t = np.arange(n) * dt
    freqs = (37.21, 211.9)
    y = 3.0 + 2.0 * np.cos(2 * np.pi * freqs[0] * t + 0.2) - 0.5 * np.sin(2 * np.pi * freqs[1] * t)
    np.testing.assert_allclose(remove_lines(y, dt, freqs), 3.0, rtol=0, atol=1e-10)
    assert np.array_equal(remove_lines(y, dt, ()), y)
    # on noise, each line removes its projection only: ~2 of N degrees of freedom
    rng = np.random.default_rng(0)
    e = rng.standard_normal(200_000)
    dv = np.var(e) - np.var(remove_lines(e, dt, [37.21, 211.9, 400.3]))
    assert 0 <= dv < 20 * 6 / e.size


def test_masks():
    dt, n = 1e-3, 1000
    f = np.arange(1, n // 2 + 1) / (n * dt)
    mask = line_mask(f, [Line(100.4, 1.0, 0.0, 50.0, 1e-9, 1e-3, 0.1, False), 250.0], dt, n)
    assert set(np.round(f[mask])) == {99, 100, 101, 102, 248, 249, 250, 251, 252}
    assert not line_mask(f, [], dt, n).any()
    assert line_mask(f, [250.0], dt, n, half_width_bins=0).sum() == 1
    m = excluded_ranges_mask(f, [[10, 12.5], [499, 500]], dt)
    assert set(np.round(f[m])) == {10, 11, 12, 499, 500}
    assert not excluded_ranges_mask(f, [], dt).any()
    assert excluded_ranges_mask(f, [0, 2], dt).sum() == 2


@pytest.mark.parametrize(
    "ranges, match",
    [([[5, 3]], r"excluded_ranges_Hz\[0\] = \[5.0, 3.0\] must satisfy 0 <= a < b <= 500 Hz"),
     ([[1, 2], [400, 600]], r"excluded_ranges_Hz\[1\] .* <= 500 Hz"),
     ([[-1, 2]], r"excluded_ranges_Hz\[0\]"),
     ([[1, 2, 3]], r"excluded_ranges_Hz must be a list of \[a, b\] pairs"),
     ("abc", r"excluded_ranges_Hz must be a list of \[a, b\] pairs")],
)
def test_excluded_ranges_errors(ranges, match):
    with pytest.raises(ValueError, match=match):
        excluded_ranges_mask(np.linspace(1, 500, 10), ranges, 1e-3)


@pytest.mark.parametrize(
    "kwargs, match",
    [(dict(positions=np.zeros((2, 100))), r"positions must be a 1-D trace; got an array of shape \(2, 100\)"),
     (dict(positions=np.r_[np.zeros(50), np.nan]), r"positions must be finite; frame 50 is nan"),
     (dict(positions=np.zeros(5)), r"at least 16 frames; got 5"),
     (dict(frame_interval=0.0), r"frame_interval must be a positive, finite number \[s\]; got 0.0"),
     (dict(p_value=1.5), r"p_value must be a probability in \(0, 1\); got 1.5"),
     (dict(max_lines=-1), r"max_lines must be a non-negative integer; got -1"),
     (dict(known=[600.0]), r"known\[0\] must be below the Nyquist frequency 500 Hz .* got 600.0 Hz"),
     (dict(known=[-3.0]), r"known\[0\] must be a positive, finite number \[Hz\]")],
)
def test_find_lines_errors(kwargs, match):
    args = dict(positions=np.random.default_rng(0).standard_normal(256), frame_interval=1e-3)
    args.update(kwargs)
    pos, dt = args.pop("positions"), args.pop("frame_interval")
    with pytest.raises(ValueError, match=match):
        find_lines(pos, dt, **args)


def test_remove_and_mask_errors():
    y = np.zeros(100)
    with pytest.raises(ValueError, match=r"lines\[1\] must be below the Nyquist frequency"):
        remove_lines(y, 1e-3, [10.0, 700.0])
    with pytest.raises(ValueError, match=r"n_frames must be an integer >= 2; got 1.5"):
        line_mask(np.ones(3), [1.0], 1e-3, 1.5)
    with pytest.raises(ValueError, match=r"half_width_bins must be a finite number >= 0; got -1"):
        line_mask(np.ones(3), [1.0], 1e-3, 100, half_width_bins=-1)
