"""The likelihoods behind ``sample_posterior``: the closed-form Whittle evaluation against a
literal NumPy Whittle sum of the public ``psd_measured``; the exact-likelihood posterior,
a joint ``k = c P`` posterior and a posterior with an extra effect, each against an
importance-sampling evaluation of the same density (independent of emcee) and against the
matching maximum-likelihood fits; the arviz export.

Statistical tolerances: the Monte Carlo SE of a posterior median is ~1.25 SD/sqrt(ESS) and
that of an SD ~SD/sqrt(2 ESS), for emcee's ESS and the importance sampler's alike; checks
allow 4 combined SEs.
"""

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import blurtrap
from blurtrap.inference import _posterior as pm
from blurtrap.inference import _posterior_result as res_mod
from blurtrap.inference import _whittle_closed as wc_mod
from blurtrap.inference._models import get_model
from blurtrap.inference._posterior import ShortChainWarning, sample_posterior
from blurtrap.inference._problems import make_layout
from blurtrap.inference._spectral import _spectral_args

DT = 1.0 / 1500.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6  # [N s/m]
EPS = 2e-9  # [m]
KT = blurtrap.BOLTZMANN * 295.0


def _sim(k, n_frames, seed, n=1, eps=EPS):
    x = blurtrap.simulate(k, GAMMA, DT, DT, n_frames, key=jax.random.key(seed),
                          method="exact_frames", tracking_std=eps, n_traces=n)
    return np.asarray(x, dtype=float).reshape(-1, n_frames)


def _quiet_sample(data, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ShortChainWarning)
        return sample_posterior(data, **kw)


