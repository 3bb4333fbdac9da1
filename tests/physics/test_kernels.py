"""General-kernel path: reproduces the rectangular closed forms; other kernels vs scipy."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import blurtrap as bt

KT = bt.BOLTZMANN * 295.0
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6


@pytest.mark.parametrize("k,w", [(5e-5, 1 / 1500), (1e-5, 1e-4), (1e-4, 2e-2), (1e-6, 1e-3)])
def test_general_variance_reproduces_rect_closed_form(k, w):
    got = float(bt.variance_general(bt.RectKernel(w), k, GAMMA))
    ref = float(bt.measured_variance(k, GAMMA, w))
    assert abs(got / ref - 1) < 1e-6


@pytest.mark.parametrize("k,dt,w", [(5e-5, 1 / 1500, 1 / 1500), (5e-5, 1 / 1500, 3e-4)])
def test_folded_psd_reproduces_closed_form(k, dt, w):
    f = np.linspace(0, 0.5 / dt, 6)
    got = np.asarray(bt.psd_folded(f, bt.RectKernel(w), k, GAMMA, dt, tracking_var=1e-18,
                                   n_alias=2000))
    ref = np.asarray(bt.psd_measured(f, k, GAMMA, w, frame_interval=dt, tracking_var=1e-18))
    assert np.max(np.abs(got / ref - 1)) < 1e-8


def test_trapezoid_with_zero_rise_is_rect():
    f = np.linspace(0, 3000, 7)
    np.testing.assert_allclose(np.asarray(bt.TrapezoidKernel(1e-3, 0.0).transfer(f)),
                               np.asarray(bt.RectKernel(1e-3).transfer(f)), rtol=1e-14)


def time_domain_variance(weight, support, k):
    """sigma2 int int h(s) h(t) exp(-|s-t|/tau) ds dt  (scipy dblquad, independent)."""
    tau = GAMMA / k
    with warnings.catch_warnings():  # quad reports roundoff at the kinks; the result is ~1e-9
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        val, _ = integrate.dblquad(
            lambda s, t: weight(s) * weight(t) * np.exp(-abs(s - t) / tau),
            0, support, 0, support, epsabs=0, epsrel=1e-10)
    return KT / k * val


def test_trapezoid_variance_vs_time_domain():
    k, w, r = 5e-5, 1e-3, 2e-4
    plateau = w - r  # trapezoid = rect(w - r) * rect(r): ramps of length r, height 1/(w - r)

    def h(t):
        if t < r:
            return t / (r * plateau)
        if t > w - r:
            return (w - t) / (r * plateau)
        return 1 / plateau

    ref = time_domain_variance(h, w, k)
    got = float(bt.variance_general(bt.TrapezoidKernel(w, r), k, GAMMA))
    assert abs(got / ref - 1) < 1e-6


def test_exponential_kernel_variance_closed_form():
    # a single-pole detector on an OU process: var = sigma2 / (1 + tau_d/tau) (independent)
    k, td = 5e-5, 2e-4
    tau = GAMMA / k
    ref = KT / k / (1 + td / tau)
    got = float(bt.variance_general(bt.ExponentialKernel(td), k, GAMMA))
    assert abs(got / ref - 1) < 1e-6


def test_product_kernel_multiplies_transfers():
    f = jnp.linspace(0, 2000, 5)
    pk = bt.ProductKernel(bt.RectKernel(1e-3), bt.ExponentialKernel(1e-4))
    np.testing.assert_allclose(
        np.asarray(pk.transfer(f)),
        np.asarray(bt.RectKernel(1e-3).transfer(f) * bt.ExponentialKernel(1e-4).transfer(f)))


def test_general_variance_differentiable():
    def fn(logk):
        return bt.variance_general(bt.RectKernel(1e-3), jnp.exp(logk), GAMMA)

    g = float(jax.grad(fn)(jnp.log(5e-5)))
    ref = float(jax.grad(lambda lk: bt.measured_variance(jnp.exp(lk), GAMMA, 1e-3))(jnp.log(5e-5)))
    assert abs(g / ref - 1) < 1e-5
