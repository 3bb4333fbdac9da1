"""Bad arguments are refused before any fitting, and failure messages blame what the data
show (outliers) rather than a default cause (dt >> tau).

Traces are built here with an exact AR(1) recursion plus white noise (independent of
blurtrap's simulator).
"""

import math
import re

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.signal import lfilter

import blurtrap as bt
from blurtrap.diagnostics import _candidates as cand_mod
from blurtrap.diagnostics import _diagnose as diag_mod
from blurtrap.inference import FitError
from blurtrap.inference import _calibrate as cal_mod
from blurtrap.inference import _options as opt_mod
from blurtrap.inference import _posterior as post_mod
from blurtrap.inference import _posterior_priors as prior_mod
from blurtrap.inference import _refusals as ref_mod

KT = 1.380649e-23 * 295.0
GAMMA = 6 * math.pi * 9.3e-4 * 1.53e-6
DT = 1 / 1500
N = 4096


def _trace(k=5e-5, seed=0, n=N, eps=0.1):
    rng = np.random.default_rng(seed)
    sig = math.sqrt(KT / k)
    rho = math.exp(-DT * k / GAMMA)
    e = rng.standard_normal(n) * sig * math.sqrt(1.0 - rho * rho)
    e[0] = rng.standard_normal() * sig
    return lfilter([1.0], [1.0, -rho], e) + eps * sig * rng.standard_normal(n), sig


def _rec(x):
    return bt.Recording(x, frame_interval=DT, exposure=1e-5)


@pytest.fixture(scope="module")
def rec():
    return _rec(_trace()[0])


def _no_fit(*a, **kw):
    raise AssertionError("a fit ran before the arguments were checked")


# ------------------------------------------------------------------------------------------
# diagnose / select_model
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("alpha", [1.5, -1, 0.0, 1.0, float("nan"), float("inf"), True, "0.05",
                                   None])
@pytest.mark.parametrize("fn", ["diagnose", "select_model"])
def test_diagnose_alpha_must_be_a_probability(rec, monkeypatch, alpha, fn):
    monkeypatch.setattr(diag_mod, "calibrate", _no_fit)
    with pytest.raises(ValueError, match=r"alpha .* in \(0, 1\).*got alpha = " +
                       re.escape(repr(alpha))):
        getattr(bt, fn)(rec, alpha=alpha)


@pytest.mark.parametrize("cands", [["warp_drive"], ["drift", "warp_drive"], "warp_drive",
                                   ["Drift"], 42])
@pytest.mark.parametrize("fn", ["diagnose", "select_model"])
def test_diagnose_unknown_candidates_are_refused(rec, monkeypatch, cands, fn):
    monkeypatch.setattr(diag_mod, "calibrate", _no_fit)
    with pytest.raises(ValueError, match="candidates") as err:
        getattr(bt, fn)(rec, candidates=cands)
    msg = str(err.value)
    # lists the valid names
    for name in ("drift", "line_noise", "hydrodynamics", "anharmonicity", "power_offset"):
        assert repr(name) in msg


def test_diagnose_valid_candidates_pass_the_check():
    assert cand_mod._check_candidates(["drift", "drift", "anharmonicity"]) == [
        "drift", "anharmonicity"]
    assert cand_mod._check_candidates("line_noise") == ["line_noise"]
    assert cand_mod._check_candidates(None) is None
    assert cand_mod._check_alpha(0.01) == 0.01


# ------------------------------------------------------------------------------------------
# f_range above Nyquist
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kw", [dict(method="psd"), dict(method="likelihood",
                                                         likelihood="whittle"), dict()])
@pytest.mark.parametrize("f_range", [(10.0, 751.0), (0.0, 5000.0), (100.0, 1e9)])
def test_f_max_above_nyquist_is_refused(rec, monkeypatch, kw, f_range):
    monkeypatch.setattr(cal_mod, "_calibrate", _no_fit)
    with pytest.raises(ValueError, match=re.escape(f"f_max = {f_range[1]:g} Hz") + " is above the Nyquist "
                       r"frequency fs/2 = 750 Hz"):
        bt.calibrate(rec, f_range=f_range, **kw)


@pytest.mark.parametrize(("f_range", "hint"), [((0.1, 0.5), r"did you mean \(100, 500\) Hz"),
                                               ((300.0, 300.1), r"at least 16$")])
