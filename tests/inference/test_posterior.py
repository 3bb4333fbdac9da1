"""Posterior sampling (emcee over one jitted, batched JAX log-posterior).

Statistical checks use fixed seeds and state their Monte Carlo standard errors. Data shapes
are few (16 384-frame single recordings, one 65 536-frame recording, one joint set) so that
the maximum-likelihood start and the log-posterior compile a handful of times only.
"""

import json
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import blurtrap
from blurtrap.inference import _log_posterior as lp_mod
from blurtrap.inference import _posterior_priors as prior_mod
from blurtrap.inference import _whittle_closed as wc_mod
from blurtrap.inference._posterior import Posterior, ShortChainWarning, sample_posterior
from blurtrap.inference._priors import (
    InverseGamma,
    LogNormal,
    LogUniform,
    Normal,
    Uniform,
    faxen_factor,
    stokes_gamma_prior,
    stuck_bead_prior,
    water_viscosity,
)

DT = 1.0 / 1500.0  # camera: frame interval = exposure
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6  # [N s/m]
EPS = 2e-9  # [m]
N_SHORT = 16384


def _sim(k, n_frames, seed, n=1, eps=EPS):
    x = blurtrap.simulate(k, GAMMA, DT, DT, n_frames, key=jax.random.key(seed),
                          method="exact_frames", tracking_std=eps, n_traces=n)
    return np.asarray(x, dtype=float).reshape(-1, n_frames)


def _rec(y, **kw):
    return blurtrap.Recording(y, frame_interval=DT, exposure=DT, **kw)


def _quiet_sample(data, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ShortChainWarning)
        return sample_posterior(data, **kw)


@pytest.fixture(scope="module")
def short_rec():
    return _rec(_sim(2e-5, N_SHORT, 7)[0])


@pytest.fixture(scope="module")
def short_post(short_rec):
    return _quiet_sample(short_rec, n_steps=300, seed=3)


# ------------------------------------------------------------------------------------------
# priors
# ------------------------------------------------------------------------------------------
def test_log_uniform_is_uniform_in_log_p():
    pr = LogUniform(1e-6, 1e-3)
    p = jnp.asarray([2e-6, 3e-5, 9e-4])
    # the sampler adds log p (Jacobian of theta = log p): constant inside the bounds
    dens = pr.log_prob(p) + jnp.log(p)
    assert np.allclose(dens, -math.log(math.log(1e3)), rtol=1e-12)
    assert np.all(np.isneginf(pr.log_prob(jnp.asarray([5e-7, 2e-3, -1.0]))))


def test_prior_densities():
    x = jnp.asarray(1.3)
    assert float(Normal(1.0, 0.5).log_prob(x)) == pytest.approx(-0.5 * 0.36 - math.log(0.5))
    assert float(LogNormal(1.0, 0.5).log_prob(x)) == pytest.approx(
        -0.5 * (math.log(1.3) / 0.5) ** 2 - math.log(1.3))
    assert float(InverseGamma(2.0, 3.0).log_prob(x)) == pytest.approx(
        -3.0 * math.log(1.3) - 3.0 / 1.3)
    assert np.isneginf(float(Normal(1.0, 0.5).log_prob(jnp.asarray(-0.1))))
    with pytest.raises(ValueError, match="low < high"):
        LogUniform(2.0, 1.0)
    u = Uniform(0.0, 4.0)
    assert float(u.log_prob(x)) == pytest.approx(-math.log(4.0))
    assert np.all(np.isneginf(u.log_prob(jnp.asarray([0.0, -1.0, 4.5]))))
    with pytest.raises(ValueError, match="0 <= low < high"):
        Uniform(-1.0, 1.0)


