"""Property-based tests (hypothesis) of the physics functions: bounds, monotonicity, limits,
smoothness across the series cut-off, broadcasting, inversion round trips, spectral identities
and the errors for bad input.

References are independent of the code under test: mpmath at 50-80 digits for S(alpha) and
its derivative, the Pade rational function written out here, closed-form lag sums for the
discrete Parseval identity, numpy formulas for the Lorentzian. Tolerances are derived from
floating-point error analysis (stated next to each) rather than fitted to the results.
Examples are derandomized, so every run checks the same inputs (and the counts in
``README.md`` are reproducible).
"""

import inspect
import math
import re

import equinox as eqx
import jax
import mpmath as mp
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import blurtrap as bt

EPS = float(np.finfo(np.float64).eps)
KB = bt.BOLTZMANN
CUT = 0.1  # the float64 series cut-off of S (blurtrap/physics/_blur.py)

PROPERTY = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
FEW = settings(PROPERTY, max_examples=6)  # each new array shape compiles once


def logu(lo, hi):
    """Log-uniform floats in [lo, hi]."""
    return st.floats(math.log(lo), math.log(hi)).map(math.exp)


ALPHA = st.one_of(st.just(0.0), logu(1e-14, 1e-3), st.floats(1e-3, 10.0), logu(10.0, 1e12))
K = logu(1e-7, 1e-3)  # N/m
GAMMA = logu(1e-9, 1e-7)  # N s/m
TEMP = st.floats(250.0, 350.0)


# ---- independent references -------------------------------------------------------------
def s_mp(a):
    """S(alpha) at 50 digits (series below 1e-6, where the literal formula cancels)."""
    with mp.workdps(50):
        a = mp.mpf(a)
        if a < mp.mpf("1e-6"):
            return float(sum(2 * (-a) ** n / mp.factorial(n + 2) for n in range(12)))
        return float(2 / a - 2 * (1 - mp.exp(-a)) / a**2)


def ds_mp(a):
    """dS/dalpha: the differentiated series below 1, the analytic derivative above."""
    with mp.workdps(60):
        a = mp.mpf(a)
        if a < 1:
            return float(sum(2 * n * (-1) ** n * a ** (n - 1) / mp.factorial(n + 2) for n in range(1, 40)))
        return float(-2 / a**2 + 4 * (1 - mp.exp(-a)) / a**3 - 2 * mp.exp(-a) / a**2)


def s_err(a):
    """Relative error bound of blur_factor: a few ulp on the series branch; on the closed
    form (2/a)(1 + expm1(-a)/a) the rounding of expm1(-a)/a (a couple of ulp of a number
    near 1) is amplified by 1/(1 - (1 - e^-a)/a), the cancellation in ``1 + expm1(-a)/a``."""
    if a < CUT:
        return 4 * EPS
    with mp.workdps(30):
        one_minus_phi1 = float(1 - (1 - mp.exp(-mp.mpf(a))) / a)
    return 4 * EPS / one_minus_phi1


_dS = jax.jit(jax.grad(bt.blur_factor))
_S_jit = jax.jit(bt.blur_factor)
_var_jit = jax.jit(bt.measured_variance)
_psd_d = jax.jit(lambda f, k, g, w, t, dt, e: bt.psd_measured(f, k, g, w, t, frame_interval=dt,
                                                              tracking_var=e))


# ---- S(alpha) -----------------------------------------------------------------------------
@PROPERTY
@given(ALPHA)
@example(0.0)
@example(CUT)
@example(float(np.nextafter(CUT, 0)))
@example(float(np.nextafter(CUT, 1)))
@example(1e300)
def test_blur_factor_bounds_and_accuracy(alpha):
    s = float(bt.blur_factor(alpha))
    assert 0.0 < s <= 1.0
    if alpha == 0.0:
        assert s == 1.0
    ref = s_mp(alpha)
    assert abs(s / ref - 1) <= s_err(alpha), (alpha, s, ref)


