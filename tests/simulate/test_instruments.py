"""Instruments in the simulator: the stage drive (``stage_drive``), the oversampling
anti-aliasing photodiode and the volts scaling, against formulas written here and against the
independent NumPy generator ``tests/_instrument_gen.py``.

Monte Carlo checks use fixed keys/seeds; their tolerances are Z standard errors, the SE taken
from the spread over independent traces (or, for averaged periodograms, the Gamma law of
DESIGN 2.9).
"""

import os
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from blurtrap.physics import BOLTZMANN
from blurtrap.simulate import (
    ExposureWindows,
    HydrodynamicFriction,
    PhotodiodeFilter,
    Sensitivity,
    StageDrive,
    TimingJitter,
    antialias_gain,
    simulate,
    simulate_photodiode,
    stage_positions,
)

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))
from _instrument_gen import generate, kaiser_lowpass  # noqa: E402

T = 296.15
K, GAMMA = 2e-5, 8.5e-9  # tau = 0.425 ms, f_c = 374 Hz
DT = 1 / 1500
SIGMA2 = BOLTZMANN * T / K
Z = 4.5


def expected_coeffs(amp, freq, phase, w, mode="fluid", pd=None):
    """(a, b) of ``a sin(w t_n) + b cos(w t_n)``: the response written from the ODE and the
    exposure average of e^{i w t} over [t_n, t_n + W] as (e^{i w W} - 1)/(i w W)."""
    om = 2 * np.pi * freq
    resp = 1j * om * GAMMA / (K + 1j * om * GAMMA) if mode == "fluid" else 1.0
    avg = (np.exp(1j * om * w) - 1) / (1j * om * w)
    g = amp * resp * avg * np.exp(1j * phase)
    if pd is not None:
        f3db, alpha = pd
        g = g * (alpha + (1 - alpha) / (1 + 1j * freq / f3db))
    return g.real, g.imag


def fit_sincos(x, t, freq):
    """Least-squares a, b (and an offset) of a sin + b cos per trace: arrays (n_traces,)."""
    th = 2 * np.pi * freq * t
    design = np.stack([np.sin(th), np.cos(th), np.ones_like(th)], axis=1)
    coef, *_ = np.linalg.lstsq(design, np.asarray(x).reshape(-1, t.size).T, rcond=None)
    return coef[0], coef[1]


def check_mean(values, expected, what):
    v = np.asarray(values)
    se = v.std(ddof=1) / np.sqrt(v.size)
    assert abs(v.mean() - expected) < Z * se, f"{what}: {v.mean():.6g} vs {expected:.6g} (SE {se:.3g})"
    return se


@pytest.mark.parametrize(
    "mode, pd, wfrac",
    [("fluid", None, 1.0), ("additive", None, 0.5), ("fluid", (600.0, 0.4), 0.8)],
)
def test_drive_response_regression(mode, pd, wfrac):
    """The frames' sin/cos components at f_d are A H(f_d) (times H_pd) times the exposure
    average; f_d = 500 Hz, W ~ dt, so sinc(f_d W) ~ 0.83 and its phase pi f_d W are resolved."""
    amp, freq, phase = 80e-9, 500.0, 0.7
    w = wfrac * DT
    inj = (StageDrive(amp, freq, phase, mode),) + ((PhotodiodeFilter(*pd),) if pd else ())
    x = simulate(K, GAMMA, w, DT, 4096, key=jax.random.key(3), n_traces=24,
                 method="exact_frames", injections=inj)
    t = np.arange(4096) * DT
    a, b = fit_sincos(x, t, freq)
    ea, eb = expected_coeffs(amp, freq, phase, w, mode, pd)
    se_a = check_mean(a, ea, "sin coefficient")
    check_mean(b, eb, "cos coefficient")
    # the SE is the thermal one, 2 P_d(f_d) / (N dt) per trace: the drive adds no noise
    assert se_a < 2e-3 * np.hypot(ea, eb)


