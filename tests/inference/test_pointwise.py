"""Pointwise log-likelihood of posterior draws (Posterior.log_likelihood, the log_likelihood
group of to_arviz): each observation's value against an independent evaluation (scipy's Gamma
density of every periodogram ordinate, the ARMA likelihood per recording), and their sum
against the likelihood the sampler used, up to a constant of the data."""

from __future__ import annotations

import warnings

import jax
import numpy as np
import pytest
from scipy import stats

import blurtrap
from blurtrap.inference import _posterior as pm
from blurtrap.inference._likelihood import arma_loglik
from blurtrap.inference._log_posterior import _nll
from blurtrap.inference._models import get_model
from blurtrap.inference._pointwise import spectral_pointwise
from blurtrap.inference._posterior import ShortChainWarning
from blurtrap.inference._problems import make_layout, spectral_model_psd
from blurtrap.inference._whittle_closed import _RationalWhittleArgs

DT = 1.0 / 1500.0
K, GAMMA = 2e-5, 1e-8


def _frames(n, seed, eps=2e-9):
    """AR(1) frames with white noise (numpy; any stationary data serve these identities)."""
    rng = np.random.default_rng(seed)
    rho = np.exp(-DT * K / GAMMA)
    sd = np.sqrt(1.38e-23 * 295 / K)
    x = np.empty(n)
    x[0] = rng.normal(0, sd)
    z = rng.normal(0, sd * np.sqrt(1 - rho**2), n)
    for i in range(1, n):
        x[i] = rho * x[i - 1] + z[i]
    return x + rng.normal(0, eps, n) + 3e-7  # a constant offset too


def _recs(ns, seed=0):
    return [blurtrap.Recording(_frames(n, seed + i), frame_interval=DT, exposure=DT)
            for i, n in enumerate(ns)]


def _params(su, n=4, seed=1):
    """Natural parameters around the ML point (one per row)."""
    rng = np.random.default_rng(seed)
    theta = su.theta_start + 0.05 * rng.standard_normal((n, su.theta_start.size))
    return np.exp(theta)


@pytest.mark.parametrize("model, f_range, evaluation", [
    ("standard", None, "closed"),
    ("standard+drift", None, "ordinates"),
    ("standard", (5.0, 600.0), "ordinates"),
])
def test_whittle_bands_sum_scipy_gamma_densities_and_the_sampler_likelihood(
        model, f_range, evaluation):
    su = pm._setup(_recs([3000, 2048]), model, None, 8, "whittle", None, f_range)
    assert isinstance(su.lik, _RationalWhittleArgs) == (evaluation == "closed")
    ps = _params(su)
    vals = su.pointwise.fn(ps)
    assert vals.shape == (len(ps), len(su.pointwise.labels))
    assert su.pointwise.dim == "band"
    # every ordinate's density from scipy, summed per recording
    spec = pm._spectral_args(su.recs, su.layout, su.model, 1, f_range)
    if evaluation == "closed":
        import dataclasses
        spec = dataclasses.replace(spec, block_len=None)
    w, power = np.asarray(spec.weight), np.asarray(spec.power)
    rec_of_label = np.array([int(lab.split(":")[0].split()[1]) for lab in su.pointwise.labels])
    consts = []
    for p, v in zip(ps, vals, strict=True):
        s = np.asarray(spectral_model_psd(p, spec))
        ok = w > 0
        ref = np.where(ok, stats.gamma.logpdf(power, a=np.where(ok, w, 1.0),
                                              scale=s / np.where(ok, w, 1.0)), 0.0)
        for r in range(w.shape[0]):
            assert v[rec_of_label == r].sum() == pytest.approx(ref[r].sum(), rel=1e-10)
        consts.append(v.sum() + float(_nll(p, su.lik)))
    # the sum over observations is the sampler's log-likelihood plus a constant of the data
    assert np.ptp(consts) < 1e-7 * abs(vals.sum(axis=1)).max()


