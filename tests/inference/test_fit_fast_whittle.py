"""The fast Whittle fit: real-arithmetic expected periodogram, one-pass value/gradient/Hessian,
coarse start, Newton stopping rule, host chi^2 survival function, batch fallback.

Independent references: the complex closed form of the expected periodogram (numpy) and its
mpmath evaluation at 60 digits, JAX autodiff of ``spectral_nll`` (value, gradient, Hessian),
numpy group means, scipy's ``gammaincc``, and single-recording ``calibrate`` fits.
"""

import math

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from scipy import special

import blurtrap as bt
from blurtrap.effects import injections
from blurtrap.inference import _batch, _fit, _spectral, _starts
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import (
    _binned_args,
    make_layout,
    spectral_newton_pass,
    spectral_newton_plan,
    spectral_nll,
)
from blurtrap.physics._spectra import _expected_block_periodogram

DT = 1 / 1500
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
KT = 1.380649e-23 * 295.0


# ------------------------------------------------------------------------------------------
# expected periodogram in real arithmetic
# ------------------------------------------------------------------------------------------
def _complex_closed_form(j, m, sigma2, tau, w, dt, eps2):
    """The complex closed form of E[I_j] (the implementation before the real form), numpy."""
    a, r = w / tau, dt / tau
    if a < 1.0:  # series (the closed forms cancel for small a)
        s = sum(2.0 * (-a) ** n / math.factorial(n + 2) for n in range(30))
        phi1 = sum((-a) ** n / math.factorial(n + 1) for n in range(30))
    else:
        s, phi1 = 2 / a - 2 * (-math.expm1(-a)) / a**2, -math.expm1(-a) / a
    c0, c1 = sigma2 * s + eps2, sigma2 * phi1**2 * math.exp(a - r)
    rho = math.exp(-r)
    e = np.exp(-2j * np.pi * j / m)
    q = rho * e
    rm1 = math.exp(-r * (m - 1))
    s1 = (e - rm1) / (1 - q)
    s2 = (e - m * rm1 + (m - 1) * rm1 * q) / (1 - q) ** 2
    return dt * (c0 + 2 * c1 * np.real(s1 - s2 / m))


def _mp_closed_form(j, m, sigma2, tau, w, dt, eps2):
    with mp.workdps(60):
        sigma2, tau, w, dt, eps2 = map(mp.mpf, (sigma2, tau, w, dt, eps2))
        a, r = w / tau, dt / tau
        s = 2 / a - 2 * (1 - mp.e ** (-a)) / a**2 if a > 0 else mp.mpf(1)
        phi1 = (1 - mp.e ** (-a)) / a if a > 0 else mp.mpf(1)
        c0, c1 = sigma2 * s + eps2, sigma2 * phi1**2 * mp.e ** (a - r)
        rho = mp.e ** (-r)
        e = mp.e ** (-2j * mp.pi * j / m)
        q, rm1 = rho * e, rho ** (m - 1)
        tot = (e - rm1) / (1 - q) - (e - m * rm1 + (m - 1) * rm1 * q) / (1 - q) ** 2 / m
        return float(dt * (c0 + 2 * c1 * mp.re(tot)))


