"""Start values and the one host-side numpy twin of calibrate.

- ``moment_start`` takes S(alpha) and rho B(alpha) from ``blurtrap.physics`` (one formula);
  it is checked against an independent mpmath evaluation of the moment estimator.
- The periodogram of the spectral fits stays in numpy (benchmarks/bench_host_twins.py: the
  JAX one compiles for every new record length); it must equal the JAX
  ``block_periodogram`` of the package.
"""

import math

import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference._likelihood import block_periodogram
from blurtrap.inference._spectral import _np_periodogram
from blurtrap.inference._starts import moment_start

KB = 1.380649e-23


def _ar1(n, rho, seed):
    rng = np.random.default_rng(seed)
    e = rng.standard_normal(n)
    y = np.empty(n)
    y[0] = e[0]
    for i in range(1, n):
        y[i] = rho * y[i - 1] + math.sqrt(1 - rho * rho) * e[i]
    return y


def _reference_moment_start(y, dt, w, temp):
    """The moment estimator of ``moment_start`` with S and rho B from their defining formulas
    in 50-digit arithmetic (S = 2/a - 2 (1 - e^-a)/a^2, rho B = e^-r 2 (cosh a - 1)/a^2)."""
    mp.mp.dps = 50
    y = y - y.mean()
    c0, c1, c2 = (float(np.mean(y[j:] * y[: y.size - j])) for j in range(3))
    rho = c2 / c1 if c1 > 0 else 0.0
    if not (0.02 < rho < 0.99999) or c1 <= 0:
        rho_used = min(max(rho, 0.05), 0.99999) if c1 > 0 else math.exp(-1.0)
    else:
        rho_used = rho
    tau = -dt / math.log(rho_used)
    a, r = mp.mpf(w) / mp.mpf(tau), mp.mpf(dt) / mp.mpf(tau)
    s = float(2 / a - 2 * (1 - mp.exp(-a)) / a**2) if a > 0 else 1.0
    rho_b = float(mp.exp(-r) * 2 * (mp.cosh(a) - 1) / a**2) if a > 0 else float(mp.exp(-r))
    sigma2 = c1 / rho_b if c1 > 0 else c0
    sigma2 = min(max(sigma2, 0.3 * c0 / s), 3.0 * c0 / s)
    eps2 = max(c0 - sigma2 * s, 0.02 * c0)
    k = KB * temp / sigma2
    return k, k * tau, eps2, rho


@pytest.mark.parametrize(("rho", "w_frac", "noise"), [
    (0.8, 1.0, 0.0),      # camera, W = dt
    (0.95, 0.3, 0.2),     # short exposure, tracking noise
    (0.999, 1e-4, 0.0),   # alpha ~ 1e-7: the series branch of S
    (0.0, 1.0, 0.0),      # white frames: the tau = dt fallback
    (0.5, 0.05, 0.1),     # short exposure, white-ish frames
])
def test_moment_start_matches_an_independent_evaluation(rho, w_frac, noise):
    dt = 1.0 / 1500.0
    y = _ar1(4096, rho, seed=3) * 3e-8
    y = y + noise * 3e-8 * np.random.default_rng(4).standard_normal(y.size)
    rec = bt.Recording(y, frame_interval=dt, exposure=w_frac * dt, temperature=300.0)
    got = moment_start(rec)
    ref = _reference_moment_start(np.asarray(rec.positions, dtype=float), dt, w_frac * dt,
                                  300.0)
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    assert all(isinstance(v, float) for v in got)


def test_moment_start_is_float64_outside_the_estimators():
    """The public function gives float64 start values whether or not x64 is on globally."""
    import jax

    dt = 1.0 / 1500.0
    rec = bt.Recording(_ar1(4096, 0.9, seed=5) * 3e-8, frame_interval=dt, exposure=dt)
    ref = _reference_moment_start(np.asarray(rec.positions, dtype=float), dt, dt, 295.0)
    was = bool(jax.config.jax_enable_x64)  # pyright: ignore[reportAttributeAccessIssue]
    try:
        jax.config.update("jax_enable_x64", False)
        got = moment_start(rec)
    finally:
        jax.config.update("jax_enable_x64", was)
    np.testing.assert_allclose(got, ref, rtol=1e-12)


@pytest.mark.parametrize("n", [4096, 4099, 1001])
@pytest.mark.parametrize("n_blocks", [1, 2, 7, 128])
def test_numpy_periodogram_equals_the_jax_one(n, n_blocks):
    y = np.random.default_rng(n + n_blocks).standard_normal(n) * 1e-8 + 1e-6
    dt = 2e-4
    f, p, m = _np_periodogram(y, dt, n_blocks)
    fj, pj, used = block_periodogram(jnp.asarray(y), dt, n_blocks)
    assert m == n // n_blocks and used == m * n_blocks
    np.testing.assert_allclose(f, np.asarray(fj), rtol=1e-14)
    np.testing.assert_allclose(p, np.asarray(pj), rtol=1e-11)


def test_numpy_periodogram_refuses_tiny_blocks_like_the_jax_one():
    for fn in (lambda: _np_periodogram(np.zeros(200), 1e-3, 100),
               lambda: block_periodogram(jnp.zeros(200), 1e-3, 100)):
        with pytest.raises(ValueError, match="n_blocks = 100 leaves 2 frames per block"):
            fn()