def test_drive_is_exact_with_common_random_numbers():
    """Same key with and without the drive: the difference is the deterministic drive term,
    to rounding, here against a brute-force quadrature of the response over each exposure;
    with several windows each gets its own average; jittered frames use their own times."""
    amp, freq, phase = 30e-9, 123.0, -0.4
    wins = [DT / 4, DT]
    drv = StageDrive(amp, freq, phase)
    kw = dict(key=jax.random.key(5), n_traces=2, method="exact_frames")
    x0 = simulate(K, GAMMA, ExposureWindows(wins), DT, 300, **kw)
    x1 = simulate(K, GAMMA, ExposureWindows(wins), DT, 300, injections=(drv,), **kw)
    fc = K / (2 * np.pi * GAMMA)
    resp = 1j * freq / (fc + 1j * freq)
    tn = np.arange(300) * DT
    for j, w in enumerate(wins):
        s = np.linspace(0, w, 4001)
        inst = np.imag(amp * resp * np.exp(1j * (2 * np.pi * freq * (tn[:, None] + s) + phase)))
        ref = np.trapezoid(inst, s, axis=1) / w
        np.testing.assert_allclose(np.asarray(x1 - x0)[j], np.broadcast_to(ref, (2, 300)),
                                   atol=1e-7 * amp)
    jit = (TimingJitter(2e-5),)
    y0, t0 = simulate(K, GAMMA, DT / 2, DT, 200, injections=jit, return_times=True, **kw)
    y1 = simulate(K, GAMMA, DT / 2, DT, 200, injections=jit + (drv,), **kw)
    t0 = np.asarray(t0)
    s = np.linspace(0, DT / 2, 2001)
    inst = np.imag(amp * resp * np.exp(1j * (2 * np.pi * freq * (t0[..., None] + s) + phase)))
    np.testing.assert_allclose(np.asarray(y1 - y0), np.trapezoid(inst, s, axis=-1) / (DT / 2),
                               atol=1e-7 * amp)


def test_stage_positions_are_the_instantaneous_stage():
    drv = StageDrive(40e-9, 37.5, 1.1, mode="additive")
    sp = stage_positions(drv, DT, 1000)
    n = np.arange(1000)
    np.testing.assert_allclose(sp, 40e-9 * np.sin(2 * np.pi * 37.5 * n * DT + 1.1), rtol=0, atol=1e-12 * 40e-9)
    # an additive drive seen with a (nearly) instantaneous exposure is the stage itself
    kw = dict(key=jax.random.key(9), method="exact_frames")
    x0 = simulate(K, GAMMA, 1e-9 * DT, DT, 1000, **kw)
    x1 = simulate(K, GAMMA, 1e-9 * DT, DT, 1000, injections=(drv,), **kw)
    np.testing.assert_allclose(np.asarray(x1 - x0)[0], sp, rtol=0, atol=1e-7 * 40e-9)


def test_volts_scaling_and_tracking_noise_in_metres():
    rd = 87e-9  # m/V
    kw = dict(key=jax.random.key(11), n_traces=3, method="exact_frames", tracking_std=4e-9)
    drv = StageDrive(20e-9, 90.0)
    xm = simulate(K, GAMMA, DT / 2, DT, 500, injections=(drv,), **kw)
    xv = simulate(K, GAMMA, DT / 2, DT, 500, injections=(drv, Sensitivity(rd)), **kw)
    np.testing.assert_allclose(np.asarray(xv), np.asarray(xm) / rd, rtol=1e-12)
    pm = simulate_photodiode(K, GAMMA, DT, 256, key=jax.random.key(2), oversample=8, tracking_std=3e-9)
    pv = simulate_photodiode(K, GAMMA, DT, 256, key=jax.random.key(2), oversample=8, tracking_std=3e-9,
                             injections=(Sensitivity(rd),))
    np.testing.assert_allclose(np.asarray(pv), np.asarray(pm) / rd, rtol=1e-12)
    gm, _ = generate(K, GAMMA, DT, DT / 2, 64, 1, substeps=8)
    gv, _ = generate(K, GAMMA, DT, DT / 2, 64, 1, substeps=8, volts_per_m=1 / rd)
    np.testing.assert_allclose(gv, gm / rd, rtol=1e-12)


