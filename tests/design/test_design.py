"""Experiment design: the Fisher information against independent references (the dense
Gaussian information, the discrete Whittle sum by finite differences, and the scatter of
simulated fits), and the optimiser's recommendations."""

import math

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.design import exact_information, whittle_information

KB = 1.380649e-23
GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
K = 5e-5
DT = 1 / 1500


def se(info):
    return np.sqrt(np.diag(np.linalg.inv(np.asarray(info))))


def censored(cov):
    """The covariance of the estimates with eps^2 >= 0 (projected Gaussian; scipy's normal
    moments and the precision-matrix form of the projection, written apart from
    blurtrap.design.bounded_covariance): theta_o = Z_o + b (max(Z_e, 0) - Z_e) with
    b = -P_oo^-1 P_oe, eps^2 relative so that its mean is 1 and its SD sqrt(cov_ee)."""
    from scipy.stats import norm

    sd = math.sqrt(cov[2, 2])
    z = 1 / sd
    mean = z * norm.cdf(z) + norm.pdf(z)
    var = (z * z + 1) * norm.cdf(z) + z * norm.pdf(z) - mean**2  # of max(Z_e, 0) / sd
    p = np.linalg.inv(cov)
    b = np.append(-np.linalg.solve(p[:2, :2], p[:2, 2]), 1.0)
    # theta_o = U + b_o Z_e' with Z_e' = max(Z_e, 0) and U independent of Z_e
    out = cov - np.outer(b, b) * cov[2, 2] * (1 - var)
    return out


@pytest.mark.parametrize("w", [DT, 0.1 * DT])
def test_whittle_information_matches_exact_gaussian_information(w):
    """Long-record (Whittle) and exact information agree to O(1/N) at N = 512."""
    wi = se(whittle_information(K, GAMMA, w, DT, 512, 295.0, 4e-18))
    ex = se(exact_information(K, GAMMA, w, DT, 512, 295.0, 4e-18))
    np.testing.assert_allclose(wi, ex, rtol=0.01)


def test_whittle_quadrature_matches_the_discrete_sum():
    """The continuum average equals 1/2 sum_j g g^T at the Fourier frequencies, with g from
    central finite differences of the public, checked psd_measured."""
    n, w, eps2 = 4096, 0.5 * DT, 4e-18
    brute = _brute_information(K, GAMMA, w, DT, n, eps2)
    ours = np.asarray(whittle_information(K, GAMMA, w, DT, n, 295.0, eps2))
    np.testing.assert_allclose(ours, brute, rtol=2e-3)


def test_predicted_se_matches_the_scatter_of_simulated_fits():
    """300 simulated camera records (W = dt, 16 384 frames, 2 nm noise), fitted by the
    vmapped Whittle fit: the SD of log k and log gamma matches the predicted relative SE
    within 3 standard errors of an SD estimate (sqrt(1/(2 (n-1))) = 4.1 %)."""
    n, reps = 16384, 300
    x = bt.simulate(K, GAMMA, DT, DT, n, key=jax.random.key(21), n_traces=reps,
                    method="exact_frames", tracking_std=2e-9)
    res = bt.calibrate_batch(np.asarray(x).reshape(reps, n), frame_interval=DT, exposure=DT)
    ok = np.array([s == "ok" for s in res.status])
    assert ok.mean() > 0.95
    pred = se(whittle_information(K, GAMMA, DT, DT, n, 295.0, 4e-18))
    sd = [np.std(np.log(np.asarray(res.k)[ok]), ddof=1),
          np.std(np.log(np.asarray(res.gamma)[ok]), ddof=1)]
    tol = 3 * math.sqrt(1 / (2 * (ok.sum() - 1)))
    np.testing.assert_allclose(sd, pred[:2], rtol=tol)


