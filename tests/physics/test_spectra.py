"""Spectra and autocovariance against brute-force alias sums and numerical integrals."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy import integrate

import blurtrap as bt

KT = bt.BOLTZMANN * 295.0
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6  # 3.06 um bead in water [N s/m]


def ref_blurred(f, k, gamma, w):
    """Independent numpy continuous blurred PSD (two-sided)."""
    sigma2, tau = KT / k, gamma / k
    x = np.pi * f * w
    sinc2 = np.where(x == 0, 1.0, np.sin(x) ** 2 / np.where(x == 0, 1.0, x) ** 2)
    return 2 * sigma2 * tau / (1 + (2 * np.pi * f * tau) ** 2) * sinc2


def brute_alias(f, k, gamma, w, dt, eps2, n_terms):
    """Brute-force alias sum over |n| <= n_terms (numpy, pairwise summation)."""
    n = np.arange(-n_terms, n_terms + 1, dtype=float)
    out = []
    for fi in np.atleast_1d(f):
        out.append(np.sum(ref_blurred(fi + n / dt, k, gamma, w)))
    return np.array(out) + eps2 * dt


# (k, dt, W) corners: ordinary camera; rho -> 1 (dt/tau = 1e-3); alpha = 30; W << dt
CASES = [
    (5e-5, 1 / 1500, 1 / 1500),
    (5e-5, 1 / 1500, 1e-4),
    (GAMMA * 1e-3 / 1e-4 * 1, 1e-4 * 1, 1e-4 * 1),  # dt/tau = 1e-3 with W = dt
    (GAMMA * 30 / 1e-2, 1.2e-2, 1e-2),  # alpha = 30
    (1e-6, 1 / 1500, 1 / 1500),  # slow trap
]


@pytest.mark.parametrize("k,dt,w", CASES)
def test_closed_form_equals_brute_force_alias_sum(k, dt, w):
    eps2 = 4e-18
    f = np.linspace(0, 0.5 / dt, 9)
    got = np.asarray(bt.psd_measured(f, k, GAMMA, w, frame_interval=dt, tracking_var=eps2))
    ref = brute_alias(f, k, GAMMA, w, dt, eps2, 200_000)
    rel = np.abs(got / ref - 1)
    assert rel.max() < 1e-10, rel.max()


@pytest.mark.parametrize("k,dt,w", CASES[:3])
def test_truncated_sum_option_equals_explicit_truncated_sum(k, dt, w):
    f = np.linspace(-0.5 / dt, 0.5 / dt, 7)
    for n_alias in (0, 1, 5):
        got = np.asarray(
            bt.psd_measured(f, k, GAMMA, w, frame_interval=dt, tracking_var=1e-18, n_alias=n_alias)
        )
        ref = brute_alias(f, k, GAMMA, w, dt, 1e-18, n_alias)
        np.testing.assert_allclose(got, ref, rtol=1e-13)


def test_continuous_psd_matches_reference():
    f = np.linspace(0, 5000, 11)
    got = np.asarray(bt.psd_measured(f, 5e-5, GAMMA, 1e-3))
    np.testing.assert_allclose(got, ref_blurred(f, 5e-5, GAMMA, 1e-3), rtol=1e-13)
    lor = np.asarray(bt.lorentzian(f, 5e-5, GAMMA))
    np.testing.assert_allclose(lor, ref_blurred(f, 5e-5, GAMMA, 0.0), rtol=1e-13)


def integrate_blurred_psd(k, gamma, w, panels=3000):
    """Integral over (-inf, inf) with scipy.quad per sinc period plus analytic f^-4 tail."""
    total = 0.0
    for j in range(panels):
        val, _ = integrate.quad(ref_blurred, j / w, (j + 1) / w, args=(k, gamma, w), epsabs=0,
                                epsrel=1e-13, limit=200)
        total += val
    fmax = panels / w
    tau = gamma / k
    tail = 2 * (KT / k) * tau / (2 * np.pi * tau) ** 2 / (2 * np.pi**2 * w**2) / (3 * fmax**3)
    return 2 * (total + tail)


@pytest.mark.parametrize("k,w", [(5e-5, 1e-3), (1e-5, 1e-4), (1e-4, 2e-2)])
def test_parseval_continuous(k, w):
    ref = integrate_blurred_psd(k, GAMMA, w)
    got = float(bt.measured_variance(k, GAMMA, w))
    assert abs(got / ref - 1) < 1e-9


@pytest.mark.parametrize("k,dt,w", CASES)
def test_parseval_discrete_equals_c0(k, dt, w):
    eps2 = 2e-18

    def p(f):
        return float(bt.psd_measured(f, k, GAMMA, w, frame_interval=dt, tracking_var=eps2))

    val, _ = integrate.quad(p, -0.5 / dt, 0.5 / dt, epsabs=0, epsrel=1e-12, limit=500)
    c0 = float(bt.frame_autocovariance(0, k, GAMMA, w, dt, tracking_var=eps2))
    assert abs(val / c0 - 1) < 1e-10


@pytest.mark.parametrize("k,dt,w", [(5e-5, 1 / 1500, 1 / 1500), (5e-5, 1 / 1500, 2e-4),
                                    (1e-5, 1e-3, 5e-4)])
@pytest.mark.parametrize("lag", [1, 2, 5])
def test_autocovariance_vs_double_integral(k, dt, w, lag):
    sigma2, tau = KT / k, GAMMA / k

    def integrand(s, t):
        return np.exp(-abs(lag * dt + t - s) / tau)

    val, _ = integrate.dblquad(integrand, 0, w, 0, w, epsabs=0, epsrel=1e-11)
    ref = sigma2 * val / w**2
    got = float(bt.frame_autocovariance(lag, k, GAMMA, w, dt))
    assert abs(got / ref - 1) < 1e-9
    # C(0) is the blurred variance, C(-n) = C(n)
    assert float(bt.frame_autocovariance(-lag, k, GAMMA, w, dt)) == got


def test_autocovariance_no_overflow_at_large_alpha():
    k = GAMMA * 800 / 1e-2  # alpha = 800: B(alpha) alone would overflow
    c = np.asarray(bt.frame_autocovariance(np.arange(4), k, GAMMA, 1e-2, 1e-2))
    assert np.all(np.isfinite(c)) and np.all(c >= 0)


def test_sample_variance_se_against_brute_force():
    k, dt, w, eps2 = 5e-5, 1 / 1500, 1 / 1500, 4e-18
    for n_frames in (2, 10, 1000):
        lags = np.arange(-(n_frames - 1), n_frames)
        c = np.asarray(bt.frame_autocovariance(lags, k, GAMMA, w, dt, tracking_var=eps2))
        ref = np.sqrt(2 / n_frames**2 * np.sum((n_frames - np.abs(lags)) * c**2))
        got = float(bt.sample_variance_se(n_frames, k, GAMMA, w, dt, tracking_var=eps2))
        assert abs(got / ref - 1) < 1e-10


def test_psd_gradients_vs_finite_differences():
    f = jnp.array([1.0, 100.0, 700.0])

    def fn(logk, loggamma):
        return jnp.sum(jnp.log(bt.psd_measured(f, jnp.exp(logk), jnp.exp(loggamma), 1 / 1500,
                                               frame_interval=1 / 1500, tracking_var=4e-18)))

    x = (jnp.log(5e-5), jnp.log(GAMMA))
    check_grads(fn, x, order=1, modes=("rev",), eps=1e-5)


def test_closed_form_stable_in_float32():
    f = np.linspace(0, 750, 50)
    ref = np.asarray(bt.psd_measured(f, 5e-5, GAMMA, 1 / 1500, frame_interval=1 / 1500))
    got = np.asarray(bt.psd_measured(f.astype(np.float32), np.float32(5e-5), np.float32(GAMMA),
                                     np.float32(1 / 1500), frame_interval=np.float32(1 / 1500)))
    assert got.dtype == np.float32
    assert np.max(np.abs(got / ref - 1)) < 1e-5


def test_jit_vmap_over_parameters():
    ks = jnp.array([1e-5, 5e-5, 1e-4])
    fn = jax.jit(jax.vmap(lambda k: bt.psd_measured(jnp.array([10.0, 300.0]), k, GAMMA, 1e-3,
                                                    frame_interval=2e-3, tracking_var=1e-18)))
    out = fn(ks)
    assert out.shape == (3, 2)
    for i, k in enumerate(ks):
        np.testing.assert_allclose(
            np.asarray(out[i]),
            np.asarray(bt.psd_measured(np.array([10.0, 300.0]), float(k), GAMMA, 1e-3,
                                       frame_interval=2e-3, tracking_var=1e-18)), rtol=1e-14)


@pytest.mark.parametrize("k,dt,w", [(5e-5, 1 / 1500, 1 / 1500), (1e-9, 1 / 1500, 1e-5),
                                    (1e-3, 0.05, 0.05), (1e-3, 1.0, 1e-4), (2e-5, 1e-5, 1e-5)])
def test_expected_block_periodogram_equals_fejer_sum(k, dt, w):
    """E[I_j] of a block of M frames = dt [C(0) + 2 sum_{n<M} (1 - n/M) C(n) cos(theta n)]
    summed term by term from frame_autocovariance, from tau >> M dt (free diffusion) to
    dt/tau ~ 7e5 (rho underflows to 0)."""
    from blurtrap.physics._spectra import _expected_block_periodogram

    gamma, temp, eps2 = 1.37e-8, 295.0, 4e-18
    m = 64
    lags = np.arange(1, m)
    c = np.array([float(bt.physics.frame_autocovariance(int(n), k, gamma, w, dt, temp, eps2))
                  for n in range(m)])
    f = np.arange(1, m // 2 + 1) / (m * dt)
    th = 2 * np.pi * f[:, None] * dt
    ref = dt * (c[0] + 2 * np.sum((1 - lags / m) * c[1:] * np.cos(th * lags), axis=1))
    sigma2 = 1.380649e-23 * temp / k
    got = np.asarray(_expected_block_periodogram(jnp.asarray(f), float(m), sigma2, gamma / k, w,
                                                 dt, eps2))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12 * np.max(np.abs(ref)))
