"""Exact likelihood against the dense multivariate normal with the Toeplitz covariance."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import linalg, stats

import blurtrap as bt
from blurtrap.inference._likelihood import arma_loglik, block_periodogram, periodogram

GAMMA = 6 * np.pi * 0.00093 * 1.53e-6


def toeplitz_cov(n, k, w, dt, eps2):
    c = np.asarray(bt.frame_autocovariance(np.arange(n), k, GAMMA, w, dt, tracking_var=eps2))
    return linalg.toeplitz(c), c


CASES = [
    (5e-5, 1 / 1500, 1 / 1500, 4e-18),  # camera, blurred, noisy
    (1e-5, 1 / 1500, 1e-4, 0.0),  # short exposure, no noise
    (1e-4, 1e-5, 1e-5, 1e-18),  # photodiode-like: rho -> 1
    (2e-4, 1e-2, 1e-2, 1e-19),  # dt >> tau: nearly white
    (5e-5, 1 / 1500, 1 / 1500, 0.0),  # blur, no noise: "negative white noise" representation
]


@pytest.mark.parametrize("k,dt,w,eps2", CASES)
@pytest.mark.parametrize("n", [1, 2, 7, 300])
def test_exact_loglik_equals_dense_mvn(k, dt, w, eps2, n, rng):
    cov, c = toeplitz_cov(n, k, w, dt, eps2)
    y = rng.multivariate_normal(np.zeros(n), cov)
    ref = stats.multivariate_normal(np.zeros(n), cov).logpdf(y)
    c0, c1 = c[0], float(bt.frame_autocovariance(1, k, GAMMA, w, dt, tracking_var=eps2))
    rho = np.exp(-dt * k / GAMMA)
    got = float(arma_loglik(jnp.asarray(y), c0, c1, rho, mean="zero"))
    assert abs(got - ref) < 1e-9 * max(1.0, abs(ref))


@pytest.mark.parametrize("k,dt,w,eps2", CASES[:3])
def test_reml_and_profile_equal_dense_formulas(k, dt, w, eps2, rng):
    n = 200
    cov, c = toeplitz_cov(n, k, w, dt, eps2)
    y = rng.multivariate_normal(np.full(n, 3e-7), cov)  # unknown offset
    ci = linalg.inv(cov)
    one = np.ones(n)
    mu = one @ ci @ y / (one @ ci @ one)
    r = y - mu
    _, logdet = np.linalg.slogdet(cov)
    prof = -0.5 * (n * np.log(2 * np.pi) + logdet + r @ ci @ r)
    reml = prof - 0.5 * np.log(one @ ci @ one) + 0.5 * np.log(2 * np.pi)
    c1 = float(bt.frame_autocovariance(1, k, GAMMA, w, dt, tracking_var=eps2))
    rho = np.exp(-dt * k / GAMMA)
    assert abs(float(arma_loglik(jnp.asarray(y), c[0], c1, rho, mean="profile")) - prof) < 1e-9 * abs(prof)
    assert abs(float(arma_loglik(jnp.asarray(y), c[0], c1, rho, mean="reml")) - reml) < 1e-9 * abs(reml)


def test_exact_loglik_gradient_matches_dense(rng):
    k, dt, w, eps2, n = 5e-5, 1 / 1500, 1 / 1500, 4e-18, 120
    cov, _ = toeplitz_cov(n, k, w, dt, eps2)
    y = jnp.asarray(rng.multivariate_normal(np.zeros(n), cov))

    def via_arma(logk):
        kk = jnp.exp(logk)
        c0 = bt.frame_autocovariance(0, kk, GAMMA, w, dt, tracking_var=eps2)
        c1 = bt.frame_autocovariance(1, kk, GAMMA, w, dt, tracking_var=eps2)
        return arma_loglik(y, c0, c1, jnp.exp(-dt * kk / GAMMA), mean="zero")

    def via_dense(logk):
        kk = jnp.exp(logk)
        c = bt.frame_autocovariance(jnp.arange(n), kk, GAMMA, w, dt, tracking_var=eps2)
        idx = jnp.abs(jnp.arange(n)[:, None] - jnp.arange(n)[None, :])
        cv = c[idx]
        chol = jnp.linalg.cholesky(cv)
        z = jax.scipy.linalg.solve_triangular(chol, y, lower=True)
        return -0.5 * (n * np.log(2 * np.pi) + 2 * jnp.sum(jnp.log(jnp.diag(chol))) + z @ z)

    g1 = float(jax.grad(via_arma)(jnp.log(k)))
    g2 = float(jax.grad(via_dense)(jnp.log(k)))
    assert abs(g1 - g2) < 1e-7 * max(1, abs(g2))


def test_periodogram_normalisation_parseval(rng):
    y = rng.normal(size=1024)
    f, p = periodogram(jnp.asarray(y), 1e-3)
    assert f.shape == (512,) and abs(float(f[-1]) - 500.0) < 1e-9
    # two-sided PSD: sum over all nonzero bins * df = variance (Parseval, mean removed)
    yc = y - y.mean()
    full = 2 * np.sum(np.asarray(p)[:-1]) + np.asarray(p)[-1]
    assert abs(full / (1024 * 1e-3) - np.mean(yc**2)) < 1e-12


def test_block_periodogram_rejects_tiny_blocks():
    with pytest.raises(ValueError, match="n_blocks = 100 leaves 2 frames per block"):
        block_periodogram(jnp.zeros(200), 1e-3, 100)