def test_stokes_gamma_prior_and_faxen():
    r, eta = 1.53e-6, 0.00093
    pr = stokes_gamma_prior(r, 0.02e-6, viscosity=eta, viscosity_err=0.00002)
    assert float(pr.mean) == pytest.approx(6 * math.pi * eta * r, rel=1e-12)
    rel = math.hypot(0.02 / 1.53, 0.00002 / 0.00093)
    assert float(pr.sd) == pytest.approx(rel * float(pr.mean), rel=1e-9)
    # Faxen at h = 2 r: 1 / (1 - 9/32 + 1/64 - 45/4096 - 1/512)
    x = 0.5
    fac = 1 / (1 - 9 / 16 * x + x**3 / 8 - 45 / 256 * x**4 - x**5 / 16)
    assert faxen_factor(r, 2 * r) == pytest.approx(fac, rel=1e-14)
    prh = stokes_gamma_prior(r, 0.02e-6, viscosity=eta, height=2 * r, height_err=0.1e-6)
    assert float(prh.mean) == pytest.approx(6 * math.pi * eta * r * fac, rel=1e-12)
    assert float(prh.sd) > float(pr.sd) * 0.9  # height error adds variance
    # from temperature via water viscosity (~0.95 mPa s at 295 K)
    prt = stokes_gamma_prior(r, 0.02e-6, temperature=295.0, temperature_err=0.5)
    assert 0.9e-3 < water_viscosity(295.0) < 1.0e-3
    assert float(prt.mean) == pytest.approx(6 * math.pi * float(water_viscosity(295.0)) * r,
                                            rel=1e-12)
    with pytest.raises(ValueError, match="exceed the radius"):
        stokes_gamma_prior(r, 0.02e-6, viscosity=eta, height=0.5 * r)
    with pytest.raises(ValueError, match="viscosity"):
        stokes_gamma_prior(r, 0.02e-6)


def test_stuck_bead_prior():
    pr = stuck_bead_prior(4e-18, 1001)
    assert float(pr.shape) == 500.0 and float(pr.scale) == pytest.approx(500.0 * 4e-18)
    v = jnp.linspace(3e-18, 5e-18, 20001)
    mode = float(v[jnp.argmax(pr.log_prob(v))])
    assert mode == pytest.approx(500 * 4e-18 / 501, rel=1e-3)  # scale / (shape + 1)
    with pytest.raises(ValueError, match="n_frames"):
        stuck_bead_prior(4e-18, 2)


# ------------------------------------------------------------------------------------------
# the sampler
# ------------------------------------------------------------------------------------------
def test_posterior_api(short_post):
    p = short_post
    assert isinstance(p, Posterior)
    assert p.param_names == ("k", "gamma", "tracking_var")
    for name in ("k", "gamma", "tracking_var", "diffusion", "tau", "corner_frequency",
                 "force_per_nm"):
        assert p.samples[name].ndim == 1 and p.samples[name].size == p.n_samples
    s = p.samples
    assert np.allclose(s["tau"], s["gamma"] / s["k"])
    assert np.allclose(s["corner_frequency"], s["k"] / (2 * np.pi * s["gamma"]))
    assert np.allclose(s["force_per_nm"], s["k"] * 1e-9)
    assert np.allclose(s["diffusion"], blurtrap.BOLTZMANN * 295.0 / s["gamma"])
    assert p.chain.shape == (p.n_steps - p.burn_in, 32, 3)
    assert p.burn_in >= 30  # at least 10 % of the steps
    assert 0.2 < float(np.mean(p.acceptance_fraction)) < 0.9
    assert set(p.autocorr_time) == set(p.ess) == set(p.param_names)
    d = json.loads(json.dumps(p.to_dict()))
    assert d["k"] == pytest.approx(float(np.median(s["k"])))
    assert d["stats"]["gamma"]["q16"] < d["gamma"] < d["stats"]["gamma"]["q84"]
    assert d["units"] == "SI" and d["n_walkers"] == 32
    text = p.summary()
    for unit in ("pN/nm", "pN s/um", "nm^2", "um^2/s", "ms", "Hz", "68 %", "95 %"):
        assert unit in text


def test_to_arviz_without_arviz(short_post, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "arviz", None)  # import arviz -> ImportError
    with pytest.raises(ImportError, match="needs arviz"):
        short_post.to_arviz()