@PROPERTY
@given(ALPHA, ALPHA)
def test_blur_factor_is_decreasing(a, b):
    a, b = min(a, b), max(a, b)
    sa, sb = float(bt.blur_factor(a)), float(bt.blur_factor(b))
    tol = s_err(a) + s_err(b)
    # never increases by more than the rounding of the two values
    assert sb <= sa * (1 + tol), (a, b, sa, sb)
    # and decreases strictly wherever the exact decrease is resolvable at that accuracy
    if s_mp(a) - s_mp(b) > 2 * tol * s_mp(a):
        assert sb < sa


@PROPERTY
@given(logu(50.0, 1e15))
def test_blur_factor_large_alpha_limit(a):
    """alpha S(alpha) = 2 - 2/alpha + 2 e^-alpha / alpha exactly, so S -> 2/alpha."""
    got = a * float(bt.blur_factor(a))
    ref = 2.0 - 2.0 / a
    assert abs(got - ref) <= 2.0 * math.exp(-a) / a + 8 * EPS * 2.0


@PROPERTY
@given(logu(1e-15, 1e-3))
def test_blur_factor_smooth_across_series_cut(delta):
    """S and dS/dalpha are continuous across the switch from the series to the closed form:
    the two-sided differences match the exact ones to within the value errors."""
    lo, hi = CUT - delta, CUT + delta
    s_lo, s_hi = float(bt.blur_factor(lo)), float(bt.blur_factor(hi))
    exact = s_mp(hi) - s_mp(lo)
    assert abs((s_hi - s_lo) - exact) <= (s_err(lo) + s_err(hi)) * s_mp(lo)
    g_lo, g_hi = (float(_dS(x)) for x in (lo, hi))
    # derivative accuracy 1e-11 relative (as tests/physics/test_blur.py); |S''| <= 1/6
    assert abs(g_lo / ds_mp(lo) - 1) < 1e-11 and abs(g_hi / ds_mp(hi) - 1) < 1e-11
    assert abs(g_hi - g_lo) <= 2 * delta / 6 + 2e-11 * abs(ds_mp(CUT))


@FEW
@given(hnp.array_shapes(min_dims=0, max_dims=3, max_side=4), st.integers(0, 2**32 - 1))
def test_blur_factor_broadcasts_elementwise(shape, seed):
    a = np.exp(np.random.default_rng(seed).uniform(-20, 10, shape))
    got = np.asarray(_S_jit(a))  # jit: one compilation per shape (the semantics are eager's)
    assert got.shape == np.shape(a)
    ref = np.array([float(_S_jit(float(x))) for x in np.ravel(a)]).reshape(np.shape(a))
    np.testing.assert_array_max_ulp(got, ref, maxulp=4)


# ---- Pade and inversions --------------------------------------------------------------------
@PROPERTY
@given(st.floats(0.0, 3.0))
def test_pade_is_the_stated_rational_function_and_within_3_percent(a):
    got = float(bt.blur_factor_pade(a))
    ref = (1 - 2 * a / 15 + a * a / 60) / (1 + a / 5)
    assert abs(got - ref) <= 4 * EPS * abs(ref)
    assert abs(got / s_mp(a) - 1) < 0.03


def _trap(draw):
    k, gamma, t = draw(K), draw(GAMMA), draw(TEMP)
    return k, gamma, t, KB * t / gamma


@st.composite
def inversion_case(draw, alpha):
    k, gamma, t, d = _trap(draw)
    a = draw(alpha)
    w = a * gamma / k
    sigma2 = KB * t / k
    eps2 = draw(st.one_of(st.just(0.0), st.floats(0.0, 3.0))) * sigma2
    return k, gamma, t, d, w, sigma2, eps2, a


