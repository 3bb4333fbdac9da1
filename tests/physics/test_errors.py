"""Bad input: clear ValueErrors naming the parameter, its value and the allowed range."""

import equinox as eqx
import numpy as np
import pytest

import blurtrap as bt


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(k=-1e-5), r"k \(trap stiffness\) must be finite and > 0 N/m; got k = -1e-05"),
        (dict(k=0.0), r"k .* > 0 N/m; got k = 0"),
        (dict(gamma=-1e-8), r"gamma .* > 0 N s/m; got gamma = -1e-08"),
        (dict(exposure=0.0), r"exposure .* > 0 s; got exposure = 0"),
        (dict(temperature=-3.0), r"temperature must be finite and > 0 K; got temperature = -3"),
        (dict(tracking_var=-1e-18), r"tracking_var .* >= 0 m\^2; got tracking_var = -1e-18"),
        (dict(k=np.nan), r"k .* got k = nan"),
    ],
)
def test_measured_variance_rejects(kwargs, match):
    args = dict(k=1e-5, gamma=1e-8, exposure=1e-3, temperature=295.0, tracking_var=0.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        bt.measured_variance(**args)


def test_exposure_longer_than_frame_interval():
    with pytest.raises(ValueError, match=r"exposure must be <= frame_interval; got exposure = 0.002 s"):
        bt.psd_measured(1.0, 1e-5, 1e-8, 2e-3, frame_interval=1e-3)
    with pytest.raises(ValueError, match="exposure must be <= frame_interval"):
        bt.frame_autocovariance(1, 1e-5, 1e-8, 2e-3, 1e-3)


def test_array_error_names_offending_values():
    with pytest.raises(ValueError, match=r"got k = -2 N/m"):
        bt.measured_variance(np.array([1e-5, -2.0, 3e-5]), 1e-8, 1e-3)


def test_negative_alpha():
    with pytest.raises(ValueError, match="alpha .* >= 0; got alpha = -0.1"):
        bt.blur_factor(-0.1)


def test_inversion_errors():
    with pytest.raises(ValueError, match="measured_var must exceed tracking_var"):
        bt.stiffness_from_variance(1e-18, 1e-12, 1e-3, tracking_var=2e-18)
    with pytest.raises(ValueError, match="method must be 'exact' or 'pade'; got method = 'newton'"):
        bt.stiffness_from_variance(1e-16, 1e-12, 1e-3, method="newton")
    with pytest.raises(ValueError, match="diffusion .* > 0 m\\^2/s"):
        bt.stiffness_from_variance(1e-16, -1e-12, 1e-3)


def test_continuous_psd_refuses_tracking_noise():
    with pytest.raises(ValueError, match="tracking_var needs frame_interval"):
        bt.psd_measured(1.0, 1e-5, 1e-8, 1e-3, tracking_var=1e-18)
    with pytest.raises(ValueError, match="n_alias needs frame_interval"):
        bt.psd_measured(1.0, 1e-5, 1e-8, 1e-3, n_alias=3)
    with pytest.raises(ValueError, match="n_alias must be a non-negative integer"):
        bt.psd_measured(1.0, 1e-5, 1e-8, 1e-3, frame_interval=1e-3, n_alias=-1)


def test_traced_values_are_checked_under_jit():
    fn = eqx.filter_jit(lambda k: bt.measured_variance(k, 1e-8, 1e-3))
    assert np.isfinite(float(fn(1e-5)))
    with pytest.raises(eqx.EquinoxRuntimeError, match=r"k \(trap stiffness\) must be finite and > 0"):
        fn(-1e-5)
    fn2 = eqx.filter_jit(lambda w, dt: bt.frame_autocovariance(1, 1e-5, 1e-8, w, dt))
    with pytest.raises(eqx.EquinoxRuntimeError, match="exposure must be <= frame_interval"):
        fn2(2e-3, 1e-3)


def test_trapezoid_rise_too_long():
    with pytest.raises(ValueError, match="rise must be <= exposure/2"):
        bt.TrapezoidKernel(1e-3, 6e-4)