def test_same_seed_identical_and_no_global_rng(short_rec, short_post):
    before = np.random.get_state()[1].copy()
    again = _quiet_sample(short_rec, n_steps=300, seed=3)
    assert np.array_equal(np.random.get_state()[1], before)
    for name in short_post.samples:
        assert np.array_equal(again.samples[name], short_post.samples[name])
    other = _quiet_sample(short_rec, n_steps=300, seed=4)
    assert not np.array_equal(other.samples["k"], short_post.samples["k"])


def test_two_compiled_batch_shapes(short_rec):
    # a walker count not used elsewhere: exactly two new traces (full and half ensemble)
    n0 = lp_mod.trace_count()
    _quiet_sample(short_rec, n_walkers=14, n_steps=40, seed=0)
    assert lp_mod.trace_count() - n0 == 2
    # new data of the same shapes reuse both
    rec2 = _rec(_sim(3e-5, N_SHORT, 8)[0])
    _quiet_sample(rec2, n_walkers=14, n_steps=40, seed=1)
    assert lp_mod.trace_count() - n0 == 2


def test_short_chain_warns(short_rec):
    with pytest.warns(ShortChainWarning, match="autocorrelation"):
        sample_posterior(short_rec, n_steps=40, seed=0)


def test_nan_maps_to_minus_inf(short_rec):
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import make_layout
    from blurtrap.inference._spectral import _spectral_args

    lay = make_layout([short_rec], "shared", True)
    spec = _spectral_args([short_rec], lay, get_model(None), 1, None)
    for lik in (spec, wc_mod._rational_args([short_rec], spec)):
        args = lp_mod._PostArgs(
            lik=lik, priors=prior_mod._resolve_priors(lay, None)[0], names=lay.names,
            user_log_prior=(), chunk=1)
        th = np.log([[2e-5, GAMMA, 4e-18], [2e-5, GAMMA, 4e-18]])
        th[1, 2] = 800.0  # eps^2 overflows: inf - inf inside
        out = np.asarray(lp_mod._batched_log_posterior(jnp.asarray(th), args))
        assert np.isfinite(out[0]) and out[1] == -np.inf


def test_bad_arguments(short_rec):
    with pytest.raises(ValueError, match="likelihood"):
        sample_posterior(short_rec, likelihood="bayes")
    with pytest.raises(ValueError, match="n_walkers must be even"):
        sample_posterior(short_rec, n_walkers=7)
    with pytest.raises(ValueError, match="unknown parameter 'kappa'"):
        sample_posterior(short_rec, priors={"kappa": Normal(1.0, 1.0)})
    with pytest.raises(TypeError, match="Prior"):
        sample_posterior(short_rec, priors={"gamma": 3.0})
    with pytest.raises(ValueError, match="support"):
        sample_posterior(short_rec, priors={"k": LogUniform(1.0, 2.0)}, n_steps=20)


def test_priors_change_result_in_expected_direction(short_rec, short_post):
    base = short_post
    lo, hi = base.interval("gamma", 0.68)
    g_med = float(np.median(base.samples["gamma"]))
    # tight Stokes prior centred 5 % above the data's value: narrower and pulled up
    mean = 1.05 * g_med
    prior = Normal(mean, 0.002 * mean)
    tight = _quiet_sample(short_rec, n_steps=300, seed=3, priors={"gamma": prior})
    tlo, thi = tight.interval("gamma", 0.68)
    assert (thi - tlo) < 0.3 * (hi - lo)
    assert float(np.median(tight.samples["gamma"])) > g_med + 0.5 * (mean - g_med)
    # stuck-bead prior on eps^2 (10 000 frames): eps^2 interval shrinks
    sb = _quiet_sample(short_rec, n_steps=300, seed=3,
                       priors={"tracking_var": stuck_bead_prior(EPS**2, 10000)})
    elo, ehi = base.interval("tracking_var", 0.68)
    slo, shi = sb.interval("tracking_var", 0.68)
    assert (shi - slo) < 0.5 * (ehi - elo)