@PROPERTY
@given(inversion_case(logu(1e-10, 1e4)))
def test_exact_inversion_round_trip(case):
    """k -> var(X_m) -> k, and var -> k -> var. The error of the var -> k step is amplified
    by var/(var - eps2) (subtracting the tracking noise); 1e-12 is the Newton tolerance
    (1e-13) with room for the rounding of S."""
    k, gamma, t, d, w, sigma2, eps2, a = case
    v = float(bt.measured_variance(k, gamma, w, t, eps2))
    amp = v / (v - eps2)
    k_back = float(bt.stiffness_from_variance(v, d, w, t, eps2))
    assert abs(k_back / k - 1) <= 1e-12 * amp, (case, k_back)
    v_back = float(bt.measured_variance(k_back, gamma, w, t, eps2))
    assert abs(v_back / v - 1) <= 1e-12 * amp


@PROPERTY
@given(inversion_case(st.floats(1e-8, 3.0)))
def test_pade_inversion_inverts_the_pade_forward_model(case):
    """Appendix D's closed form is the exact inverse of var = (kT/k) S_pade(alpha) + eps2
    (it solves that quadratic), so the round trip holds to rounding, not just to 3 %."""
    k, gamma, t, d, w, sigma2, eps2, a = case
    v = sigma2 * (1 - 2 * a / 15 + a * a / 60) / (1 + a / 5) + eps2
    k_back = float(bt.stiffness_from_variance(v, d, w, t, eps2, method="pade"))
    assert abs(k_back / k - 1) <= 1e-12 * v / (v - eps2), (case, k_back)


# ---- measured variance ------------------------------------------------------------------------
@st.composite
def variance_case(draw):
    k, gamma, t, _ = _trap(draw)
    eps2 = draw(st.one_of(st.just(0.0), st.floats(0.0, 1.0))) * KB * t / k
    w1, w2 = sorted([draw(logu(1e-9, 1.0)), draw(logu(1e-9, 1.0))])
    return k, gamma, t, eps2, w1, w2


def _var_err(k, gamma, w):
    # S's error plus ~4 roundings in (kB T / k) * S + eps2
    return s_err(w * k / gamma) + 4 * EPS


@PROPERTY
@given(variance_case())
def test_measured_variance_decreases_with_exposure_toward_kT_over_k(case):
    k, gamma, t, eps2, w1, w2 = case
    sigma2 = KB * t / k
    v1, v2 = (float(bt.measured_variance(k, gamma, w, t, eps2)) for w in (w1, w2))
    tol1, tol2 = _var_err(k, gamma, w1), _var_err(k, gamma, w2)
    assert v2 <= v1 * (1 + tol1 + tol2)  # longer exposure, never more variance
    assert v1 <= (sigma2 + eps2) * (1 + tol1)  # bounded by the unblurred variance
    assert v2 > eps2  # the blurred Brownian part stays positive
    # W -> 0: var = sigma2 (1 - alpha/3 + alpha^2/12 - ...) + eps2 (alternating series)
    a0 = 1e-9
    w0 = a0 * gamma / k
    v0 = float(bt.measured_variance(k, gamma, w0, t, eps2))
    assert abs(v0 - (sigma2 * (1 - a0 / 3) + eps2)) <= sigma2 * a0**2 / 12 + 8 * EPS * v0


@FEW
@given(hnp.mutually_broadcastable_shapes(num_shapes=3, max_dims=3, max_side=3), st.integers(0, 2**32 - 1))
def test_measured_variance_broadcasts(shapes, seed):
    rng = np.random.default_rng(seed)
    ks = np.exp(rng.uniform(np.log(1e-7), np.log(1e-3), shapes.input_shapes[0]))
    gs = np.exp(rng.uniform(np.log(1e-9), np.log(1e-7), shapes.input_shapes[1]))
    ws = np.exp(rng.uniform(np.log(1e-6), np.log(1e-2), shapes.input_shapes[2]))
    got = np.asarray(_var_jit(ks, gs, ws))
    assert got.shape == shapes.result_shape
    kb, gb, wb = np.broadcast_arrays(ks, gs, ws)
    ref = np.array([float(_var_jit(float(a), float(b), float(c)))
                    for a, b, c in zip(kb.ravel(), gb.ravel(), wb.ravel())]).reshape(shapes.result_shape)
    np.testing.assert_array_max_ulp(got, ref, maxulp=4)