# ------------------------------------------------------------------------------------------
# closed-form Whittle likelihood == literal Whittle sum
# ------------------------------------------------------------------------------------------
def _numpy_whittle_nll(recs, k_rec, gamma, eps2, blur=True):
    """Literal reference: periodogram by numpy FFT, P_d(f) from the public psd_measured,
    -sum_j w_j [log P_j - log ref + I_j / P_j] with w = 1/2 at Nyquist; ref = the mean
    ordinate (the same additive constant as spectral_nll)."""
    ords = []
    for r in recs:
        y = np.asarray(r.positions, dtype=float)
        n, dt = y.size, float(r.frame_interval)
        spec = np.fft.rfft(y - y.mean())[1:]
        power = (spec.real**2 + spec.imag**2) * dt / n
        f = np.arange(1, n // 2 + 1) / (n * dt)
        wt = np.ones_like(f)
        if n % 2 == 0:
            wt[-1] = 0.5
        ords.append((f, power, wt))
    log_ref = math.log(np.mean(np.concatenate([o[1] for o in ords])))
    total = 0.0
    for i, (r, (f, power, wt)) in enumerate(zip(recs, ords, strict=True)):
        w = float(r.exposure) if blur else 1e-15
        psd = np.asarray(blurtrap.psd_measured(f, k_rec[i], gamma, w, 295.0,
                                               frame_interval=float(r.frame_interval),
                                               tracking_var=eps2))
        total += np.sum(wt * (np.log(psd) - log_ref + power / psd))
    return total


CASES = {
    # name: (frames per recording, frame intervals, model, k mode); odd and even lengths
    "joint_lengths_rates": ([700, 1201, 64], [DT, 1.3 * DT, 0.7 * DT], "standard",
                            "per_recording"),
    "blur_no_noise": ([512, 513], [DT, DT], "blur", "shared"),
    "naive_aliased": ([601], [DT], "naive_aliased", "shared"),
    "power_offset": ([400, 401, 402], [DT, DT, DT], "standard+power_offset", "linear_power"),
}


@eqx.filter_jit
def _all_paths(ps, rat):
    """(trials, 3): the auto, lag-sum and ordinate evaluations, and lag_ok, per trial."""
    def one(p):
        vals = [wc_mod._rational_whittle_nll(p, rat, path)
                for path in ("auto", "lags", "ordinates")]
        return jnp.stack(vals), wc_mod._rational_parts(p, rat)["lag_ok"]

    return jax.vmap(one)(ps)


@pytest.mark.parametrize("case", sorted(CASES))
def test_closed_form_whittle_equals_literal_sum(case):
    sizes, dts, model, k_mode = CASES[case]
    rng = np.random.default_rng(len(case))
    powers = [0.05, 0.1, 0.15]
    # any data will do for an identity between two evaluations of one function
    recs = [blurtrap.Recording(1e-8 * rng.standard_normal(n), frame_interval=dt,
                               exposure=0.8 * dt, laser_power=powers[i])
            for i, (n, dt) in enumerate(zip(sizes, dts, strict=True))]
    mdl = get_model(model)
    lay = make_layout(recs, k_mode, mdl.noise, tuple(p.name for p in mdl.extra_params))
    spec = _spectral_args(recs, lay, mdl, 1, None)
    assert wc_mod._rational_ok(mdl, None)
    rat = wc_mod._rational_args(recs, spec)
    vals = {"k": 2e-5, "c": 2e-4, "gamma": GAMMA, "tracking_var": EPS**2, "power_offset": 0.01}
    ps = np.array([[vals[n.split("[")[0]] * math.exp(0.3 * rng.normal()) for n in lay.names]
                   for _ in range(3)])
    got, lag_ok = _all_paths(jnp.asarray(ps), rat)
    assert np.all(np.asarray(lag_ok))  # camera data: |theta| < 0.3, the lag sums are used
    for p, g in zip(ps, np.asarray(got), strict=True):
        if k_mode == "linear_power":
            k_rec = p[0] * (np.array(powers) - p[lay.names.index("power_offset")])
            gamma = p[1]
        else:
            k_rec, gamma = p[: lay.n_k][np.asarray(lay.k_index)], p[lay.n_k]
        eps2 = p[lay.names.index("tracking_var")] if mdl.noise else 0.0
        want = _numpy_whittle_nll(recs, k_rec, gamma, eps2, blur=mdl.blur)
        assert g == pytest.approx(np.full(3, want), rel=1e-11)


def test_closed_form_whittle_falls_back_for_large_theta():
    """Strong white noise with dt << tau makes the MA root theta -> -rho ~ -1: the truncated
    lag sum is no longer exact, the ordinate sum is used, and the value is still the literal
    Whittle sum; short records exercise the (-theta)^N term of the closed-form log sum."""
    for n in (6, 7, 50, 4096):
        y = np.random.default_rng(n).standard_normal(n) * 1e-8
        rec = blurtrap.Recording(y, frame_interval=1e-5, exposure=1e-6)
        lay = make_layout([rec], "shared", True)
        spec = _spectral_args([rec], lay, get_model(None), 1, None)
        rat = wc_mod._rational_args([rec], spec)
        for eps2, lag_ok in ((1e-20, True), (1e-13, False)):
            p = jnp.asarray([1e-6, GAMMA, eps2])
            parts = wc_mod._rational_parts(p, rat)
            assert bool(parts["lag_ok"]) is lag_ok, (n, eps2, float(parts["theta"][0]))
            want = _numpy_whittle_nll([rec], [1e-6], GAMMA, eps2)
            assert float(wc_mod._rational_whittle_nll(p, rat)) == pytest.approx(want, rel=1e-11)
        assert float(parts["theta"][0]) < -0.9


def test_leakage_decides_the_whittle_form():
    """The closed form (P_d) stands in for calibrate's Whittle likelihood only when the
    Fejer leakage of the finite record is negligible: u0 = 2 C(1) / (N num(0)) ~ rho tau/T.
    Long camera records qualify; a short record of a soft trap does not."""
    def leak(k, n):
        rec = blurtrap.Recording(np.random.default_rng(0).standard_normal(n) * 1e-8,
                                 frame_interval=DT, exposure=DT)
        lay = make_layout([rec], "shared", True)
        spec = _spectral_args([rec], lay, get_model(None), 1, None)
        return wc_mod._leakage(np.array([k, GAMMA, EPS**2]), wc_mod._rational_args([rec], spec))

    for k, n in ((5e-6, 65536), (2e-5, 16384), (1e-4, 4096), (2e-6, 2048)):
        # num(0) = P_d(0) (1 - rho)^2 / dt, from the public spectrum and autocovariance
        rho = math.exp(-DT * k / GAMMA)
        p0 = float(blurtrap.psd_measured(0.0, k, GAMMA, DT, 295.0, frame_interval=DT,
                                         tracking_var=EPS**2))
        c1 = float(blurtrap.frame_autocovariance(1, k, GAMMA, DT, DT, 295.0, EPS**2))
        want = 2.0 * c1 * DT / (n * p0 * (1.0 - rho) ** 2) * math.sqrt(n)
        assert leak(k, n) == pytest.approx(want, rel=1e-9), (k, n)
    assert leak(5e-6, 65536) < wc_mod.LEAKAGE_MAX < leak(2e-6, 2048)


# ------------------------------------------------------------------------------------------
# posterior vs maximum likelihood: exact likelihood, joint k = c P, an extra effect
# ------------------------------------------------------------------------------------------
def _flat_in_p(names):
    """User log-prior that cancels the default log-uniform 1/p of the scale parameters
    (eps^2's default prior is uniform already): posterior = likelihood."""

    def f(d):
        return sum(jnp.log(d[n]) for n in names if n != "tracking_var")

    return f


def _setup_and_sample(data, n_steps, seed, **kw):
    """The posterior by emcee, and the set-up (same density) for an independent check."""
    su = pm._setup(data, kw.get("model"), kw.get("priors"), 32, kw.get("likelihood", "whittle"),
                   kw.get("k"), None)
    return su, _quiet_sample(data, n_steps=n_steps, seed=seed, **kw)


def _importance_reference(su, n=12000, scale=1.4, seed=0):
    """Posterior median and SD of every parameter by importance sampling from a widened
    Gaussian in log parameters (centre: ML, covariance: 1.4^2 x Fisher), evaluated with the
    sampler's own compiled density in batches of 32 (no new compilation). Independent of
    emcee. Returns ({name: (median, sd)}, effective sample size)."""
    d = len(su.layout.names)
    chol = np.linalg.cholesky(su.cov_theta)
    z = np.random.default_rng(seed).standard_normal((n, d))
    th = su.theta_start[None, :] + scale * z @ chol.T
    lp = np.concatenate([su.log_prob(th[i:i + 32]) for i in range(0, n, 32)])
    logw = lp + 0.5 * np.sum(z * z, axis=1)
    w = np.exp(logw - np.max(logw))
    w /= w.sum()
    out = {}
    for i, name in enumerate(su.layout.names):
        x = np.exp(th[:, i])
        order = np.argsort(x)
        cdf = np.cumsum(w[order])
        med = float(x[order][np.searchsorted(cdf, 0.5)])
        mean = float(np.sum(w * x))
        out[name] = (med, float(np.sqrt(np.sum(w * (x - mean) ** 2))))
    return out, float(1.0 / np.sum(w * w))


def _check_sampler(post, ref, ess_is, names):
    """emcee against the importance-sampling reference: medians within 4 combined Monte
    Carlo SEs (1.25 SD / sqrt(ESS) each), SDs within 4 x sqrt(1/(2 ESS_mcmc) + 1/(2 ESS_is))."""
    for name in names:
        s = post.samples[name]
        med, sd = ref[name]
        ess = post.ess[name]
        se_med = 1.25 * sd * math.sqrt(1.0 / ess + 1.0 / ess_is)
        se_sd = math.sqrt(0.5 / ess + 0.5 / ess_is)
        assert ess > 300 and ess_is > 2000, (name, ess, ess_is)
        assert abs(np.median(s) - med) < 4 * se_med, (name, (np.median(s) - med) / se_med)
        assert np.std(s) / sd == pytest.approx(1.0, abs=4 * se_sd), (name, np.std(s) / sd)


def _check_against_ml(post, names, med_tol, sd_tol):
    for name in names:
        i = post.param_names.index(name)
        s = post.samples[name]
        ml, se = post.ml.values[i], post.ml.errors[i]
        assert abs(np.median(s) - ml) < med_tol * se, (name, (np.median(s) - ml) / se)
        assert np.std(s) == pytest.approx(se, rel=sd_tol), (name, np.std(s) / se)


def test_exact_likelihood_posterior():
    """likelihood='exact' end to end on a short record (4096 frames, eps = 4 nm), prior
    flat in p (posterior = likelihood): emcee reproduces the independent importance-sampling
    posterior; median and SD agree with the exact ML estimate and its observed-Fisher SE to
    0.25 SE and 12 % (at 4096 frames the likelihood is still skewed: gamma's relative SE is
    7 %, which puts its median ~0.15 SE above the maximum)."""
    y = _sim(2e-5, 4096, 3, eps=4e-9)[0]
    rec = blurtrap.Recording(y, frame_interval=DT, exposure=DT)
    names = ("k", "gamma", "tracking_var")
    su, post = _setup_and_sample(rec, 600, 1, likelihood="exact", priors=_flat_in_p(names))
    assert post.likelihood == "exact" and post.evaluation == "exact"
    ml = blurtrap.calibrate(rec, method="likelihood", likelihood="exact")
    assert np.allclose(post.ml.values, ml.values, rtol=1e-10)
    ref, ess_is = _importance_reference(su)
    _check_sampler(post, ref, ess_is, names)
    _check_against_ml(post, names, med_tol=0.25, sd_tol=0.12)


def test_joint_linear_power_posterior():
    """Joint RecordingSet, k = c P across three powers with shared gamma and eps^2 (closed-
    form Whittle evaluation): emcee against the importance-sampling reference, and against
    the joint ML fit and its Fisher SE (0.15 SE, 12 %)."""
    c_true = 2e-4  # N/m/W: k = 0.01, 0.02, 0.03 pN/nm
    powers = (0.05, 0.1, 0.15)
    recs = [blurtrap.Recording(_sim(c_true * pw, 16384, 60 + i)[0], frame_interval=DT,
                               exposure=DT, laser_power=pw) for i, pw in enumerate(powers)]
    data = blurtrap.RecordingSet(recs)
    names = ("c", "gamma", "tracking_var")
    su, post = _setup_and_sample(data, 600, 2, k="linear_power", priors=_flat_in_p(names))
    assert post.param_names == names and post.k_mode == "linear_power"
    assert post.evaluation == "whittle_closed_form"
    ref, ess_is = _importance_reference(su)
    _check_sampler(post, ref, ess_is, names)
    _check_against_ml(post, names, med_tol=0.15, sd_tol=0.12)
    for pw in powers:
        assert np.allclose(post.samples[f"k[P={pw * 1e3:g} mW]"], post.samples["c"] * pw)


def test_posterior_with_drift_effect():
    """'standard+drift' (an additive effect: the generic per-ordinate Whittle evaluation) on
    a record with a random-walk drift of 20 nm^2/s (~45 nm of wander over the 11 s record):
    emcee against the importance-sampling reference for all four parameters; the drift
    coefficient's 95 % interval covers the truth and the ML fit of the same model."""
    from blurtrap.simulate import RandomWalkDrift

    d_drift = 2e-17  # m^2/s
    x = blurtrap.simulate(2e-5, GAMMA, DT, DT, 16384, key=jax.random.key(77),
                          method="exact_frames", tracking_std=EPS,
                          injections=(RandomWalkDrift(d_drift),))
    rec = blurtrap.Recording(np.asarray(x, dtype=float).reshape(-1), frame_interval=DT,
                             exposure=DT)
    names = ("k", "gamma", "tracking_var", "drift_diffusion")
    su, post = _setup_and_sample(rec, 700, 4, model="standard+drift")
    assert post.param_names == names and post.model == "standard+drift"
    assert post.ml.model == "standard+drift" and post.evaluation == "whittle_ordinates"
    ref, ess_is = _importance_reference(su)
    _check_sampler(post, ref, ess_is, names)
    lo, hi = post.interval("drift_diffusion", 0.95)
    assert lo < d_drift < hi
    assert lo < post.ml.values[3] < hi
    assert "nm^2/s" in post.summary()


def test_derived_k_with_power_offset():
    """k[P] = c (P - P0) in the samples when the model has power_offset."""
    recs = [blurtrap.Recording(np.arange(8.0) * 1e-9, frame_interval=DT, exposure=DT,
                               laser_power=pw)
            for pw in (0.05, 0.1)]
    lay = make_layout(recs, "linear_power", True, ("power_offset",))
    chain = np.array([[[2e-4, GAMMA, 4e-18, 0.01]], [[3e-4, GAMMA, 4e-18, 0.02]]])
    s = res_mod._derived(lay, chain, 295.0)
    assert np.allclose(s["k[P=50 mW]"], [2e-4 * 0.04, 3e-4 * 0.03], rtol=1e-14)
    assert np.allclose(s["k[P=100 mW]"], [2e-4 * 0.09, 3e-4 * 0.08], rtol=1e-14)
    assert np.allclose(s["power_offset"], [0.01, 0.02])


# ------------------------------------------------------------------------------------------
# export
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_post():
    rec = blurtrap.Recording(_sim(2e-5, 4096, 9)[0], frame_interval=DT, exposure=DT)
    return _quiet_sample(rec, n_walkers=8, n_steps=60, seed=0)


def test_draws_layout(small_post):
    p = small_post
    n_kept = p.n_steps - p.burn_in
    for name in p.samples:
        d = p.draws(name)
        assert d.shape == (p.n_walkers, n_kept)
    for i, name in enumerate(p.param_names):
        assert np.array_equal(p.draws(name), p.chain[:, :, i].T)


def test_to_arviz(small_post):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        az = pytest.importorskip("arviz")
    idata = small_post.to_arviz()
    post = idata.posterior if hasattr(idata, "posterior") else idata["posterior"]
    n_kept = small_post.n_steps - small_post.burn_in
    assert set(small_post.samples) <= set(post.data_vars)
    for name in small_post.samples:
        arr = post[name]
        assert tuple(arr.dims) == ("chain", "draw")
        assert arr.shape == (small_post.n_walkers, n_kept)
        assert np.array_equal(arr.values, small_post.draws(name))
    for i, name in enumerate(small_post.param_names):  # chain c = walker c, in step order
        assert np.array_equal(post[name].values, small_post.chain[:, :, i].T)
    stats = idata.sample_stats if hasattr(idata, "sample_stats") else idata["sample_stats"]
    assert np.array_equal(stats["lp"].values, small_post.log_prob.T)
    assert float(post["k"].mean()) == pytest.approx(float(np.mean(small_post.samples["k"])),
                                                    rel=1e-12)
    assert az.__version__
