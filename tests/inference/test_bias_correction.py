"""Parametric-bootstrap bias correction (blurtrap.inference._bias).

The core is checked on a toy whose bias is known in closed form: N i.i.d. centred Gaussian
positions of variance kT/k, k estimated as kT / mean(x^2). Then mean(x^2) ~ (kT/k) chi2_N / N
and E[k_hat] = k N / (N - 2) exactly, so the bootstrap bias at theta is 2 theta / (N - 2) in
expectation for any number of replicates B, and

- once corrected (2 k_hat - mean of refits): E = k N (N - 4) / (N - 2)^2;
- iterated once (k_hat - b(corrected)): E = k N / (N - 2) (1 - 2 (N - 4) / (N - 2)^2).

The batched exact refit is checked against ``calibrate(..., likelihood="exact")`` on frames
from the independent circulant-embedding generator (tests/_circulant.py).
"""

import jax
import numpy as np
import pytest
from _circulant import circulant_frames

import blurtrap as bt
from blurtrap.inference._bias import (
    _keep_valid,
    bootstrap_correct,
    exact_template,
    refit_exact,
    refit_start,
)
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import make_layout, rec_meta

KT = 1.380649e-23 * 295.0
K_TRUE = 5e-5
N = 20


def _toy_refit(theta, key, n_boot):
    """kT / mean(x^2) of ``n_boot`` toy data sets of N frames at k = theta[0]."""
    x = jax.random.normal(key, (n_boot, N)) * np.sqrt(KT / theta[0])
    return (KT / np.mean(np.asarray(x) ** 2, axis=1))[:, None]


def _toy_study(n_sets, n_boot, iterate):
    rng = np.random.default_rng(11)
    est, cor = np.empty(n_sets), np.empty(n_sets)
    key = jax.random.PRNGKey(3)
    for i in range(n_sets):
        x = rng.standard_normal(N) * np.sqrt(KT / K_TRUE)
        k_hat = np.array([KT / np.mean(x**2)])
        r = bootstrap_correct(k_hat, _toy_refit, jax.random.fold_in(key, i), n_boot,
                              iterate=iterate, support=["positive"])
        est[i], cor[i] = r.estimate[0], r.corrected[0]
    return est / K_TRUE, cor / K_TRUE


@pytest.mark.parametrize("iterate", [False, True])
def test_toy_bias_removed_to_the_analytic_value(iterate):
    # 3000 data sets, B = 20: MC SE of the mean of k/k_true ~ 0.45 % (stated from the sample)
    est, cor = _toy_study(3000, 20, iterate)
    once = N * (N - 4) / (N - 2) ** 2  # 0.9877
    expect = N / (N - 2) * (1 - 2 * (N - 4) / (N - 2) ** 2) if iterate else once
    se_est = est.std(ddof=1) / np.sqrt(est.size)
    se_cor = cor.std(ddof=1) / np.sqrt(cor.size)
    # the uncorrected estimate carries the known +2/(N - 2) = +11.1 % bias ...
    assert abs(est.mean() - N / (N - 2)) < 3 * se_est
    assert est.mean() - 1 > 15 * se_est
    # ... the corrected one has the analytic residual (O(1/N^2)), far from the +11 %
    assert abs(cor.mean() - expect) < 3 * se_cor, (cor.mean(), expect, se_cor)


def test_same_key_same_result_and_estimate_kept():
    k_hat = np.array([6e-5])
    a = bootstrap_correct(k_hat, _toy_refit, jax.random.PRNGKey(0), 50)
    b = bootstrap_correct(k_hat, _toy_refit, jax.random.PRNGKey(0), 50)
    c = bootstrap_correct(k_hat, _toy_refit, jax.random.PRNGKey(1), 50)
    assert a.corrected[0] == b.corrected[0] and a.corrected[0] != c.corrected[0]
    assert a.estimate[0] == 6e-5 and a.n_boot == 50 and a.iterations == 1
    assert a.corrected[0] == pytest.approx(6e-5 - a.bias[0], rel=1e-15)
    # the Monte Carlo error of the bias is the refits' SD / sqrt(B): ~ k sqrt(2/N) / sqrt(B)
    assert a.bias_se[0] == pytest.approx(6e-5 * np.sqrt(2 / N) / np.sqrt(50), rel=0.4)


def test_kept_valid_at_the_bounds():
    est = np.array([1.0, 2.0, 0.1])
    c = _keep_valid(np.array([-0.5, 1.0, -0.2]), est, ("positive", "positive", "nonnegative"))
    assert c[0] == pytest.approx(1.0 / 2.5)  # ratio form est^2 / (2 est - c), positive
    assert c[1] == 1.0 and c[2] == 0.0
    free = _keep_valid(np.array([-0.5]), np.array([1.0]), ("real",))
    assert free[0] == -0.5


@pytest.mark.parametrize("kw, match", [
    ({"n_boot": 1}, "n_boot must be an integer >= 2; got n_boot = 1"),
    ({"n_boot": 10.0}, "n_boot must be an integer >= 2; got n_boot = 10.0"),
    ({"n_boot": True}, "n_boot must be an integer >= 2"),
    ({"estimate": np.array([np.nan])}, "estimate must be a finite 1-D array"),
    ({"support": ["positive", "positive"]}, "support must name one of .* for each of the 1 "),
    ({"support": ["psoitive"]}, r"got support = \('psoitive',\)"),
])
def test_bad_arguments(kw, match):
    args = {"estimate": np.array([5e-5]), "n_boot": 10, "support": None} | kw
    with pytest.raises(ValueError, match=match):
        bootstrap_correct(args["estimate"], _toy_refit, jax.random.PRNGKey(0), args["n_boot"],
                          support=args["support"])


def test_refit_fails_clearly_when_every_refit_fails():
    with pytest.raises(ValueError, match="fewer than 2 refits succeeded"):
        bootstrap_correct(np.array([5e-5]), lambda t, k, b: np.full((b, 1), np.nan),
                          jax.random.PRNGKey(0), 10)


def test_batched_exact_refit_equals_calibrate():
    """Camera 1500 fps, W = 0.1 dt, eps = 2 nm, 1024 frames: rows at and off the eps^2 bound."""
    dt, gamma = 1 / 1500, 6 * np.pi * 0.00093 * 1.53e-6
    w, eps2 = 0.1 * dt, 4e-18
    ys = circulant_frames(K_TRUE, gamma, w, dt, eps2, 1024, seed=5, reps=2)
    recs = [bt.Recording(y, frame_interval=dt, exposure=w, temperature=295.0) for y in ys]
    fits = [bt.calibrate(r, method="likelihood", likelihood="exact") for r in recs]
    want = np.array([[f.params[n] for n in ("k", "gamma", "tracking_var")] for f in fits])
    tpl = exact_template(get_model("standard"), make_layout(recs[:1], "shared", True),
                         rec_meta(recs[:1]), 1024)
    got, ok = refit_exact(tpl, ys + 1e-6, refit_start([K_TRUE, gamma, eps2], 295.0), 30)
    assert any("tracking_var" in f.at_bounds for f in fits)  # the bound case is covered
    assert any("tracking_var" not in f.at_bounds for f in fits)
    np.testing.assert_allclose(got[:, :2], want[:, :2], rtol=1e-6)
    inner = np.array(["tracking_var" not in f.at_bounds for f in fits])
    np.testing.assert_allclose(got[inner, 2], want[inner, 2], rtol=1e-5)
    assert np.all(got[~inner, 2] < 1e-6 * eps2)