# ---- spectra ------------------------------------------------------------------------------------
@st.composite
def spectrum_case(draw):
    k, gamma, t, _ = _trap(draw)
    tau = gamma / k
    dt = draw(logu(1e-3, 30.0)) * tau  # dt/tau from "rho -> 1" to "frames independent"
    w = draw(st.floats(1e-6, 1.0)) * dt
    eps2 = draw(st.one_of(st.just(0.0), logu(1e-6, 1.0))) * KB * t / k
    n = draw(st.sampled_from([64, 1024]))
    return k, gamma, t, dt, w, eps2, n


def lag_alias_reference(k, gamma, t, dt, w, eps2, n):
    """(1/(N dt)) sum_{j<N} P_d(j/(N dt)) = sum_m C(mN) = C(0) + 2 sum_{m>=1} C(mN), with
    C(n) = sigma2 phi1(a)^2 exp(a - n r) for n >= 1 (phi1 = (1-e^-a)/a, r = dt/tau)."""
    with mp.workdps(40):
        sigma2 = mp.mpf(KB) * t / k
        tau = mp.mpf(gamma) / k
        a, r = w / tau, dt / tau
        phi1 = (1 - mp.exp(-a)) / a
        c0 = sigma2 * (2 / a - 2 * (1 - mp.exp(-a)) / a**2) + eps2
        tail = sigma2 * phi1**2 * mp.exp(a) * mp.exp(-r * n) / (1 - mp.exp(-r * n))
        return float(c0), float(c0 + 2 * tail)


@settings(PROPERTY, max_examples=25)
@given(spectrum_case())
def test_discrete_psd_positive_symmetric_and_parseval(case):
    k, gamma, t, dt, w, eps2, n = case
    f = np.arange(n) / (n * dt)  # one full period [0, fs)
    p = np.asarray(_psd_d(f, k, gamma, w, t, dt, eps2))
    assert np.all(p > 0) and np.all(np.isfinite(p))
    pm = np.asarray(_psd_d(-f, k, gamma, w, t, dt, eps2))
    np.testing.assert_array_equal(pm, p)  # P(-f) = P(f) exactly (sin^2 is even)
    c0, dft_ref = lag_alias_reference(k, gamma, t, dt, w, eps2, n)
    # closed form accurate to ~1e-13 per ordinate; a sum of positive terms keeps that
    assert abs(np.sum(p) / (n * dt) / dft_ref - 1) < 1e-12, (case, np.sum(p) / (n * dt), dft_ref)
    assert dft_ref >= c0  # the lag-aliased sum exceeds the frame variance C(0)


@PROPERTY
@given(K, GAMMA, TEMP, logu(1e-3, 1e9))
def test_lorentzian_limits(k, gamma, t, f):
    """P(0) = 2 kT gamma / k^2; f^2 P(f) = D/(2 pi^2) / (1 + (fc/f)^2) -> D/(2 pi^2);
    even in f and never above P(0)."""
    p0 = float(bt.lorentzian(0.0, k, gamma, t))
    assert abs(p0 / (2 * KB * t * gamma / k**2) - 1) <= 8 * EPS
    p = float(bt.lorentzian(f, k, gamma, t))
    assert float(bt.lorentzian(-f, k, gamma, t)) == p
    assert p <= p0
    d, fc = KB * t / gamma, k / (2 * math.pi * gamma)
    assert abs(f * f * p / (d / (2 * math.pi**2) / (1 + (fc / f) ** 2)) - 1) <= 16 * EPS


