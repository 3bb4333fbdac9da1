"""x/y calibration: principal axes, k per axis, shared gamma, against frames drawn by an
independent numpy generator (tests/_xy_gen.py: circulant embedding of the exact frame
autocovariance per principal axis, then rotation and isotropic tracking noise)."""

import math
import os
import sys

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference._xy import _angle_stats, _principal

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))
from _xy_gen import xy_frames  # noqa: E402

K1, K2, GAMMA, W, DT, PHI, EPS, N = 2e-5, 5e-5, 1e-8, 4e-4, 5e-4, 0.5, 3e-9, 4096


def _xy(seed, k1=K1, k2=K2, phi=PHI, n=N):
    x, y = xy_frames(n, k1, k2, GAMMA, W, DT, phi, EPS, np.random.default_rng(seed))
    return bt.xy_from_arrays(x, y, frame_interval=DT, exposure=W)


def _wrap(d):
    """An angle difference mod pi, in (-pi/2, pi/2]."""
    return (d + math.pi / 2) % math.pi - math.pi / 2


def test_recovery_z_scores():
    """k1, k2, phi, gamma within their stated SEs over 5 seeds: every |z| < 4 and the mean
    z^2 (20 values, expectation 1) below 2.2 (chi2_20 / 20 exceeds 2.2 with p ~ 0.002)."""
    zs = []
    for seed in range(5):
        r = bt.calibrate_xy(_xy(seed), separate=False)
        assert r.resolved
        zs += [(r.k1 - K1) / r.k1_err, (r.k2 - K2) / r.k2_err, _wrap(r.phi - PHI) / r.phi_err,
               (r.gamma - GAMMA) / r.gamma_err]
    zs = np.array(zs)
    assert np.all(np.abs(zs) < 4), zs
    assert np.mean(zs**2) < 2.2, zs


def test_stiffness_matrix_and_lab_outputs():
    r = bt.calibrate_xy(_xy(11), separate=True)
    kmat = r.principal_axes @ np.diag([r.k1, r.k2]) @ r.principal_axes.T
    np.testing.assert_allclose(r.stiffness_matrix, kmat, rtol=1e-12)
    # the detector-axis values against the truth, within their stated SEs
    c, s = math.cos(PHI), math.sin(PHI)
    truth = (K1 * c * c + K2 * s * s, K1 * s * s + K2 * c * c, (K1 - K2) * s * c)
    for est, err, t in zip((r.k_x, r.k_y, r.k_xy), (r.k_x_err, r.k_y_err, r.k_xy_err), truth,
                           strict=True):
        assert abs(est - t) < 4 * err
    d = r.to_dict()
    assert d["k1"] == r.k1 and d["phi"] == r.phi and d["joint"]["gamma"] == r.gamma
    assert "pN/nm" in r.summary() and "deg" in r.summary()
    assert "<table>" in r._repr_html_()
    # the expected (Whittle Fisher) SE of the joint gamma agrees with the fit's own SE (exact
    # likelihood, observed information) to 20 %, and sharing gamma gains over either axis
    joint_se, se1, se2 = r.expected_gamma_se
    assert abs(joint_se / r.gamma_err - 1) < 0.2, (joint_se, r.gamma_err)
    assert r.gamma_precision_gain == pytest.approx(min(se1, se2) / joint_se)
    assert 1.2 < r.gamma_precision_gain < 3.0
    assert d["gamma_precision_gain"] == r.gamma_precision_gain


@pytest.mark.parametrize(("w", "dt"), [(W, DT), (8e-5, 1e-4)])
def test_phi_error_matches_monte_carlo(w, dt):
    """The delta-method SE of phi against the SD of phi over 300 numpy draws (no fits); the SD
    of an SD from 300 draws is ~4 %, the tolerance 15 %. At dt = 0.1 ms the frames are
    correlated (rho1 rho2 ~ 0.5) and the lag terms of the SE matter (without them the SE is
    ~40 % too small)."""
    phis = []
    for seed in range(300):
        x, y = xy_frames(N, K1, K2, GAMMA, w, dt, PHI, EPS, np.random.default_rng(1000 + seed))
        phis.append(_principal(np.stack([x, y], axis=1))[0])
    sd = np.std(_wrap(np.array(phis) - PHI), ddof=1)
    xy = bt.xy_from_arrays(np.zeros(N) + 1e-8 * (np.arange(N) % 2), np.zeros(N) + 1e-8 *
                           (np.arange(N) % 3), frame_interval=dt, exposure=w)
    se, _ = _angle_stats(K1, K2, GAMMA, EPS**2, xy, 1.0, 0.0)
    assert abs(se / sd - 1) < 0.15, (se, sd)


@pytest.mark.parametrize("angle", [0.3, 1.4, -2.0])
def test_phi_invariance_under_rotation(angle):
    """Rotating the data by a known angle shifts phi by that angle (mod pi) and leaves k1,
    k2, gamma unchanged."""
    xy = _xy(3)
    a = bt.calibrate_xy(xy, separate=False)
    b = bt.calibrate_xy(xy.rotated(angle), separate=False)
    assert abs(_wrap(b.phi - a.phi - angle)) < 1e-10
    assert -math.pi / 2 < b.phi <= math.pi / 2
    for name in ("k1", "k2", "gamma", "phi_err"):
        assert getattr(b, name) == pytest.approx(getattr(a, name), rel=1e-6), name


