"""The irregular-time likelihood: equal to the ARMA likelihood on a regular grid and to the
dense multivariate normal (covariance integrated numerically from the OU kernel) on an
irregular one."""

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest
from scipy import integrate, linalg

from blurtrap.inference._irregular import _exposure_terms, irregular_loglik
from blurtrap.inference._likelihood import arma_loglik

SIGMA2, TAU, EPS2 = 4e-16, 2.5e-3, 1e-17


def _arma_moments(dt, w, tau, sigma2, eps2):
    """C(0), C(1), rho of regular frames, written out from the OU kernel (paper eq. 5) in
    50-digit arithmetic (the double-precision formulas cancel at small W/tau)."""
    if w == 0.0:
        return sigma2 + eps2, sigma2 * np.exp(-dt / tau), np.exp(-dt / tau)
    with mpmath.workdps(50):
        al = mpmath.mpf(w) / tau
        s = 2 * (al - 1 + mpmath.exp(-al)) / al**2
        c1 = (mpmath.exp(al) - 1) * (1 - mpmath.exp(-al)) / al**2 * mpmath.exp(-dt / tau)
        return sigma2 * float(s) + eps2, sigma2 * float(c1), np.exp(-dt / tau)


@pytest.mark.parametrize("w_over_dt", [0.0, 1e-6, 0.3, 1.0])
@pytest.mark.parametrize("mean", ["zero", "profile", "reml"])
def test_regular_grid_equals_the_arma_likelihood(rng, w_over_dt, mean):
    n, dt = 257, 1e-3
    y = rng.normal(size=n) * 2e-8 + 3e-7
    w = w_over_dt * dt
    c0, c1, rho = _arma_moments(dt, w, TAU, SIGMA2, EPS2)
    ll_ref = arma_loglik(jnp.asarray(y), c0, c1, rho, mean=mean)
    ll = irregular_loglik(jnp.asarray(y), jnp.full(n, dt), w, SIGMA2, TAU, EPS2, mean=mean)
    assert float(ll) == pytest.approx(float(ll_ref), rel=1e-11, abs=1e-9)


def _dense_cov(starts, w, tau, sigma2, eps2):
    """Covariance of exposure averages over [s_i, s_i + w], by numerical quadrature of the
    OU kernel sigma^2 exp(-|t - t'|/tau) (independent of the closed forms)."""
    n = len(starts)
    cov = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            if w == 0.0:
                v = sigma2 * np.exp(-abs(starts[j] - starts[i]) / tau)
            elif i == j:  # the kernel's kink on the diagonal: integrate the two triangles
                v, _ = integrate.dblquad(lambda u, t: sigma2 * np.exp(-(t - u) / tau),
                                         0.0, w, 0.0, lambda t: t, epsabs=0.0, epsrel=1e-12)
                v *= 2.0 / (w * w)
            else:  # disjoint exposures: the kernel is smooth
                v, _ = integrate.dblquad(
                    lambda u, t: sigma2 * np.exp(-(starts[j] + u - starts[i] - t) / tau),
                    0.0, w, 0.0, w, epsabs=0.0, epsrel=1e-12)
                v /= w * w
            cov[i, j] = cov[j, i] = v
    return cov + eps2 * np.eye(n)


def _dense_loglik(y, cov, mean):
    n = len(y)
    cf = linalg.cho_factor(cov, lower=True)
    logdet = 2.0 * np.sum(np.log(np.diag(cf[0])))
    if mean == "zero":
        return -0.5 * (n * np.log(2 * np.pi) + logdet + y @ linalg.cho_solve(cf, y))
    one = np.ones(n)
    si1, siy = linalg.cho_solve(cf, one), linalg.cho_solve(cf, y)
    mu = (one @ siy) / (one @ si1)
    r = y - mu
    ll = -0.5 * (n * np.log(2 * np.pi) + logdet + r @ linalg.cho_solve(cf, r))
    if mean == "reml":
        ll += -0.5 * np.log(one @ si1) + 0.5 * np.log(2 * np.pi)
    return ll


@pytest.mark.parametrize("w", [0.0, 0.4e-3])
@pytest.mark.parametrize("mean", ["zero", "reml"])
def test_irregular_times_equal_the_dense_normal(rng, w, mean):
    n, dt = 24, 1e-3
    # jittered clock with a dropped frame: intervals 0.9-1.1 dt and one of 2 dt
    d = dt * rng.uniform(0.9, 1.1, size=n - 1)
    d[10] = 2 * dt
    starts = np.concatenate([[0.0], np.cumsum(d)])
    cov = _dense_cov(starts, w, TAU, SIGMA2, EPS2)
    y = linalg.cholesky(cov, lower=True) @ rng.normal(size=n) + 1e-6
    ll_ref = _dense_loglik(y, cov, mean)
    ll = irregular_loglik(jnp.asarray(y), jnp.asarray(np.append(d, dt)), w, SIGMA2, TAU,
                          EPS2, mean=mean)
    assert float(ll) == pytest.approx(ll_ref, rel=1e-9)