@PROPERTY
@given(K, GAMMA, logu(1e-3, 1e7), logu(1e-12, 1e-1))
def test_continuous_blurred_psd_below_lorentzian_and_tends_to_it(k, gamma, f, w):
    lor = float(bt.lorentzian(f, k, gamma))
    p = float(bt.psd_measured(f, k, gamma, w))
    assert p <= lor * (1 + 8 * EPS)
    x = math.pi * f * w  # sinc^2 = 1 - x^2/3 + ...: relative deficit at most x^2/3
    assert lor - p <= lor * (x * x / 3 + 8 * EPS)


# ---- bad input: every function names the parameter, the value and the allowed range ---------
GOOD = dict(alpha=0.5, k=2e-5, gamma=1e-8, exposure=1e-4, temperature=295.0, tracking_var=1e-18,
            frame_interval=1e-3, f=100.0, measured_var=2e-16, diffusion=4e-13, lag=1,
            n_frames=1000.0, rise=2e-5, response_time=1e-5)
POS, NONNEG, FINITE = "> 0", ">= 0", "finite"
# function name -> (callable taking the keyword arguments, {parameter: kind})
TRAP = {"k": POS, "gamma": POS, "temperature": POS}
FUNCS = {
    "blur_factor": (lambda alpha: bt.blur_factor(alpha), {"alpha": NONNEG}),
    "blur_factor_pade": (lambda alpha: bt.blur_factor_pade(alpha), {"alpha": NONNEG}),
    "measured_variance": (
        lambda k, gamma, exposure, temperature, tracking_var: bt.measured_variance(
            k, gamma, exposure, temperature, tracking_var),
        {**TRAP, "exposure": POS, "tracking_var": NONNEG}),
    "stiffness_from_variance": (
        lambda measured_var, diffusion, exposure, temperature, tracking_var:
        bt.stiffness_from_variance(measured_var, diffusion, exposure, temperature, tracking_var),
        {"measured_var": POS, "diffusion": POS, "exposure": POS, "temperature": POS,
         "tracking_var": NONNEG}),
    "stiffness_from_variance(pade)": (
        lambda measured_var, diffusion, exposure, temperature, tracking_var:
        bt.stiffness_from_variance(measured_var, diffusion, exposure, temperature, tracking_var,
                                   method="pade"),
        {"measured_var": POS, "diffusion": POS, "exposure": POS, "temperature": POS,
         "tracking_var": NONNEG}),
    "lorentzian": (lambda f, k, gamma, temperature: bt.lorentzian(f, k, gamma, temperature),
                   {"f": FINITE, **TRAP}),
    "psd_measured": (
        lambda f, k, gamma, exposure, temperature, frame_interval, tracking_var: bt.psd_measured(
            f, k, gamma, exposure, temperature, frame_interval, tracking_var),
        {"f": FINITE, **TRAP, "exposure": POS, "frame_interval": POS, "tracking_var": NONNEG}),
    "frame_autocovariance": (
        lambda lag, k, gamma, exposure, frame_interval, temperature, tracking_var:
        bt.frame_autocovariance(lag, k, gamma, exposure, frame_interval, temperature, tracking_var),
        {**TRAP, "exposure": POS, "frame_interval": POS, "tracking_var": NONNEG}),
    "sample_variance_se": (
        lambda n_frames, k, gamma, exposure, frame_interval, temperature, tracking_var:
        bt.sample_variance_se(n_frames, k, gamma, exposure, frame_interval, temperature,
                              tracking_var),
        {"n_frames": POS, **TRAP, "exposure": POS, "frame_interval": POS,
         "tracking_var": NONNEG}),
    "transfer_rect": (lambda f, exposure: bt.transfer_rect(f, exposure),
                      {"f": FINITE, "exposure": POS}),
    "variance_general": (
        lambda k, gamma, temperature: bt.variance_general(bt.RectKernel(1e-4), k, gamma, temperature),
        dict(TRAP)),
    "psd_folded": (
        lambda f, k, gamma, frame_interval, temperature, tracking_var: bt.psd_folded(
            f, bt.RectKernel(1e-4), k, gamma, frame_interval, temperature, tracking_var, n_alias=3),
        {"f": FINITE, **TRAP, "frame_interval": POS, "tracking_var": NONNEG}),
    "RectKernel": (lambda exposure: bt.RectKernel(exposure), {"exposure": POS}),
    "TrapezoidKernel": (lambda exposure, rise: bt.TrapezoidKernel(exposure, rise),
                        {"exposure": POS, "rise": NONNEG}),
    "ExponentialKernel": (lambda response_time: bt.ExponentialKernel(response_time),
                          {"response_time": POS}),
}
CASES = [(fn, p) for fn, (_, params) in FUNCS.items() for p in params]
BAD = {POS: [-1.0, 0.0, -0.0, math.nan, math.inf, -math.inf, -1e-300],
       NONNEG: [-1.0, -1e-300, math.nan, math.inf, -math.inf],
       FINITE: [math.nan, math.inf, -math.inf]}