def test_a_band_with_too_few_ordinates_is_refused(rec, monkeypatch, f_range, hint):
    """--f-range 0.1 0.5 meant in kHz kept 2 ordinates and ended in 'did not converge ...
    check the data': the band's ordinate count is checked first, with the kHz reading."""
    monkeypatch.setattr(cal_mod, "_calibrate", _no_fit)
    with pytest.raises(ValueError, match=r"keeps only \d+ periodogram ordinate.*" + hint):
        bt.calibrate(rec, f_range=f_range, method="psd")


def test_f_max_at_nyquist_is_accepted(rec):
    assert opt_mod._check_options([rec], "psd", "auto", None, None, (10.0, 750.0), None,
                                  False, None, True)[1] == (10.0, 750.0)


def test_sample_posterior_f_range_above_nyquist(rec, monkeypatch):
    with pytest.raises(ValueError, match="above the Nyquist"):
        bt.sample_posterior(rec, f_range=(1.0, 800.0), n_steps=20)


# ------------------------------------------------------------------------------------------
# sample_posterior: init_scale and user priors
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e6, 1.5, 0.0, -0.1, float("nan"), float("inf"), True,
                                   "0.1", None])
def test_init_scale_is_validated_first(rec, monkeypatch, scale):
    monkeypatch.setattr(post_mod, "_setup", _no_fit)
    with pytest.raises(ValueError, match=r"init_scale must be a finite number in \(0, 1\]"):
        bt.sample_posterior(rec, init_scale=scale, n_steps=20)


def _float_prior(p):
    return -float(p["k"])


def _numpy_prior(p):
    return np.log(p["gamma"])


def _math_prior(p):
    return math.log(p["k"])


def _branching_prior(p):
    return 0.0 if p["k"] > 1e-5 else -10.0


@pytest.mark.parametrize("fn", [_float_prior, _numpy_prior, _math_prior, _branching_prior])
@pytest.mark.parametrize("how", ["callable", "list", "dict"])
def test_untraceable_user_prior_is_a_clear_type_error(rec, monkeypatch, fn, how):
    monkeypatch.setattr(post_mod, "calibrate", _no_fit)  # checked before the ML fit
    priors = {"callable": fn, "list": [fn], "dict": {"log_prior": fn}}[how]
    with pytest.raises(TypeError, match="not JAX-traceable") as err:
        bt.sample_posterior(rec, priors=priors, n_steps=20)
    msg = str(err.value)
    assert fn.__name__ in msg and "jax.numpy" in msg and "jnp.where" in msg
    assert "'k'" in msg and "'gamma'" in msg and "'tracking_var'" in msg


def test_user_prior_with_unknown_name_or_vector_output(rec, monkeypatch):
    monkeypatch.setattr(post_mod, "calibrate", _no_fit)
    with pytest.raises(ValueError, match=r"reads params\['kappa'\].*'k', 'gamma'"):
        bt.sample_posterior(rec, priors=lambda p: p["kappa"], n_steps=20)
    with pytest.raises(TypeError, match="one scalar"):
        bt.sample_posterior(rec, priors=lambda p: jnp.stack([p["k"], p["gamma"]]), n_steps=20)


def test_traceable_user_priors_pass_the_check():
    names = ("k", "gamma", "tracking_var")
    prior_mod._check_user_priors(
        (lambda p: jnp.log(p["k"]), lambda p: jnp.where(p["k"] > 1e-5, 0.0, -10.0),
         lambda p: 0.0), names)


# ------------------------------------------------------------------------------------------
# failure messages name what the data show
# ------------------------------------------------------------------------------------------
def _with_outliers(n_out, amp=200.0, seed=0):
    x, sig = _trace(seed=seed)
    x = x.copy()
    x[np.arange(n_out) * 300 + 100] += amp * sig
    return _rec(x)


def test_outliers_are_not_blamed_on_dt_much_larger_than_tau():
    """10 outliers of 200 SD break the exact fit (singular Fisher information, or no
    convergence); the frames without them resolve tau well (lag-1 correlation ~15 SE), so the
    message names the outliers and does not blame dt >> tau."""
    with pytest.raises(FitError, match="Fisher information is singular|did not converge") \
            as err:
        bt.calibrate(_with_outliers(10), method="likelihood", likelihood="exact")
    msg = str(err.value)
    assert "dt >> tau" not in msg
    assert "outliers: recording 0 has 10 frame(s) more than 8 robust SDs" in msg
    assert "remove the outliers" in msg