def test_padding_does_not_change_the_likelihood(rng):
    n, dt = 100, 1e-3
    d = dt * rng.uniform(0.8, 1.2, size=n)
    y = rng.normal(size=n) * 1e-8
    ll = irregular_loglik(jnp.asarray(y), jnp.asarray(d), 0.5e-3, SIGMA2, TAU, EPS2)
    yp = np.concatenate([y, np.zeros(20)])
    dp = np.concatenate([d, np.full(20, dt)])
    mask = np.concatenate([np.ones(n), np.zeros(20)])
    llp = irregular_loglik(jnp.asarray(yp), jnp.asarray(dp), 0.5e-3, SIGMA2, TAU, EPS2,
                           mask=jnp.asarray(mask))
    assert float(llp) == pytest.approx(float(ll), rel=1e-13)


def test_gradients_are_finite_at_zero_exposure(rng):
    y = jnp.asarray(rng.normal(size=64) * 1e-8)
    d = jnp.full(64, 1e-3)

    def f(logs):
        s2, tau, e2 = jnp.exp(logs)
        return irregular_loglik(y, d, 0.0, s2, tau, e2)

    g = jax.grad(f)(jnp.log(jnp.array([SIGMA2, TAU, EPS2])))
    assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.parametrize("alpha", [1e-9, 1e-5, 0.999e-3, 1.001e-3, 0.1, 1.0, 30.0])
def test_exposure_terms_against_mpmath(alpha):
    """a, S - a^2 and 4 sinh^2(alpha/2)/alpha on both sides of the series threshold."""
    with mpmath.workdps(60):
        al = mpmath.mpf(alpha)
        a = (1 - mpmath.exp(-al)) / al
        s = 2 * (al - 1 + mpmath.exp(-al)) / al**2
        ref = (float(a), float(s - a * a), float(4 * mpmath.sinh(al / 2) ** 2 / al))
    got = _exposure_terms(jnp.asarray(alpha))
    for g, r in zip(got, ref, strict=True):
        assert float(g) == pytest.approx(r, rel=1e-11)


def _dropped_frames_recording(seed, n=2048):
    """A camera recording with 5 % of the frames missing (their interval is 2 dt), drawn
    exactly by tests/_irregular_gen.py (dense Cholesky, not blurtrap's simulator)."""
    import _irregular_gen as gen

    import blurtrap as bt

    k, gamma, temp, dt = 3.6e-6, 9.0e-9, 295.0, 1e-3
    r = np.random.default_rng(seed)
    t = gen.clock("dropped", n, dt, 0.05, r)
    x = gen.frames(t, 0.5 * dt, k, gamma, temp, 4e-18, r, offset=1e-7)
    rec = bt.Recording(x, frame_interval=dt, exposure=0.5 * dt, temperature=temp, times=t,
                       allow_irregular=True)
    return rec, k, gamma


def test_calibrate_fits_the_recorded_frame_times():
    """The remedy for timing jitter: with the time stamps the exact likelihood at the recorded
    times recovers k and gamma (the regular-grid fit of the same frames ignores the gaps)."""
    import blurtrap as bt

    rec, k, gamma = _dropped_frames_recording(11)
    res = bt.calibrate(rec)
    assert any("recorded (irregular) frame times" in n for n in res.notes)
    assert abs(res.k - k) < 3 * res.k_err
    assert abs(res.gamma - gamma) < 3 * res.gamma_err
    # the likelihood maximised is the one at the recorded times, not the regular-grid one
    from blurtrap.inference._irregular import irregular_loglik
    from blurtrap.physics._constants import BOLTZMANN

    d = np.append(np.diff(np.asarray(rec.times)), 1e-3)
    ll = irregular_loglik(jnp.asarray(rec.positions), jnp.asarray(d), rec.exposure,
                          BOLTZMANN * rec.temperature / res.k, res.gamma / res.k,
                          res.tracking_var)
    assert float(ll) == pytest.approx(res.extras["loglik"], rel=1e-12)


def test_irregular_times_with_a_spectral_model_say_so():
    import blurtrap as bt

    rec, _, _ = _dropped_frames_recording(12, n=1024)
    res = bt.calibrate(rec, likelihood="whittle")
    assert any("treats the frames as regular" in n for n in res.notes)
    with pytest.raises(ValueError, match="irregular frame times is not available"):
        bt.calibrate(rec, model="standard+drift", likelihood="exact")