def _call(fn_name, **changes):
    fn, _ = FUNCS[fn_name]
    names = inspect.signature(fn).parameters
    kw = {n: GOOD[n] for n in names}
    kw.update(changes)
    return fn(**kw)


def _expected(param, kind, bad):
    shown = re.escape(f"{bad:.6g}")
    rng = "finite" if kind == FINITE else f"finite and {kind}"
    return rf"{re.escape(param)}( \([^)]*\))? must be {re.escape(rng)}.*got {re.escape(param)} = {shown}"


@settings(PROPERTY, max_examples=250)
@given(st.sampled_from(CASES), st.data())
def test_bad_values_raise_naming_parameter_and_value(bad_input, case, data):
    fn_name, param = case
    kind = FUNCS[fn_name][1][param]
    bad = data.draw(st.sampled_from(BAD[kind]), label="bad value")
    if data.draw(st.booleans(), label="inside an array"):
        n = data.draw(st.integers(1, 6), label="length")
        arr = np.full(n, GOOD[param])
        arr[data.draw(st.integers(0, n - 1), label="index")] = bad
        value = arr
    else:
        value = bad
    bad_input(f"physics: {fn_name}", lambda: _call(fn_name, **{param: value}),
              match=_expected(param, kind, bad), value=(param, value))


STRUCTURAL = [
    ("frame_autocovariance", dict(lag=0.5), r"lag \(frame lag\) must be an integer; got lag = 0.5"),
    ("frame_autocovariance", dict(lag=np.array([0.0, 1.0, 2.5])), r"lag .*must be an integer; got lag = 2.5"),
    ("frame_autocovariance", dict(lag=math.nan), r"lag .*must be an integer; got lag = nan"),
    ("frame_autocovariance", dict(lag=math.inf), r"lag .*must be an integer; got lag = inf"),
    ("frame_autocovariance", dict(lag="1"), r"lag must be an integer or array of integers"),
    ("measured_variance", dict(k="2e-5"), r"k must be a real number or array of numbers; got str"),
    ("measured_variance", dict(k=None), r"k must be a real number or array of numbers; got NoneType"),
    ("measured_variance", dict(exposure=1e-4 + 1e-5j), r"exposure must be real; got complex"),
    ("lorentzian", dict(f=[1.0, "a"]), r"f must be a real number or array of numbers"),
    ("psd_measured", dict(exposure=2e-3), r"exposure must be <= frame_interval; got exposure = 0.002 s"),
    ("frame_autocovariance", dict(exposure=2e-3), r"exposure must be <= frame_interval"),
    ("sample_variance_se", dict(exposure=2e-3), r"exposure must be <= frame_interval"),
    ("stiffness_from_variance", dict(tracking_var=3e-16), r"measured_var must exceed tracking_var"),
    ("stiffness_from_variance(pade)", dict(measured_var=1e-20, tracking_var=0.0),
     r"Pade closed form has no solution here"),
    ("TrapezoidKernel", dict(rise=6e-5), r"rise must be <= exposure/2"),
]