@pytest.mark.parametrize("m", [8, 64, 1000, 65536])
@pytest.mark.parametrize("wfrac", [0.0, 0.25, 1.0])
def test_real_expected_periodogram_equals_complex_form(m, wfrac):
    """Realistic regime (record longer than 3 tau): agreement with the complex closed form to
    2e-12 relative (the complex form itself carries up to ~1e-12 rounding there)."""
    j = np.arange(1, m // 2 + 1)
    f = j / (m * DT)
    worst = 0.0
    for r in (3.0 / m, 0.01, 0.3, 1.0, 5.0, 40.0, 800.0):
        if r * m < 3:
            continue
        tau, w = DT / r, wfrac * DT
        got = np.asarray(_expected_block_periodogram(jnp.asarray(f), float(m), 1e-16, tau, w, DT,
                                                     4e-18))
        ref = _complex_closed_form(j, m, 1e-16, tau, w, DT, 4e-18)
        worst = max(worst, float(np.max(np.abs(got / ref - 1))))
    assert worst < 2e-12


@pytest.mark.parametrize("m,r", [(64, 1e-6), (4096, 1e-6), (4096, 1e-4), (65536, 1e-4),
                                 (65536, 1.0), (64, 30.0), (1000, 700.0)])
def test_real_expected_periodogram_equals_mpmath(m, r):
    """Against 60-digit arithmetic, including free diffusion (tau >> M dt), where the real
    form keeps ~1e-14 and the complex form lost up to 1e-10."""
    js = sorted({1, 2, 3, 10, m // 8, m // 4, m // 2})
    for wfrac in (0.0, 1.0):
        tau = DT / r
        got = np.asarray(_expected_block_periodogram(
            jnp.asarray(np.array(js) / (m * DT)), float(m), 1e-16, tau, wfrac * DT, DT, 4e-18))
        ref = np.array([_mp_closed_form(jj, m, 1e-16, tau, wfrac * DT, DT, 4e-18) for jj in js])
        np.testing.assert_allclose(got, ref, rtol=2e-13)


def test_expected_periodogram_precomputed_s2_is_the_same():
    m = 4096
    f = jnp.asarray(np.arange(1, m // 2 + 1) / (m * DT))
    s2 = jnp.sin(jnp.pi * f * DT) ** 2
    a = _expected_block_periodogram(f, float(m), 2e-16, 3e-3, DT, DT, 1e-18)
    b = _expected_block_periodogram(jnp.zeros_like(f), float(m), 2e-16, 3e-3, DT, DT, 1e-18,
                                    s2=s2)
    np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-15)


# ------------------------------------------------------------------------------------------
# one-pass value, gradient and Hessian against autodiff
# ------------------------------------------------------------------------------------------
def _recordings(seed, specs, injections=()):
    out = []
    for i, (k, n, w, power, temp) in enumerate(specs):
        x = bt.simulate(k, GAMMA, w, DT, n, key=jax.random.key(seed + i), method="exact_frames",
                        tracking_std=2e-9, temperature=temp, injections=injections)
        out.append(bt.Recording(np.asarray(x).reshape(-1), frame_interval=DT, exposure=w,
                                laser_power=power, temperature=temp))
    return out


#: joint fits exercise padding (different lengths), per-recording exposures/temperatures, two
#: k layouts, blur and noise on and off, a blocked fit and f_range (zero weights in the rows);
#: the last case is a single recording with blur but no tracking noise
CASES = {
    "standard per_power, 3 lengths": (
        None, "per_power", 1, None,
        [(3e-5, 8192, DT, 0.1, 295.0), (5e-5, 6000, DT / 2, 0.2, 300.0),
         (8e-5, 4100, DT / 4, 0.3, 295.0)]),
    "naive_aliased linear_power, blocked, f_range": (
        "naive_aliased", "linear_power", 4, (20.0, 600.0),
        [(3e-5, 8192, DT, 0.1, 295.0), (6e-5, 8192, DT, 0.2, 295.0)]),
    "blur (no noise), one recording": (
        "blur", "shared", 1, None, [(5e-5, 8192, DT / 2, None, 300.0)]),
    # additive effects ride on the fused pass (their spectrum and its derivatives added)
    "standard+drift+line per_recording, 2 lengths": (
        get_model("standard").add("drift").add("line_noise", frequency=123.4, width=0.2),
        "per_recording", 1, None,
        [(3e-5, 8192, DT, 0.1, 295.0), (5e-5, 6000, DT / 2, 0.2, 300.0)]),
    "blur+drift, blocked, f_range": (
        "blur+drift", "shared", 4, (5.0, 700.0), [(5e-5, 8192, DT, None, 295.0)]),
}


@pytest.fixture(scope="module", params=list(CASES))
def problem(request):
    model, k_mode, n_blocks, f_range, specs = CASES[request.param]
    mdl = get_model(model)
    # the effects present in the data, so that their parameters' optimum is interior
    inject = [injections.RandomWalkDrift(2e-16)] if mdl.has("drift") else []
    if mdl.has("line_noise"):
        inject.append(injections.SinusoidDrift(10e-9, 1 / 123.4))
    recs = _recordings(7, specs, inject)
    layout = make_layout(recs, k_mode, mdl.noise, tuple(p.name for p in mdl.extra_params))
    args = _spectral._spectral_args(recs, layout, mdl, n_blocks, f_range)
    scale = _starts._start_vector(recs, layout, mdl.noise)
    return args, scale


def _autodiff(x, scale, args):
    f = lambda xx: spectral_nll(scale * jnp.exp(xx), args)  # noqa: E731
    return f(x), jax.grad(f)(x), jax.hessian(f)(x)


_autodiff_jit = jax.jit(_autodiff)


def test_newton_pass_equals_autodiff(problem):
    args, scale = problem
    assert args.block_len is not None and spectral_newton_plan(args) is not None
    fast = jax.jit(spectral_newton_pass)
    rng = np.random.default_rng(3)
    for spread in (0.2, 1.0):  # near the start values and up to ~e^2 away from them
        x = jnp.asarray(rng.normal(0.0, spread, scale.shape))
        v, g, h = fast(x, scale, args)
        v0, g0, h0 = _autodiff_jit(x, scale, args)
        assert abs(float(v / v0) - 1) < 1e-11
        np.testing.assert_allclose(np.asarray(g), np.asarray(g0), rtol=1e-9,
                                   atol=1e-11 * float(jnp.max(jnp.abs(g0))))
        np.testing.assert_allclose(np.asarray(h), np.asarray(h0), rtol=1e-9,
                                   atol=1e-11 * float(jnp.max(jnp.abs(h0))))


def test_fit_returns_the_optimum_and_its_observed_information(problem):
    """At the returned parameters the autodiff gradient vanishes (to what a 1e-9 step in log
    parameters leaves), and the covariance is the inverse autodiff Hessian in natural
    parameters (evaluated within ~1e-6 of the estimate: equal to ~1e-5)."""
    args, scale = problem
    out = _fit.fit_ml(spectral_nll, scale, args)
    assert bool(out.success)
    x = jnp.log(out.value / scale)
    v0, g0, h0 = _autodiff_jit(x, scale, args)
    step = np.linalg.solve(np.asarray(h0), np.asarray(g0))
    assert np.max(np.abs(step)) < 1e-8
    assert abs(float(out.nll) - float(v0)) < 1e-9 * abs(float(v0))
    u = np.exp(np.asarray(x))
    hess_u = (np.asarray(h0) - np.diag(np.asarray(g0))) / np.outer(u, u)
    cov = np.linalg.inv(hess_u) * np.outer(np.asarray(scale), np.asarray(scale))
    np.testing.assert_allclose(np.asarray(out.cov), cov, rtol=1e-4)


def test_binned_args_are_weighted_group_means(problem):
    args, _ = problem
    width = 4
    b = _binned_args(args, width)
    n = (args.power.shape[-1] // width) * width
    wt = np.asarray(args.weight)[:, :n].reshape(args.weight.shape[0], -1, width)
    for name in ("s2", "power", "f"):
        z = np.asarray(getattr(args, name))[:, :n].reshape(wt.shape)
        ws = wt.sum(-1)
        want = np.where(ws > 0, (wt * z).sum(-1) / np.where(ws > 0, ws, 1), z.mean(-1))
        np.testing.assert_allclose(np.asarray(getattr(b, name)), want, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(b.weight), wt.sum(-1), rtol=0)


def test_plan_only_for_the_closed_form_expected_periodogram():
    recs = _recordings(11, [(5e-5, 16384, DT, None, 295.0)])
    for model, n_blocks, want_plan, want_width in (
            (None, 1, True, 4),  # 8192 ordinates -> groups of 4
            (None, 128, True, None),  # 64 ordinates per block: no coarse stage
            ("standard+drift", 1, True, None),  # additive effects: fused, no coarse stage
            ("standard+hydrodynamics", 1, False, None),  # folded: autodiff Newton
            ("naive", 1, False, None)):  # no expected periodogram
        mdl = get_model(model)
        layout = make_layout(recs, "shared", mdl.noise, tuple(p.name for p in mdl.extra_params))
        args = _spectral._spectral_args(recs, layout, mdl, n_blocks, None)
        plan = spectral_newton_plan(args)
        assert (plan is not None) == want_plan, model
        if plan is not None:
            coarse = plan[1]
            got = None if coarse is None else args.power.shape[-1] // coarse.power.shape[-1]
            assert got == want_width


# ------------------------------------------------------------------------------------------
# Newton stopping rule
# ------------------------------------------------------------------------------------------
C = jnp.array([0.5, 2.0, 1.3])


def _convex_pass(factor):
    """f(x) = sum(exp(x) - c x) (optimum x = log c) with its Hessian multiplied by
    ``factor``: factor 1 is Newton (quadratic convergence), factor 3 converges only linearly
    (rate 2/3), the case a rule based on the step size alone accepts far from the optimum."""

    def pass_fn(x, scale, args):
        e = jnp.exp(x)
        return jnp.sum(e - C * x), e - C, factor * jnp.diag(e)

    return pass_fn


@pytest.mark.parametrize("factor", [1.0, 3.0])
def test_newton_stopping_rule_bounds_the_error(factor):
    tol = 1e-9
    x, _, _, _, dx, k, done, _ = jax.jit(
        lambda x0: _fit._newton_iterate(_convex_pass(factor), None, None, x0, tol, tol, 200)
    )(jnp.full(3, 0.3))
    assert bool(done)
    err = np.max(np.abs(np.asarray(x - dx) - np.log(np.asarray(C))))
    assert err < 3 * tol * (1 + np.max(np.abs(np.log(np.asarray(C)))))
    if factor == 1.0:
        assert int(k) <= 6  # quadratic
    else:
        assert int(k) > 30  # ran until the linear iteration had really converged


def _boundary_pass(x, scale, args):
    """f(x) = sum_{i<3}(exp(x_i) - c_i x_i) + exp(x_3): the last parameter's optimum is on its
    boundary (u = exp(x_3) -> 0), where its log-space curvature exp(x_3) vanishes."""
    e = jnp.exp(x)
    g = jnp.concatenate([e[:3] - C, e[3:]])
    return jnp.sum(e[:3] - C * x[:3]) + e[3], g, jnp.diag(e)


def test_newton_converges_at_a_boundary_optimum():
    # before: the boundary coordinate stepped on for ever with a merely semi-definite Hessian,
    # the iteration never reported convergence and the BFGS fallback took over
    tol = 1e-9
    x, _, _, _, dx, k, done, _ = jax.jit(
        lambda x0: _fit._newton_iterate(_boundary_pass, None, None, x0, tol, tol, 200)
    )(jnp.full(4, 0.3))
    assert bool(done) and int(k) < 200
    x_hat = np.asarray(x - dx)
    assert np.max(np.abs(x_hat[:3] - np.log(np.asarray(C)))) < 1e-8
    # stopped only once the boundary term, the objective's excess over its infimum, no
    # longer matters (Newton decrement below 1e-13 (1 + |f|))
    assert math.exp(x_hat[3]) < 1e-10


def test_covariance_holds_a_boundary_parameter_at_its_bound():
    """The bound parameter gets a NaN variance; the others the inverse of their own block of
    the information: here f = u_i - c_i log u_i (i < 3), so var(u_i) = c_i exactly, and no
    correlation with the bound one. (Before: d2f/du2 of the bound parameter is (H - g)/u^2 =
    0/u^2, the information was singular and every error NaN.)"""
    tol = 1e-9
    x, v, g, h, dx, k, done, _ = _fit._newton_iterate(_boundary_pass, None, None,
                                                      jnp.full(4, 0.3), tol, tol, 200)
    out = _fit._finish_from(x, v, g, h, jnp.ones(4), done, k, x_value=x - dx)
    assert bool(out.hessian_pd) and bool(out.success)
    cov = np.asarray(out.cov)
    np.testing.assert_allclose(np.diag(cov)[:3], np.asarray(C), rtol=1e-6)
    assert np.isnan(cov[3, 3])
    off = cov[~np.eye(4, dtype=bool)]
    assert np.all(np.abs(off) < 1e-9)


def test_standard_fit_of_a_hydrodynamic_record_finds_the_trap():
    """Regression (benchmarks/study_diagnose.py, hydrodynamics seed 3504): a 200 kHz record of a
    1.5 um bead with frequency-dependent friction, fitted with the standard model: eps^2 runs to
    its boundary; the Newton fit never declared convergence, the BFGS fallback ran k to 6e-11
    N/m (a worse likelihood) and calibrate raised a FitError. The misspecified fit must find
    the trap's own optimum (k within 20 % of the truth, the hydrodynamic bias being ~16 %)."""
    from blurtrap.physics._effects import water_viscosity
    from blurtrap.simulate import HydrodynamicFriction

    radius, k = 1.5e-6, 5e-5
    gamma = 6 * math.pi * float(water_viscosity(295.0)) * radius
    x = np.asarray(bt.simulate(k, gamma, 1e-8, 5e-6, 2**16, key=jax.random.key(3504),
                               method="spectral", tracking_std=0.2e-9,
                               injections=(HydrodynamicFriction(radius),)))[0]
    rec = bt.Recording(x, frame_interval=5e-6, exposure=1e-8)
    fit = bt.calibrate(rec, method="likelihood", likelihood="whittle")
    assert abs(fit.k / k - 1) < 0.2, fit.summary()
    assert "tracking_var" in fit.at_bounds
    assert np.isfinite(fit.k_err) and np.isfinite(fit.gamma_err)  # eps^2 counted as free


# ------------------------------------------------------------------------------------------
# chi^2 survival function on the host
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("dof", [1, 2, 3, 7, 100, 497, 5000, 32768])
def test_chi2_sf_equals_scipy(dof):
    for q in (1e-6, 0.01, 0.5, 0.9, 1.0, 1.02, 1.5, 3.0, 10.0):
        for x in (dof * q, dof * q + 0.5, max(dof * q - 2 * math.sqrt(dof), 1e-3)):
            want = special.gammaincc(dof / 2, x / 2)
            if want > 1e-250:
                assert abs(_fit.chi2_sf(x, dof) / want - 1) < 1e-10, (dof, x)
    assert _fit.chi2_sf(0.0, dof) == 1.0 and _fit.chi2_sf(math.inf, dof) == 0.0


@pytest.mark.parametrize("d1,d2", [(1, 1), (15, 71.7), (15, 35.8), (3, 1000), (40, 2.5)])
def test_f_sf_equals_scipy(d1, d2):
    from blurtrap.inference._chi2 import f_sf

    for x in (1e-4, 0.1, 0.5, 1.0, 1.7, 3.0, 10.0, 100.0, 1e4):
        want = special.fdtrc(d1, d2, x)
        if want > 1e-250:
            assert abs(f_sf(x, d1, d2) / want - 1) < 1e-9, (d1, d2, x, want)
    assert f_sf(0.0, d1, d2) == 1.0 and f_sf(math.inf, d1, d2) == 0.0


# ------------------------------------------------------------------------------------------
# batch: items that the vmapped steps do not finish are refitted alone
# ------------------------------------------------------------------------------------------
def test_batch_items_beyond_the_vmapped_steps_equal_calibrate(monkeypatch):
    n = 9000  # a shape no other test uses, so the patched step limit is traced
    x = np.asarray(bt.simulate(5e-5, GAMMA, DT, DT, n, key=jax.random.key(5),
                               method="exact_frames", tracking_std=2e-9, n_traces=2))
    x = x.reshape(2, n)
    monkeypatch.setattr(_batch, "_BATCH_NEWTON_STEPS", 0)  # nobody finishes in the batch
    res = bt.calibrate_batch(x, frame_interval=DT, exposure=DT)
    assert list(res.status) == ["ok", "ok"]
    assert np.all(res.n_steps >= 1)  # steps of the single fits, not of the batch
    for i in range(2):
        one = bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=DT),
                           likelihood="whittle")
        assert abs(res.k[i] / one.k - 1) < 1e-8 and abs(res.gamma[i] / one.gamma - 1) < 1e-8
        assert abs(res.k_err[i] / one.k_err - 1) < 1e-5


def test_batch_in_chunks_equals_calibrate(monkeypatch):
    """Batches larger than a chunk are fitted chunk by chunk (the last one padded to the
    chunk shape); a constant row keeps its own status and NaN values."""
    n = 9000  # same shapes as the test above: no extra compilation in the same worker
    x = np.asarray(bt.simulate(5e-5, GAMMA, DT, DT, n, key=jax.random.key(6),
                               method="exact_frames", tracking_std=2e-9, n_traces=4))
    x = x.reshape(4, n)
    x = np.concatenate([x[:2], np.full((1, n), 1e-7), x[2:]])
    monkeypatch.setattr(_batch, "_CHUNK", 2)  # chunks [0, 2), [2, 4), [4] + 1 padding row
    res = bt.calibrate_batch(x, frame_interval=DT, exposure=DT)
    assert list(res.status) == ["ok", "ok", "constant trace", "ok", "ok"]
    assert np.isnan(res.k[2]) and np.isnan(res.k_err[2]) and not res.success[2]
    for i in (0, 3, 4):  # first chunk, the one with the constant row, the padded last one
        one = bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=DT),
                           likelihood="whittle")
        assert abs(res.k[i] / one.k - 1) < 1e-8 and abs(res.gamma[i] / one.gamma - 1) < 1e-8
        assert abs(res.k_err[i] / one.k_err - 1) < 1e-5