@pytest.mark.parametrize("n_out", [1, 3])
def test_auto_names_outliers_that_hide_the_lag_correlation(n_out):
    with pytest.raises(FitError, match="cannot identify gamma") as err:
        bt.calibrate(_with_outliers(n_out))
    msg = str(err.value)
    assert "dt >> tau" not in msg
    assert f"{n_out} frame(s) more than 8 robust SDs" in msg and "remove the outliers" in msg


def test_non_convergence_names_the_outliers():
    with pytest.raises(FitError, match="did not converge") as err:
        bt.calibrate(_with_outliers(3), method="likelihood", likelihood="exact")
    assert "outliers: recording 0 has 3 frame(s)" in str(err.value)


def test_dt_much_larger_than_tau_is_still_named_when_true():
    """White frames (tau = dt/100): the message does blame dt >> tau."""
    x, _ = _trace(k=5e-3, seed=4)
    with pytest.raises(FitError, match="Fisher information is singular") as err:
        bt.calibrate(_rec(x), method="likelihood", likelihood="exact")
    msg = str(err.value)
    assert "dt >> tau" in msg and "outliers" not in msg


def test_clean_informative_trace_gets_a_neutral_list():
    x, _ = _trace(seed=5)
    why = ref_mod._singular_fisher_causes([_rec(x)], np.array([5e-5, GAMMA, 1e-18]),
                                          ("k", "gamma", "tracking_var"))
    assert "dt >> tau" not in why and "outliers:" not in why
    assert "possible causes" in why and "outliers or steps" in why
    # a step of the trap centre is named
    y = x.copy()
    y[N // 2:] += 20 * float(np.std(x))
    why = ref_mod._singular_fisher_causes([_rec(y)], np.array([5e-5, GAMMA, 1e-18]),
                                          ("k", "gamma", "tracking_var"))
    assert "a step or drift" in why and "dt >> tau" not in why


@pytest.mark.parametrize("kw, band, kept", [
    (dict(f_range=(100.0, 200.0)), r"f_range = \(100, 200\) Hz", 273),
    (dict(f_range=(100.0, 200.0), excluded_ranges=[(150.0, 160.0)]),
     r"f_range = \(100, 200\) Hz and excluded_ranges = \[\(150\.0, 160\.0\)\] Hz", 273 - 27)])
def test_a_failed_fit_names_the_band_the_caller_confined_it_to(rec, monkeypatch, kw, band, kept):
    """A band chosen by the caller (100-200 Hz, far below f_c ~ 300 Hz: k and gamma not
    identified) is a cause the frames cannot show: the refusal names it, with the ordinates
    it kept (counted here: j/T in the band, T = 4096/1500 s, j = 274..546; 150-160 Hz holds
    j = 410..436)."""
    def refuse(*a, **k):
        raise FitError("likelihood fit: the Fisher information is singular")

    monkeypatch.setattr(cal_mod, "_calibrate", refuse)
    with pytest.raises(FitError, match=rf"singular The fit was confined to {band}: {kept} of the 2048 "
                                       r"periodogram ordinates\. .*widen f_range"):
        bt.calibrate(rec, method="psd", **kw)
    monkeypatch.setattr(cal_mod, "_calibrate", refuse)
    with pytest.raises(FitError, match=r"singular$"):  # without a band of the caller's, nothing is added
        bt.calibrate(rec, method="psd")


def test_a_laser_power_missing_on_some_recordings_is_named(rec):
    """Powers on recordings 0 and 2 but not on 1: the default k mode used to fall back to one
    shared k, dropping the declared powers; the recording without one is named."""
    recs = [bt.Recording(_trace(seed=4 + i)[0], frame_interval=DT, exposure=1e-5, laser_power=p)
            for i, p in enumerate((0.25, None, 1.0))]
    with pytest.raises(ValueError, match=r"laser_power is given on recordings \[0, 2\] but missing on "
                                         r"recordings \[1\]: give every recording's laser_power"):
        bt.calibrate(recs)
    assert bt.calibrate(recs, k="shared").param_names[0] == "k"