@pytest.mark.parametrize("fn_name, changes, match", STRUCTURAL,
                         ids=[f"{c[0]}-{sorted(c[1])[0]}-{i}" for i, c in enumerate(STRUCTURAL)])
def test_structural_bad_input(bad_input, fn_name, changes, match):
    exc = TypeError if re.search(r"real|integer or array", match) else ValueError
    bad_input(f"physics: {fn_name}", lambda: _call(fn_name, **changes), match=match, exc=exc,
              value=changes)


BAD_COUNTS = [-1, 0, 2.5, math.nan, math.inf, "3", True, None]
COUNTS = [
    ("psd_measured", lambda n: bt.psd_measured(1.0, 2e-5, 1e-8, 1e-4, frame_interval=1e-3, n_alias=n),
     r"n_alias must be a non-negative integer or None; got n_alias = ", [0, None]),
    ("psd_folded", lambda n: bt.psd_folded(1.0, bt.RectKernel(1e-4), 2e-5, 1e-8, 1e-3, n_alias=n),
     r"n_alias must be a non-negative integer; got n_alias = ", [0]),
    ("variance_general", lambda n: bt.variance_general(bt.RectKernel(1e-4), 2e-5, 1e-8, n_nodes=n),
     r"n_nodes must be an integer >= 1; got n_nodes = ", []),
    ("variance_general",
     lambda n: bt.variance_general(bt.RectKernel(1e-4), 2e-5, 1e-8, n_linear_panels=n),
     r"n_linear_panels must be an integer >= 1; got n_linear_panels = ", []),
]
COUNT_CASES = [(label, fn, match, bad) for label, fn, match, valid in COUNTS for bad in BAD_COUNTS
               if not any(bad is v or (type(bad) is type(v) and bad == v) for v in valid)]


@pytest.mark.parametrize("label, fn, match, bad", COUNT_CASES,
                         ids=[f"{c[0]}-{c[2].split()[0]}-{c[3]!r}" for c in COUNT_CASES])
def test_bad_counts(bad_input, label, fn, match, bad):
    bad_input(f"physics: {label}", lambda: fn(bad), match=match + re.escape(repr(bad)),
              value=(match.split()[0], bad))


@pytest.mark.parametrize("label, fn", [
    ("variance_general", lambda k: bt.variance_general(k, 2e-5, 1e-8)),
    ("psd_folded", lambda k: bt.psd_folded(1.0, k, 2e-5, 1e-8, 1e-3)),
], ids=["variance_general", "psd_folded"])
@pytest.mark.parametrize("kernel", [1e-4, "rect", None])
def test_kernel_must_be_a_kernel(bad_input, label, fn, kernel):
    bad_input(f"physics: {label}", lambda: fn(kernel), exc=TypeError,
              match=r"kernel must be a detection kernel .*; got ", value=("kernel", kernel))


TRACED = [
    ("blur_factor", "alpha", -0.5, r"alpha \(dimensionless exposure W/tau\) must be finite and >= 0"),
    ("lorentzian", "f", math.nan, r"f must be finite"),
    ("transfer_rect", "exposure", -1e-4, r"exposure \(exposure time W\) must be finite and > 0"),
    ("frame_autocovariance", "lag", 1.5, r"lag \(frame lag\) must be an integer"),
    ("psd_measured", "tracking_var", -1e-18, r"tracking_var .* must be finite and >= 0"),
]


@pytest.mark.parametrize("fn_name, param, bad, match", TRACED, ids=[t[0] for t in TRACED])
def test_traced_bad_values_raise_under_jit(bad_input, fn_name, param, bad, match):
    jitted = eqx.filter_jit(lambda x: _call(fn_name, **{param: x}))
    assert np.all(np.isfinite(np.asarray(jitted(np.float64(GOOD[param])))))
    bad_input(f"physics: {fn_name} (traced)", lambda: jitted(np.float64(bad)),
              exc=eqx.EquinoxRuntimeError, match=match, value=(param, bad))