def test_isotropic_limit_notes_undefined_phi():
    k = 3e-5
    r = bt.calibrate_xy(_xy(5, k1=k, k2=k), separate=False)
    assert not r.resolved
    assert any("phi is undefined" in n for n in r.notes)
    assert abs(r.k1 - k) < 4 * r.k1_err and abs(r.k2 - k) < 4 * r.k2_err
    assert abs(r.gamma - GAMMA) < 4 * r.gamma_err
    # an anisotropic trap is resolved (the same seed)
    assert bt.calibrate_xy(_xy(5), separate=False).resolved


def test_bad_input():
    rec = bt.Recording(np.random.default_rng(0).normal(0, 1e-8, 100), frame_interval=DT,
                       exposure=W)
    with pytest.raises(TypeError, match="xy must be an XYRecording"):
        bt.calibrate_xy(rec)
    with pytest.raises(ValueError, match="k = 'shared' cannot be set"):
        bt.calibrate_xy(_xy(0, n=256), k="shared")


def test_calibrate_points_xy_recordings_to_calibrate_xy():
    rng = np.random.default_rng(0)
    xy = bt.xy_from_arrays(rng.normal(size=256) * 1e-8, rng.normal(size=256) * 1e-8,
                           frame_interval=1e-3, exposure=1e-3)
    for data in (xy, [xy]):
        with pytest.raises(TypeError, match="calibrate_xy"):
            bt.calibrate(data)


def _rotated_axes(rng, k1, k2, gamma, dt, n, phi):
    """x, y [m] of a trap whose principal axes (independent exact AR(1) samples of the OU
    motion, stiffness k1 and k2, point sampling) lie at ``phi`` from x; numpy only."""
    from scipy.signal import lfilter

    kt = 1.380649e-23 * 295.0

    def ou(k):
        a = math.exp(-k * dt / gamma)
        e = rng.standard_normal(n) * math.sqrt(kt / k)
        e[1:] *= math.sqrt(1 - a * a)
        return lfilter([1.0], [1.0, -a], e)

    u, v = ou(k1), ou(k2)
    return math.cos(phi) * u - math.sin(phi) * v, math.sin(phi) * u + math.cos(phi) * v


def test_unequal_axis_sensitivities_are_named():
    # y recorded with 1.3x the x sensitivity (one Rd used for both axes of a QPD): k1, k2,
    # gamma and phi came back 14-55 SE off with no note; the principal-axis motions are then
    # correlated at lag 1, which one isotropic friction cannot produce. Numpy AR(1) axes.
    g, dt, n = 6 * math.pi * 9.5e-4 * 1.53e-6, 1 / 1500, 16384

    def coupled_notes(seed, gain):
        rng = np.random.default_rng(seed)
        x, y = _rotated_axes(rng, 2e-5, 5e-5, g, dt, n, 0.5)
        x = x + 2e-9 * rng.standard_normal(n)
        y = y + 2e-9 * rng.standard_normal(n)
        res = bt.calibrate_xy(bt.xy_from_arrays(x, gain * y, frame_interval=dt,
                                                exposure=1e-9 * dt, temperature=295.0),
                              separate=False)
        return [s for s in res.notes if "principal axes are coupled" in s]

    assert coupled_notes(33, 1.3)
    assert not any(coupled_notes(s, 1.0) for s in (34, 35, 36))


def test_cross_talk_between_the_channels_is_named():
    """x' = x + c y (cross-talk of a quadrant photodiode's channels): the principal-axis
    motions are mixtures of the two axes whose lag-0 cross-covariance vanishes, so the lag-1
    test is nearly blind (an independent pass: 8 % cross-talk, k1 3.5-7.6 SE off, no note).
    Their cross-spectrum has the shape of the two axes' normalised spectra's difference,
    which the score over every frequency sees. Numpy AR(1) axes."""
    g, dt, n = 6 * math.pi * 9.5e-4 * 1.0e-6, 1e-3, 32768

    def notes(seed, talk):
        rng = np.random.default_rng(seed)
        x, y = _rotated_axes(rng, 2e-5, 4e-5, g, dt, n, 0.4)
        x, y = x + talk * y, y  # channel y leaks into x
        res = bt.calibrate_xy(bt.xy_from_arrays(x + 2e-9 * rng.standard_normal(n),
                                                y + 2e-9 * rng.standard_normal(n),
                                                frame_interval=dt, exposure=1e-9 * dt,
                                                temperature=295.0), separate=False)
        return [s for s in res.notes if "principal axes are coupled" in s]

    assert all(notes(s, 0.1) for s in (40, 41))
    assert not any(notes(s, 0.0) for s in (40, 41))


def test_a_refusal_names_the_axes_alone():
    """2 nm of tracking noise on x and 20 nm on y (more than the stiff axis's motion): the
    joint fit's one eps^2 cannot describe it and the fit is refused. The refusal gives each
    principal axis fitted alone and names unequal tracking noise, in k1/k2 (it listed
    outliers, a wrong exposure or a short record, and the internal name k[axis2])."""
    dt, n, rng = 1e-3, 16384, np.random.default_rng(900)
    x, y = _rotated_axes(rng, 2e-5, 3e-5, 6 * math.pi * 9.5e-4 * 1.0e-6, dt, n, 0.4)
    x = x + 2e-9 * rng.standard_normal(n)
    y = y + 2e-8 * rng.standard_normal(n)
    with pytest.raises(bt.FitError) as err:
        bt.calibrate_xy(bt.xy_from_arrays(x, y, frame_interval=dt, exposure=1e-9 * dt,
                                          temperature=295.0))
    msg = str(err.value)
    assert "axis 1" in msg and "axis 2" in msg and "calibrate each axis alone" in msg
    assert "k[axis" not in msg