def test_bands_are_log_spaced_and_cover_every_ordinate_once():
    recs = _recs([4096])
    mdl = get_model("standard")
    spec = pm._spectral_args(recs, make_layout(recs, "shared", True), mdl, 1, None)
    labels = spectral_pointwise(spec).labels
    lo = np.array([float(lab.split(": ")[1].split("-")[0]) for lab in labels])
    hi = np.array([float(lab.split("-")[1].split()[0]) for lab in labels])
    assert np.all(lo[1:] > hi[:-1])  # disjoint, in order
    assert lo[0] == pytest.approx(1 / (4096 * DT), rel=1e-3)  # first ordinate
    assert hi[-1] == pytest.approx(0.5 / DT, rel=1e-3)  # Nyquist
    widths = np.log(hi[-10:] / lo[-10:])
    assert np.ptp(widths) < 0.05  # log-spaced at high frequency
    assert 40 <= len(labels) <= 64


def test_exact_pointwise_is_the_arma_likelihood_of_each_recording():
    su = pm._setup(_recs([700, 1000]), "standard", None, 8, "exact", None, None)
    assert su.pointwise.dim == "recording" and len(su.pointwise.labels) == 2
    ps = _params(su, n=2)
    vals = su.pointwise.fn(ps)
    loglik = jax.jit(arma_loglik)
    for p, v in zip(ps, vals, strict=True):
        k, g, e2 = p
        c0, c1, rho = su.model.moments(np.array([k, k]), g, e2, su.lik.meta.dt, su.lik.meta.w,
                                       su.lik.meta.temp)
        for r, rec in enumerate(su.recs):
            ref = float(loglik(np.asarray(rec.positions), c0[r], c1[r], rho[r]))
            assert v[r] == pytest.approx(ref, rel=1e-10)
        assert v.sum() == pytest.approx(-float(_nll(p, su.lik)), rel=1e-10)


@pytest.fixture(scope="module")
def post():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ShortChainWarning)
        return blurtrap.sample_posterior(_recs([2048]), n_walkers=8, n_steps=30, seed=3)


def test_log_likelihood_of_the_draws_and_thinning(post):
    vals, dim, labels, steps = post.log_likelihood()
    n_kept = post.chain.shape[0]
    assert vals.shape == (8, n_kept, len(labels)) and dim == "band"
    assert np.array_equal(steps, np.arange(n_kept))
    # walker w, step s is chain[s, w]
    one = post.pointwise.fn(post.chain[3, 5][None])[0]
    assert np.allclose(vals[5, 3], one, rtol=1e-12)
    v2, _, _, st2 = post.log_likelihood(max_draws=40)
    assert v2.shape[1] == len(st2) <= 5 and st2[-1] == n_kept - 1
    assert np.allclose(v2, vals[:, st2], rtol=1e-12)
    from blurtrap.inference._posterior_result import _thinned_steps

    assert _thinned_steps(0, 8, 40).size == 0  # nothing kept: nothing to thin
    for bad in (3, 2.5, True):
        with pytest.raises(ValueError, match="max_draws"):
            post.log_likelihood(max_draws=bad)


def test_to_arviz_log_likelihood_group_works_with_loo(post):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        az = pytest.importorskip("arviz")
    idata = post.to_arviz(max_draws=80)
    ll = idata.log_likelihood if hasattr(idata, "log_likelihood") else idata["log_likelihood"]
    vals, _, labels, steps = post.log_likelihood(max_draws=80)
    assert tuple(ll["periodogram"].dims) == ("chain", "draw", "band")
    assert np.array_equal(ll["periodogram"].values, vals)
    assert list(ll["periodogram"].coords["band"].values) == list(labels)
    postg = idata.posterior if hasattr(idata, "posterior") else idata["posterior"]
    assert np.array_equal(postg["k"].values, post.draws("k")[:, steps])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loo = az.loo(idata)
    # elpd is the summed pointwise log-likelihood less a small effective-parameter penalty
    lppd = float(np.sum(np.log(np.mean(np.exp(vals - vals.max(axis=(0, 1))), axis=(0, 1)))
                        + vals.max(axis=(0, 1))))
    assert 0 < lppd - float(loo["elpd_loo"]) < 10
    no_ll = post.to_arviz(log_likelihood=False)
    assert "log_likelihood" not in (no_ll.groups() if hasattr(no_ll, "groups") else no_ll)
