"""S(alpha), Pade and the stiffness inversions against independent references (mpmath)."""

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from jax.test_util import check_grads

import blurtrap as bt
from blurtrap.physics._blur import _blur_factor

ALPHAS = [0.0] + [float(x) for x in np.logspace(-14, 6, 81)] + [0.4999, 0.5, 0.5001, 2.0, 30.0]


def s_mpmath(a):
    with mp.workdps(60):
        a = mp.mpf(a)
        if a == 0:
            return mp.mpf(1)
        return 2 / a - 2 * (1 - mp.exp(-a)) / a**2


def test_blur_factor_matches_mpmath_float64():
    got = np.asarray(bt.blur_factor(np.array(ALPHAS)))
    ref = np.array([float(s_mpmath(a)) for a in ALPHAS])
    rel = np.abs(got / ref - 1)
    assert rel.max() < 1e-13, (ALPHAS[int(rel.argmax())], rel.max())


def test_blur_factor_float32_stable():
    a32 = np.array(ALPHAS, dtype=np.float32)
    got = np.asarray(bt.blur_factor(a32))
    assert got.dtype == np.float32
    ref = np.array([float(s_mpmath(float(a))) for a in a32])
    # float32 unit roundoff is 6e-8; a few ulps are allowed
    assert np.max(np.abs(got / ref - 1)) < 1e-6


def test_literal_formula_is_bad_at_small_alpha():
    """Document why the series is needed: the literal formula is ~20 % off at 1e-8."""
    a = 1e-8
    literal = 2 / a - 2 * (1 - np.exp(-a)) / a**2
    assert abs(literal - 1) > 0.05
    assert abs(float(bt.blur_factor(a)) - 1) < 1e-8


def test_limits_and_monotonicity():
    a = np.logspace(-10, 8, 2000)
    s = np.asarray(bt.blur_factor(a))
    assert float(bt.blur_factor(0.0)) == 1.0
    assert np.all(s > 0) and np.all(s <= 1)
    assert np.all(np.diff(s) < 0)
    assert abs(float(a[-1] * s[-1]) - 2) < 1e-7  # alpha S -> 2 (next term -2/alpha)


def test_derivatives_at_zero():
    d1 = jax.grad(bt.blur_factor)(0.0)
    d2 = jax.grad(jax.grad(bt.blur_factor))(0.0)
    assert abs(float(d1) + 1 / 3) < 1e-14
    assert abs(float(d2) - 1 / 6) < 1e-13  # S = 1 - a/3 + a^2/12 - ...


@pytest.mark.parametrize("a", [1e-6, 0.1, 0.49, 0.51, 1.0, 7.0, 300.0])
def test_gradients_vs_finite_differences(a):
    check_grads(_blur_factor, (jnp.asarray(a),), order=2, modes=("fwd", "rev"), eps=1e-4 * a)


def test_derivative_matches_mpmath():
    a = np.array([1e-9, 1e-3, 0.3, 0.5, 0.7, 3.0, 100.0])
    got = np.asarray(jax.vmap(jax.grad(bt.blur_factor))(a))
    def ds(x):  # analytic derivative, evaluated at 60 digits
        with mp.workdps(60):
            x = mp.mpf(x)
            return -2 / x**2 + 4 * (1 - mp.exp(-x)) / x**3 - 2 * mp.exp(-x) / x**2

    ref = np.array([float(ds(x)) for x in a])
    assert np.max(np.abs(got / ref - 1)) < 1e-11


def test_grad_no_nan_on_either_branch():
    g = jax.vmap(jax.grad(bt.blur_factor))(jnp.array([0.0, 1e-300, 0.5, 1e3, 1e300]))
    assert np.all(np.isfinite(np.asarray(g)))


def test_pade_within_three_percent_below_alpha_3():
    a = np.linspace(0, 3, 3001)
    rel = np.abs(np.asarray(bt.blur_factor_pade(a)) / np.array([float(s_mpmath(x)) for x in a]) - 1)
    assert rel.max() < 0.03


KT = bt.BOLTZMANN * 295.0


@pytest.mark.parametrize("k", [1e-6, 5e-6, 1e-5, 5e-5, 1e-4])
@pytest.mark.parametrize("eps2", [0.0, 4e-18])
def test_exact_inversion_round_trip(k, eps2):
    gamma = 6 * np.pi * 0.00093 * 1.53e-6
    d = KT / gamma
    for w in [1e-6, 1e-4, 1e-3, 2e-2]:
        v = bt.measured_variance(k, gamma, w, tracking_var=eps2)
        k_back = float(bt.stiffness_from_variance(v, d, w, tracking_var=eps2))
        assert abs(k_back / k - 1) < 1e-10


def test_pade_inversion_within_three_percent():
    gamma = 6 * np.pi * 0.00093 * 1.53e-6
    d = KT / gamma
    k = np.logspace(-7, -4, 40)
    for alpha in [0.01, 0.5, 1.0, 2.0, 2.9]:
        w = alpha * gamma / k
        v = bt.measured_variance(k, gamma, w)
        kp = np.asarray(bt.stiffness_from_variance(v, d, w, method="pade"))
        assert np.max(np.abs(kp / k - 1)) < 0.03


def test_inversion_is_differentiable():
    gamma, w = 1e-8, 1e-3
    d = KT / gamma

    def f(v):
        return bt.stiffness_from_variance(v, d, w)

    v0 = float(bt.measured_variance(2e-5, gamma, w))
    g = float(jax.grad(f)(v0))
    h = v0 * 1e-6
    fd = (float(f(v0 + h)) - float(f(v0 - h))) / (2 * h)
    assert abs(g / fd - 1) < 1e-7


def test_inversion_broadcasts_and_jits():
    gamma = 1e-8
    k = np.array([[1e-6], [1e-5]])
    w = np.array([1e-4, 1e-3, 5e-3])
    v = bt.measured_variance(k, gamma, w)
    kb = jax.jit(bt.stiffness_from_variance)(v, KT / gamma, w)
    assert kb.shape == (2, 3)
    np.testing.assert_allclose(np.asarray(kb), np.broadcast_to(k, (2, 3)), rtol=1e-10)