def test_joint_linear_power():
    c_true = 2e-5 / 0.1  # k = c P, 0.02 pN/nm at 100 mW
    powers = (0.05, 0.1, 0.15)
    recs = [_rec(_sim(c_true * pw, N_SHORT, 20 + i)[0], laser_power=pw)
            for i, pw in enumerate(powers)]
    p = _quiet_sample(blurtrap.RecordingSet(recs), k="linear_power", n_steps=300, seed=0)
    assert p.param_names == ("c", "gamma", "tracking_var")
    assert p.k_mode == "linear_power"
    for pw in powers:
        kk = p.samples[f"k[P={pw * 1e3:g} mW]"]
        assert np.allclose(kk, p.samples["c"] * pw)
        assert f"tau[P={pw * 1e3:g} mW]" in p.samples
    for name, truth in (("c", c_true), ("gamma", GAMMA), ("tracking_var", EPS**2)):
        s = p.samples[name]
        assert abs(np.median(s) - truth) < 4 * np.std(s), name
    assert "pN/nm/W" in p.summary()


def test_log_posterior_is_likelihood_plus_prior_plus_jacobian(short_rec):
    """Every likelihood form: log post(theta) = -nll(p) + log prior(p) + sum(theta)."""
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import (
        exact_nll,
        make_exact_args,
        make_layout,
        spectral_nll,
    )
    from blurtrap.inference._spectral import _spectral_args

    rec = _rec(np.asarray(short_rec.positions)[:2048])
    lay = make_layout([rec], "shared", True)
    mdl = get_model(None)
    gprior = Normal(GAMMA, 0.05 * GAMMA)
    priors, fns = prior_mod._resolve_priors(lay, {"gamma": gprior})
    th = np.log([[2e-5, GAMMA, 4e-18], [3e-5, 1.1 * GAMMA, 2e-18]])
    spec = _spectral_args([rec], lay, mdl, 1, None)
    rat = wc_mod._rational_args([rec], spec)
    for lik, nll, chunk in ((spec, spectral_nll, 1),
                            (rat, wc_mod._rational_whittle_nll, 1),
                            (make_exact_args([rec], lay, mdl), exact_nll, None)):
        args = lp_mod._PostArgs(lik=lik, priors=priors, names=lay.names,
                                  user_log_prior=fns, chunk=chunk)
        got = lp_mod._compiled_log_posterior(args)(th)
        assert got.dtype == np.float64 and isinstance(got, np.ndarray)
        for t, g in zip(th, got, strict=True):
            p = jnp.exp(jnp.asarray(t))
            want = (-nll(p, lik) + gprior.log_prob(p[1]) + float(np.sum(t))
                    - math.log(p[0]) - math.log(math.log(1e10))  # default LogUniform on k
                    - math.log(1e-10))  # default Uniform(0, 1e-10 m^2) on eps^2
            assert g == pytest.approx(float(want), rel=1e-12, abs=1e-8)


# ------------------------------------------------------------------------------------------
# statistical validation
# ------------------------------------------------------------------------------------------
def test_median_and_sd_match_ml_and_fisher():
    """Well-identified data (65 536 frames, eps = 4 nm): with a prior flat in p (a user
    log-prior cancelling the default log-uniform 1/p) the posterior is the likelihood, whose
    median and SD must match the ML estimate and Fisher SE to 10 % of the SE. Monte Carlo
    error with ESS >~ 1000: SE(median) ~ 1.25/sqrt(ESS) ~ 0.04 SE, SE(SD)/SD ~ 0.03."""
    rec = _rec(_sim(2e-5, 65536, 11, eps=4e-9)[0])

    def flat_in_p(d):  # cancels the default log-uniform 1/p (eps^2: uniform already)
        return jnp.log(d["k"]) + jnp.log(d["gamma"])

    p = _quiet_sample(rec, priors=flat_in_p, n_steps=1500, seed=5)
    for i, name in enumerate(p.param_names):
        s = p.samples[name]
        ml, se = p.ml.values[i], p.ml.errors[i]
        assert p.ess[name] > 800, name
        assert abs(np.median(s) - ml) < 0.1 * se, name
        assert np.std(s) == pytest.approx(se, rel=0.1), name