def lorentzian(f):
    tau = GAMMA / K
    return 2 * SIGMA2 * tau / (1 + (2 * np.pi * f * tau) ** 2)


@pytest.mark.parametrize("pd, m", [(None, 16), ((500.0, 0.3), 8)])
def test_antialiased_photodiode_psd_and_variance(pd, m):
    """Averaged periodograms below 0.4 fs equal the unblurred, unaliased Lorentzian (times the
    diode's |H_pd|^2) plus the floor eps2 dt (the folded or blurred spectra differ by 50 % and
    20 % near 0.4 fs); the output variance is the integral of the filtered PSD plus eps2."""
    n, n_tr, eps = 4096, 32, 5e-9
    inj = (PhotodiodeFilter(*pd),) if pd else ()

    def psd(f):
        if pd is None:
            return lorentzian(f)
        return lorentzian(f) * (pd[1] ** 2 + (1 - pd[1] ** 2) / (1 + (f / pd[0]) ** 2))

    x = np.asarray(simulate_photodiode(K, GAMMA, DT, n, key=jax.random.key(21), n_traces=n_tr,
                                       oversample=m, tracking_std=eps, injections=inj))
    per = np.abs(np.fft.rfft(x - x.mean(axis=1, keepdims=True), axis=1)) ** 2 * DT / n
    f = np.fft.rfftfreq(n, DT)
    band = (f > 0) & (f < 0.4 / DT)
    ratio = per[:, band] / (psd(f[band]) + eps**2 * DT)
    nb = 32  # bins per block: each block mean has relative SE 1/sqrt(n_tr nb) (Gamma law)
    blocks = ratio[:, : ratio.shape[1] // nb * nb].reshape(n_tr, -1, nb).mean(axis=(0, 2))
    z = (blocks - 1) * np.sqrt(n_tr * nb)
    assert np.max(np.abs(z)) < Z, z
    assert abs(ratio.mean() - 1) < Z / np.sqrt(ratio.size), ratio.mean()
    # the folded, blurred camera spectrum at the same rate would fail at the top of the band
    top = f[band][f[band] > 0.35 / DT]
    folded = sum(lorentzian(top + j / DT) for j in range(-200, 201))
    assert np.min(folded / lorentzian(top)) > 1.3
    # variance: integral of the filtered Lorentzian (independent Kaiser taps) plus eps2
    h = kaiser_lowpass(m)
    ff = np.linspace(0, 0.5 / DT, 20001)
    j = np.arange(h.size) - h.size // 2
    gain = np.cos(2 * np.pi * ff[:, None] * DT / m * j) @ h
    np.testing.assert_allclose(gain[::100], antialias_gain(ff[::100], DT, m), atol=1e-9)
    expect = 2 * np.trapezoid(psd(ff) * gain**2, ff) + eps**2
    check_mean(x.var(axis=1) * n / (n - 1), expect, "output variance")


def lag_stats(x):
    x = np.asarray(x) - np.asarray(x).mean(axis=1, keepdims=True)
    return (x * x).mean(axis=1), (x[:, 1:] * x[:, :-1]).mean(axis=1)


def assert_same(u, v, what):
    """Two independent samples of per-trace statistics have the same mean (Z SEs)."""
    se = np.hypot(u.std(ddof=1) / np.sqrt(u.size), v.std(ddof=1) / np.sqrt(v.size))
    assert abs(u.mean() - v.mean()) < Z * se, f"{what}: {u.mean():.5g} vs {v.mean():.5g} (SE {se:.3g})"


@pytest.mark.parametrize("aa", [False, True])
def test_simulator_agrees_with_numpy_generator(aa):
    """Variance, lag-1 autocovariance and the drive's sin/cos components of blurtrap's frames
    and of the independent generator agree within their Monte Carlo errors."""
    n, n_tr, eps = 2048, 32, 3e-9
    drive = dict(amplitude_m=60e-9, frequency_Hz=310.0, phase=0.3, mode="fluid")
    drv = StageDrive(60e-9, 310.0, 0.3, "fluid")
    if aa:
        x = simulate_photodiode(K, GAMMA, DT, n, key=jax.random.key(4), n_traces=n_tr,
                                oversample=8, tracking_std=eps, injections=(drv,))
        g, stage = generate(K, GAMMA, DT, None, n, 17, n_traces=n_tr, tracking_std=eps,
                            drive=drive, anti_aliasing=True, oversample=8)
    else:
        x = simulate(K, GAMMA, DT / 2, DT, n, key=jax.random.key(4), n_traces=n_tr,
                     method="exact_frames", tracking_std=eps, injections=(drv,))
        g, stage = generate(K, GAMMA, DT, DT / 2, n, 17, n_traces=n_tr, tracking_std=eps,
                            drive=drive, substeps=32)
    np.testing.assert_allclose(stage, stage_positions(drv, DT, n), rtol=0, atol=1e-20)
    t = np.arange(n) * DT
    ax, bx = fit_sincos(x, t, 310.0)
    ag, bg = fit_sincos(g, t, 310.0)
    assert_same(ax, ag, "sin component")
    assert_same(bx, bg, "cos component")
    if not aa:  # both also equal the analytic value
        ea, _ = expected_coeffs(60e-9, 310.0, 0.3, DT / 2)
        check_mean(ag, ea, "generator sin component")
    # the thermal part: remove the fitted drive, then compare the moments
    th = 2 * np.pi * 310.0 * t
    rx = np.asarray(x) - ax[:, None] * np.sin(th) - bx[:, None] * np.cos(th)
    rg = g - ag[:, None] * np.sin(th) - bg[:, None] * np.cos(th)
    for (u, v), what in zip(zip(lag_stats(rx), lag_stats(rg)), ("variance", "lag-1 autocovariance")):
        assert_same(u, v, what)
    if not aa:  # and the generator's moments are DESIGN 2.5's C(0), C(1)
        al, rho = DT / 2 / (GAMMA / K), np.exp(-DT / (GAMMA / K))
        s_al = 2 / al - 2 * (1 - np.exp(-al)) / al**2
        b_al = (np.sinh(al / 2) / (al / 2)) ** 2
        var_g, c1_g = lag_stats(rg)
        check_mean(var_g, SIGMA2 * s_al + eps**2, "generator variance")
        check_mean(c1_g, SIGMA2 * b_al * rho, "generator lag-1 autocovariance")


def test_float32_drive_keeps_its_phase_over_long_records():
    drv = StageDrive(50e-9, 499.0, 0.0, "additive")
    kw = dict(key=jax.random.key(1), method="exact_frames")
    n = 200_000
    x0 = simulate(K, GAMMA, 1e-9 * DT, DT, n, dtype=jnp.float32, **kw)
    x1 = simulate(K, GAMMA, 1e-9 * DT, DT, n, dtype=jnp.float32, injections=(drv,), **kw)
    err = np.asarray(x1 - x0, np.float64)[0, -1000:] - stage_positions(drv, DT, n)[-1000:]
    assert np.max(np.abs(err)) < 1e-6 * 50e-9  # float32 phases w t_n would be 1e-3 off


def test_refusals():
    with pytest.raises(ValueError, match="HydrodynamicFriction"):
        simulate(K, GAMMA, DT, DT, 16, key=jax.random.key(0), method="spectral",
                 injections=(StageDrive(1e-9, 10.0), HydrodynamicFriction(1e-6)))
    with pytest.raises(ValueError, match="at most one Sensitivity"):
        simulate(K, GAMMA, DT, DT, 16, key=jax.random.key(0),
                 injections=(Sensitivity(1e-7), Sensitivity(2e-7)))
    with pytest.raises(ValueError, match="TimingJitter"):
        simulate_photodiode(K, GAMMA, DT, 16, key=jax.random.key(0), injections=(TimingJitter(1e-6),))
    with pytest.raises(ValueError, match="mode"):
        StageDrive(1e-9, 10.0, mode="lab")
    with pytest.raises(ValueError, match="frequency"):
        StageDrive(1e-9, -1.0)
    with pytest.raises(ValueError, match="rd"):
        Sensitivity(0.0)
    with pytest.raises(ValueError, match="oversample"):
        simulate_photodiode(K, GAMMA, DT, 16, key=jax.random.key(0), oversample=1)