def test_design_recommends_the_best_candidate_and_beats_w_equal_dt():
    """The design of notebooks/06_design.ipynb (a stiffness range around K, photon-limited
    noise): the same static settings compile the same optimiser programs, which the
    notebook's kernel then loads from the compilation cache."""
    r = bt.design(k=(0.4 * K, 2 * K), gamma=GAMMA, max_fps=1500, min_exposure=20e-6,
                  total_time=30.0, tracking_std=2e-9, photon_limited=True, target="k",
                  current=[(DT, DT, 45000)], series=(1, 2))
    objs = [c.objective for c in r.candidates]
    assert r.best.objective == min(objs)
    naive = next(c for c in r.candidates if c.label.startswith("W = dt"))
    assert r.best.objective < 0.9 * naive.objective  # an exposure series helps k here
    for c in r.candidates:  # constraints hold
        for dt, w, nf in c.recordings:
            assert dt >= DT * (1 - 1e-9) and 0 < w <= dt * (1 + 1e-9) and nf > 0
        assert sum(dt * nf for dt, _, nf in c.recordings) == pytest.approx(30.0, rel=1e-6)
    assert set(r.predicted_se) == {"k", "gamma", "tracking_var"}
    assert "recommended" in r.summary()
    # an independent pass fitted such a recommendation with calibrate (one shared eps^2):
    # k 0.04 x the truth; the summary says what the SEs assume
    assert len({w for _, w, _ in r.best.recordings}) > 1
    assert r.notes and "calibrate fits one eps^2 shared by all recordings" in r.notes[0]
    assert r.notes[0] in r.summary() and r.to_dict()["notes"] == list(r.notes)
    assert r.to_dict()["best"]["label"] == r.best.label


def test_design_validates_its_arguments():
    with pytest.raises(ValueError, match="target"):
        bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=4096, target="f")
    with pytest.raises(ValueError, match="gamma"):
        bt.design(k=K, max_fps=1500, n_frames=4096)
    with pytest.raises(ValueError, match="exactly one of n_frames"):
        bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=4096, total_time=1.0)
    with pytest.raises(ValueError, match="max_fps"):
        bt.design(k=K, gamma=GAMMA, max_fps=-1, n_frames=4096)
    with pytest.raises(ValueError, match="photon_limited"):
        bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=4096, photon_limited=True)


def test_design_never_recommends_an_unidentified_design():
    """500 fps, k = 0.5 pN/nm (dt/tau ~ 36): no candidate identifies gamma (relative SE
    > 100 %); before, the W = dt candidate with a NaN objective was sorted first and the
    optimised series (gamma SE 241 %) was recommended for k."""
    with pytest.raises(ValueError, match="identifies both k and gamma"):
        bt.design(k=5e-4, radius=1.53e-6, max_fps=500, total_time=60.0, tracking_std=2e-9)


def test_design_without_tracking_noise_optimises_its_series():
    """tracking_std = 0: eps^2 is no parameter, also inside the optimiser (before, the traced
    eps^2 = 0 made log eps^2 a parameter there, every optimised candidate had a singular
    information and only the two fixed candidates were compared). The optimised single
    recording at W = dt is W = dt at the fastest frame rate, so its SE equals that one's to
    the optimiser's tolerance, and each SE is the Whittle information's, from _fisher."""
    from blurtrap.design import whittle_information

    res = bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=65536, tracking_std=0.0,
                    series=(1, 2))
    labels = [c.label for c in res.candidates]
    assert "optimised single recording" in labels and "optimised series of 2 exposures" in labels
    for c in res.candidates:
        assert set(c.predicted_se) == {"k", "gamma"} and np.isfinite(c.objective)
        info = sum(np.asarray(whittle_information(K, GAMMA, w, dt, n, 295.0, 0.0))
                   for dt, w, n in c.recordings)
        se = np.sqrt(np.diag(np.linalg.inv(info)))
        assert np.allclose([c.predicted_se["k"][0], c.predicted_se["gamma"][0]], se, rtol=1e-9)
    one = res.candidates[labels.index("optimised single recording")]
    wdt = res.candidates[labels.index("W = dt at the fastest frame rate")]
    assert one.objective <= wdt.objective * (1 + 1e-4)


def _brute_information(k, gamma, w, dt, n, eps2, temperature=295.0):
    """1/2 sum_j g g^T at the Fourier frequencies, g = d log P / d (log k, log gamma,
    log eps^2) by central differences of the public psd_measured (independent of _fisher)."""
    f = np.arange(1, n) / (n * dt)
    th0 = np.log([k, gamma, eps2])

    def logp(th):
        kk, gg, e2 = np.exp(th)
        return np.log(np.asarray(bt.psd_measured(f, kk, gg, w, temperature, dt, e2)))

    grads = []
    for i in range(3):
        h = np.zeros(3)
        h[i] = 1e-5
        grads.append((logp(th0 + h) - logp(th0 - h)) / 2e-5)
    g = np.stack(grads, axis=1)
    return 0.5 * g.T @ g