@pytest.mark.slow
def test_interval_coverage():
    """40 camera datasets (dt = W = 1/1500 s, eps = 2 nm, k log-uniform in 0.005-0.1
    pN/nm, 16 384 frames, default priors). Coverage counts of the central 68 % / 95 %
    intervals are Binomial(40, q): SE = sqrt(q (1-q) / 40) = 0.074 (68 %) and 0.034 (95 %);
    we require |rate - q| < 4 SE for each of k, gamma, eps^2. Sharper, from the same runs:
    the probability integral transforms u = P(param < truth | data) of a calibrated
    posterior are uniform, so z = Phi^-1(u) is N(0, 1): |mean z| < 4/sqrt(40) and
    |SD z - 1| < 4/sqrt(2 x 40) per parameter (a log-uniform eps^2 prior, which piles mass
    near eps^2 ~ 0 for stiff traps, fails the SD check).

    400 steps: tau ~ 30-60 steps here, so burn-in max(3 tau, 40) and >= 200 independent
    samples per run; the interval end points then carry a Monte Carlo error of <~ 0.1
    posterior SD, which moves the coverage of a 95 % interval by < 1 %."""
    from statistics import NormalDist

    n = 40
    rng = np.random.default_rng(2024)
    ks = np.exp(rng.uniform(np.log(5e-6), np.log(1e-4), n))
    ys = [_sim(float(k), N_SHORT, 1000 + i)[0] for i, k in enumerate(ks)]
    truth = {"gamma": GAMMA, "tracking_var": EPS**2}
    names = ("k", "gamma", "tracking_var")
    hits = {q: {name: 0 for name in names} for q in (0.68, 0.95)}
    zs = {name: [] for name in names}
    for i in range(n):
        p = _quiet_sample(_rec(ys[i]), n_steps=400, seed=i)
        truth["k"] = ks[i]
        for q in (0.68, 0.95):
            for name in names:
                lo, hi = p.interval(name, q)
                hits[q][name] += int(lo <= truth[name] <= hi)
        for name in names:
            s = p.samples[name]
            u = (np.sum(s < truth[name]) + 0.5) / (s.size + 1.0)
            zs[name].append(NormalDist().inv_cdf(float(u)))
    for q in (0.68, 0.95):
        se = math.sqrt(q * (1 - q) / n)
        for name, h in hits[q].items():
            assert abs(h / n - q) < 4 * se, (q, name, h, hits)
    for name, z in zs.items():
        z = np.asarray(z)
        assert abs(np.mean(z)) < 4 / math.sqrt(n), (name, np.mean(z))
        assert abs(np.std(z, ddof=1) - 1.0) < 4 / math.sqrt(2 * n), (name, np.std(z, ddof=1))


def test_auto_length_extends_the_chain_until_50_autocorrelation_times(short_rec, monkeypatch):
    """n_steps='auto' (the default): the run grows in chunks until it holds 50 integrated
    autocorrelation times (an independent pass: the old default of 2000 steps warned on
    every fit of a camera recording whose eps^2 sits near 0), up to its cap, then warns."""
    import warnings

    from blurtrap.inference import _posterior_chain as chain_mod

    monkeypatch.setattr(chain_mod, "AUTO_FIRST_STEPS", 60)
    monkeypatch.setattr(chain_mod, "AUTO_MAX_STEPS", 1000)
    real = chain_mod._integrated_time
    tau = {"value": 4.0}  # 50 x 4 = 200 steps needed: 60, then a chunk of at least 500

    def fake(emcee, chain):
        return np.full(np.shape(chain)[-1], tau["value"]) if np.shape(chain)[0] > 0 else real(emcee, chain)

    monkeypatch.setattr(chain_mod, "_integrated_time", fake)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ShortChainWarning)
        post = sample_posterior(short_rec, seed=1)
    assert post.n_steps == 560 and post.log_prob.shape[0] + post.burn_in == 560
    tau["value"] = 100.0  # 5000 steps needed: stops at the cap and says so
    with pytest.warns(ShortChainWarning, match=r"chain \(1000 steps\)"):
        post = sample_posterior(short_rec, seed=1)
    assert post.n_steps == 1000
    with pytest.raises(ValueError, match="n_steps must be 'auto' or an integer >= 10"):
        sample_posterior(short_rec, n_steps="long")
