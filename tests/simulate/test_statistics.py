"""Statistical tests of the simulator against the exact physics (fixed keys, 4-sigma bounds)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

from blurtrap.physics import BOLTZMANN, frame_autocovariance, measured_variance
from blurtrap.physics._spectra import _sample_variance_var
from blurtrap.simulate import ExposureWindows, SubstepBiasWarning, simulate

T = 295.0
# (label, bead radius [m], k [N/m], tau [s]); gamma = k tau = 6 pi eta r with eta ~ 0.00089 Pa s
SETTINGS = [
    ("r1.6um_k0.05", 1.6e-6, 5e-5, 0.537e-3),
    ("r0.4um_k0.05", 0.4e-6, 5e-5, 0.134e-3),
    ("r1.6um_k0.0125", 1.6e-6, 1.25e-5, 2.148e-3),
]


def sigma2(k):
    return BOLTZMANN * T / k


def viscosity(k, tau, r):
    return k * tau / (6 * np.pi * r)

Z = 4.0  # tolerance in standard errors
ALPHAS = np.array([0.1, 0.5, 1.0, 2.0, 4.0])  # W / tau


def _var_check(x, k, gamma, w, dt, dtype=np.float64):
    """mean of x^2 over (traces, frames) vs sigma2 S(alpha); SE from the correlated-frame
    formula var(s^2) = (2/N^2) sum (N-|n|) C(n)^2, divided by the number of traces."""
    x = np.asarray(x, dtype=np.float64)
    n_tr, n = x.shape
    pred = float(measured_variance(k, gamma, w, T))
    se = float(np.sqrt(_sample_variance_var(n, sigma2(k), gamma / k, w, dt, 0.0) / n_tr))
    est = float(np.mean(x * x))
    assert abs(est - pred) < Z * se, (est / pred, se / pred)
    return est, pred, se


def test_settings_are_the_papers():
    for _, r, k, tau in SETTINGS:
        assert 0.00088 <= viscosity(k, tau, r) <= 0.00095  # water, ~ 20-25 C


@pytest.mark.parametrize("method", ["exact", "exact_frames"])
@pytest.mark.parametrize("setting", SETTINGS, ids=[s[0] for s in SETTINGS])
def test_variance_vs_exposure(setting, method):
    """var(X_m)/var(X) = S(alpha) over exposures, all windows from one run (Fig. 1a)."""
    _, _, k, tau = setting
    gamma = k * tau
    wins = ALPHAS * tau
    dt = wins.max()
    kw = {"substeps": 64} if method == "exact" else {}
    x = simulate(
        k, gamma, ExposureWindows(wins), dt, 1000, key=jax.random.key(11),
        n_traces=256, method=method, temperature=T, **kw,
    )
    assert x.shape == (wins.size, 256, 1000)
    for j, w in enumerate(wins):
        _var_check(x[j], k, gamma, w, dt)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_variance_single_exposure_dtypes(dtype):
    _, _, k, tau = SETTINGS[0]
    gamma, w, dt = k * tau, 0.8 * tau, 2.0 * tau
    for method in ("exact", "exact_frames"):
        kw = {"substeps": 32} if method == "exact" else {}
        x = simulate(k, gamma, w, dt, 2000, key=jax.random.key(3), n_traces=256,
                     method=method, dtype=dtype, **kw)
        assert x.dtype == dtype
        _var_check(x, k, gamma, w, dt)


def test_histogram_gaussian():
    """KS test of (effectively independent) frames against N(0, sigma2 S); the naive law
    N(0, sigma2) must be rejected (the test has power)."""
    _, _, k, tau = SETTINGS[1]
    gamma, w, dt = k * tau, 2.0 * tau, 2.0 * tau
    x = np.asarray(simulate(k, gamma, w, dt, 401, key=jax.random.key(5), n_traces=2000,
                            substeps=32))
    sample = x[:, ::100].ravel()  # 100 dt = 200 tau apart: independent to exp(-200)
    sd = float(np.sqrt(measured_variance(k, gamma, w)))
    assert scipy.stats.kstest(sample / sd, "norm").pvalue > 1e-3
    assert scipy.stats.kstest(sample / np.sqrt(sigma2(k)), "norm").pvalue < 1e-6


@pytest.mark.parametrize("method", ["exact", "exact_frames"])
def test_autocovariance_lags(method):
    """Lag-1 and lag-2 autocovariance vs C(n) = sigma2 B rho^n; SE from the spread over
    independent traces."""
    _, _, k, tau = SETTINGS[2]
    gamma, w, dt = k * tau, 1.0 * tau, 1.2 * tau
    kw = {"substeps": 16} if method == "exact" else {}
    x = np.asarray(simulate(k, gamma, w, dt, 2000, key=jax.random.key(7), n_traces=256,
                            method=method, **kw))
    for lag in (1, 2):
        per_trace = np.mean(x[:, lag:] * x[:, :-lag], axis=1)
        est, se = per_trace.mean(), per_trace.std(ddof=1) / np.sqrt(per_trace.size)
        pred = float(frame_autocovariance(lag, k, gamma, w, dt))
        assert abs(est - pred) < Z * se, (lag, est / pred, se / pred)
        if lag == 1:  # and it is distinguishable from the unblurred sigma2 rho
            naive = sigma2(k) * np.exp(-lag * dt / tau)
            assert abs(est - naive) > Z * se


def test_exact_frames_agrees_with_exact_substeps():
    """Same distribution: variance, lag-1 covariance and a two-sample KS test."""
    _, _, k, tau = SETTINGS[0]
    gamma, w, dt = k * tau, 1.5 * tau, 2.0 * tau
    a = np.asarray(simulate(k, gamma, w, dt, 1000, key=jax.random.key(1), n_traces=256,
                            substeps=64))
    b = np.asarray(simulate(k, gamma, w, dt, 1000, key=jax.random.key(2), n_traces=256,
                            method="exact_frames"))
    for stat in (lambda x: np.mean(x * x, 1), lambda x: np.mean(x[:, 1:] * x[:, :-1], 1)):
        sa, sb = stat(a), stat(b)
        se = np.sqrt(sa.var(ddof=1) / sa.size + sb.var(ddof=1) / sb.size)
        assert abs(sa.mean() - sb.mean()) < Z * se
    assert scipy.stats.ks_2samp(a[:, ::50].ravel(), b[:, ::50].ravel()).pvalue > 1e-3


def test_exact_frames_innovations_form_agrees_with_segment_law():
    """One exposure window draws the frames from their innovations form (one normal per frame);
    a one-element ExposureWindows uses the segment law (two normals per frame). Same law,
    from the first frame on: frame-0 variance and frame-0/1 covariance over many traces
    against C(0), C(1), and variance / lag-1 covariance of the two samplers against each
    other."""
    _, _, k, tau = SETTINGS[1]
    gamma, w, dt = k * tau, 0.7 * tau, 1.3 * tau
    kw = dict(n_traces=4096, method="exact_frames", temperature=T)
    inn = np.asarray(simulate(k, gamma, w, dt, 64, key=jax.random.key(21), **kw))
    seg = np.asarray(simulate(k, gamma, ExposureWindows([w]), dt, 64, key=jax.random.key(22),
                              **kw))[0]
    c0 = float(frame_autocovariance(0, k, gamma, w, dt))
    c1 = float(frame_autocovariance(1, k, gamma, w, dt))
    n = inn.shape[0]
    # the first frame: var of x^2 is 2 C0^2; of x0 x1 it is C0^2 + C1^2 (Gaussian)
    assert abs(np.mean(inn[:, 0] ** 2) - c0) < Z * np.sqrt(2 / n) * c0
    assert abs(np.mean(inn[:, 0] * inn[:, 1]) - c1) < Z * np.sqrt((c0**2 + c1**2) / n)
    for stat in (lambda x: np.mean(x * x, 1), lambda x: np.mean(x[:, 1:] * x[:, :-1], 1)):
        sa, sb = stat(inn), stat(seg)
        se = np.sqrt(sa.var(ddof=1) / sa.size + sb.var(ddof=1) / sb.size)
        assert abs(sa.mean() - sb.mean()) < Z * se
    assert scipy.stats.ks_2samp(inn[:, ::16].ravel(), seg[:, ::16].ravel()).pvalue > 1e-3


def test_euler_converges_to_exact():
    """Euler's variance bias ~ h/(2 tau) shrinks with h (measured), towards exact_frames."""
    _, _, k, tau = SETTINGS[0]
    gamma, w, dt = k * tau, 0.4 * tau, 1.0 * tau
    pred = float(measured_variance(k, gamma, w))
    n_tr, n = 512, 1000
    se = float(np.sqrt(_sample_variance_var(n, sigma2(k), tau, w, dt, 0.0) / n_tr)) / pred
    biases = []
    for substeps in (2, 4, 8):
        h = 0.4 / substeps
        x = simulate(k, gamma, w, dt, n, key=jax.random.key(substeps), n_traces=n_tr,
                     method="euler", substeps=substeps, bias_tol=1.0)
        b = float(np.mean(np.asarray(x) ** 2)) / pred - 1.0
        biases.append(b)
        # leading-order prediction h/2 (stationary Euler OU variance 1/(1-h/2))
        assert abs(b - h / 2) < 0.25 * h / 2 + Z * se, (substeps, b, h / 2, se)
    d = np.diff(biases)
    assert np.all(-d > Z * np.sqrt(2) * se), biases  # strictly shrinking with h


def test_euler_coarse_substeps_warns():
    _, _, k, tau = SETTINGS[0]
    with pytest.warns(SubstepBiasWarning, match=r"h/tau = 0\.2.*estimated relative bias"):
        simulate(k, k * tau, 0.4 * tau, tau, 4, key=jax.random.key(0), method="euler",
                 substeps=2)