def test_known_friction_is_prior_information_on_log_gamma():
    """friction_se = 0: the covariance of (log k, log eps^2) is the inverse of their own block
    of the information (gamma held); friction_se = s: the information plus 1/s^2 on log gamma.
    Reference: the brute-force Whittle information."""
    from blurtrap.design import relative_se

    n, w, eps2 = 4096, 0.3 * DT, 4e-18
    brute = _brute_information(K, GAMMA, w, DT, n, eps2)
    recs = [(DT, w, n)]
    for bounded in (False, True):
        def ref(info):
            cov = np.linalg.inv(info)
            return np.sqrt(np.diag(censored(cov) if bounded else cov))

        args = (recs, [K], GAMMA, 295.0, eps2, DT, False, True)
        held = np.asarray(relative_se(*args, 0.0, bounded=bounded))[0]
        block = brute.copy()
        block[1, :], block[:, 1], block[1, 1] = 0.0, 0.0, 1e24  # gamma held
        np.testing.assert_allclose(held[[0, 2]], ref(block)[[0, 2]], rtol=3e-3)
        assert held[1] < 1e-9
        prior = np.asarray(relative_se(*args, 0.05, bounded=bounded))[0]
        with_prior = brute + np.diag([0.0, 1 / 0.05**2, 0.0])
        np.testing.assert_allclose(prior, ref(with_prior), rtol=3e-3)
        free = np.asarray(relative_se(*args, bounded=bounded))[0]
        np.testing.assert_allclose(free, ref(brute), rtol=3e-3)


def test_determinant_and_force_sensitivity_objectives():
    """The W = dt candidate's objective: det(cov of log k, log gamma)^(1/4) (D-optimal) and
    the force sensitivity sqrt(v_kk + v_gg/4 - v_kg + s^2/4) (Rf = k' sqrt(gamma0/gamma') of a
    volts fit), from the brute-force information."""
    n, eps2 = 4096, 4e-18
    cov = censored(np.linalg.inv(_brute_information(K, GAMMA, DT, DT, n, eps2)))
    kw = dict(k=K, gamma=GAMMA, max_fps=1500, n_frames=n, tracking_std=2e-9, series=())
    det = bt.design(target="determinant", **kw)
    naive = next(c for c in det.candidates if c.label.startswith("W = dt"))
    assert naive.objective == pytest.approx(np.linalg.det(cov[:2, :2]) ** 0.25, rel=3e-3)
    fs = bt.design(target="force_sensitivity", friction_error=0.04, **kw)
    naive = next(c for c in fs.candidates if c.label.startswith("W = dt"))
    ref = math.sqrt(cov[0, 0] + cov[1, 1] / 4 - cov[0, 1] + 0.04**2 / 4)
    assert naive.objective == pytest.approx(ref, rel=3e-3)
    assert naive.predicted_se["force_sensitivity"][0] == pytest.approx(ref, rel=3e-3)
    assert "SE force_sensitivity %" in fs.summary()
    with pytest.raises(ValueError, match="friction_error"):
        bt.design(target="force_sensitivity", **kw)
    with pytest.raises(ValueError, match="friction_error"):
        bt.design(friction_error=-0.1, **kw)
    with pytest.raises(ValueError, match="known exactly"):
        bt.design(target="gamma", friction_error=0.0, **kw)


def test_known_friction_makes_dt_much_larger_than_tau_designable_and_fittable():
    """500 fps, k = 0.5 pN/nm (dt/tau ~ 36): without the friction no design identifies both
    (test above); with it the recommended exposure series identifies k, and calibrate with
    gamma held fits such a series (before: refused as 'no temporal information' although the
    exposures separate k from eps^2). k within 3 SE of the truth on one simulated series."""
    gamma = 6 * math.pi * 0.00095 * 1.53e-6
    k = 5e-4
    res = bt.design(k=k, gamma=gamma, max_fps=500, total_time=30.0, tracking_std=2e-9,
                    friction_error=0.0, series=(2,))
    assert "series" in res.best.label and math.isfinite(res.best.objective)
    assert res.predicted_se["k"] < 0.1 and res.predicted_se["gamma"] == 0.0
    recs = []
    for i, (dt, w, nf) in enumerate(res.best.recordings):
        x = bt.simulate(k, gamma, w, dt, int(nf), key=jax.random.key(40 + i),
                        method="exact_frames", tracking_std=2e-9)
        recs.append(bt.Recording(np.asarray(x).ravel(), frame_interval=dt, exposure=w))
    fit = bt.calibrate(recs, fixed={"gamma": gamma})
    assert abs(fit.k - k) < 3 * fit.k_err
    assert any("separates k from eps^2" in n for n in fit.notes)
