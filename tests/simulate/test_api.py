"""API, determinism, grids, chunking, injections, exact-frame law and bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from blurtrap.physics import BOLTZMANN, TrapezoidKernel, measured_variance, variance_general
from blurtrap.simulate import (
    ExposureWindows,
    RandomWalkDrift,
    SinusoidDrift,
    SubstepBiasWarning,
    TimingJitter,
    TrackingNoise,
    TrapezoidProfile,
    harmonic_force,
    quartic_force,
    simulate,
)
from blurtrap.simulate import _coeffs as co

K, TAU = 5e-5, 0.537e-3
GAMMA = K * TAU
S2 = BOLTZMANN * 295.0 / K
Z = 4.0


def _sim(n_frames=50, **kw):
    kw.setdefault("key", jax.random.key(0))
    kw.setdefault("substeps", 8)
    return simulate(kw.pop("k", K), kw.pop("gamma", GAMMA), kw.pop("exposure", 0.5 * TAU),
                    kw.pop("frame_interval", TAU), n_frames, **kw)


# --- exact joint law of (x_end, average) -------------------------------------------------

@pytest.mark.parametrize("L", [1e-3, 0.2, 0.49, 0.51, 2.0, 20.0])
def test_segment_law_against_quadrature(L):
    """var(m|x0) and cov(x_L, m|x0) from integrating cov(x_s,x_t|x0) = e^-|t-s| - e^-(s+t)."""
    import mpmath as mp

    mp.mp.dps = 30
    Lm = mp.mpf(L)
    c = lambda s, t: mp.exp(-abs(t - s)) - mp.exp(-(s + t))  # noqa: E731
    # symmetric in (s, t): twice the integral over t < s, smooth on each triangle
    inner = lambda s: mp.quad(lambda t: c(s, t), [0, s])  # noqa: E731
    vm = float(2 * mp.quad(inner, [0, Lm]) / Lm**2)
    cxm = float(mp.quad(lambda t: c(t, Lm), [0, Lm]) / Lm)
    em1, p, s_m, c_x, s_x = co.segment_law(np.array(L))
    np.testing.assert_allclose(em1, float(mp.expm1(-Lm)), rtol=1e-15)
    np.testing.assert_allclose(s_m**2, vm, rtol=1e-7)
    np.testing.assert_allclose(c_x * s_m, cxm, rtol=1e-8)
    np.testing.assert_allclose(c_x**2 + s_x**2, 1 - np.exp(-2 * L), rtol=1e-10)
    np.testing.assert_allclose(p, (1 - np.exp(-L)) / L, rtol=1e-12)
    # unconditional: p^2 + var(m|x0) = S(L)
    np.testing.assert_allclose(p**2 + s_m**2, co.s_blur(L), rtol=1e-12)


@pytest.mark.parametrize("a, r", [(1e-4, 1e-3), (0.3, 0.3), (0.49, 2.0), (0.51, 0.51),
                                  (2.0, 5.0), (20.0, 20.0), (800.0, 900.0),
                                  (1e-6, 1e-6),  # c -> 1
                                  (800.0, 800.0)])  # c underflows to 0, b ~ 6e-4 must not
def test_innovations_law_against_quadrature(a, r):
    """The innovations form (one normal per frame) reproduces the frames' autocovariance
    C(n) = (1/a^2) int int e^{-|n r + t - s|} ds dt (units sigma, tau) at lags 0, 1, 2,
    written as the one-dimensional (1/a^2) int_{-a}^{a} (a - |u|) e^{-|n r + u|} du."""
    import mpmath as mp

    mp.mp.dps = 30
    am, rm = mp.mpf(a), mp.mpf(r)

    def cov(n):
        if a > 100:  # beyond float64's sinh; the closed forms S(a) and e^{-n r} q(a)
            if n == 0:
                return 2 / am * (1 - (1 - mp.exp(-am)) / am)
            return mp.exp(-n * rm) * (mp.sinh(am / 2) / (am / 2)) ** 2
        f = lambda u: (am - abs(u)) * mp.exp(-abs(n * rm + u))  # noqa: E731
        # kink at u = 0; e^{-u} varies on the scale 1
        return mp.quad(f, mp.linspace(-am, am, max(41, int(4 * a) + 1))) / am**2

    cm1, cb, s, sv = co.innovations_law(np.array(a), np.array(r))
    np.testing.assert_allclose(cm1, float(mp.expm1(-rm)), rtol=1e-15)
    c = np.exp(-r)
    b = cb - c
    assert abs(b) < 1
    # X_m = xh_m + e_m, xh_{m+1} = c xh_m + (c + b) e_m, var(xh) = v, var(e) = s^2
    g0 = sv**2 + s**2
    g1 = c * sv**2 + cb * s**2
    np.testing.assert_allclose(g0, float(cov(0)), rtol=1e-12)
    np.testing.assert_allclose(g1, float(cov(1)), rtol=1e-10)
    np.testing.assert_allclose(c * g1, float(cov(2)), rtol=1e-10)
    # v is the stationary variance of the predictor
    np.testing.assert_allclose(sv**2, c * c * sv**2 + cb**2 * s**2, rtol=1e-12)


def test_cond_avg_var_series_small_L():
    import mpmath as mp

    mp.mp.dps = 40
    for Lf in (1e-8, 1e-4, 0.3):
        L = mp.mpf(Lf)
        ref = float(2 / mp.mpf(L) - 2 * (1 - mp.e ** (-L)) / L**2 - ((1 - mp.e ** (-L)) / L) ** 2)
        np.testing.assert_allclose(co.cond_avg_var(np.array(Lf)), ref, rtol=1e-13)


# --- determinism, keys, grids, chunks ----------------------------------------------------

def test_same_key_identical_different_keys_independent():
    a = _sim(400, n_traces=64, key=jax.random.key(42))
    b = _sim(400, n_traces=64, key=jax.random.key(42))
    c = _sim(400, n_traces=64, key=jax.random.key(43))
    np.testing.assert_array_equal(a, b)
    a, c = np.asarray(a), np.asarray(c)
    # same-time correlation between runs: ~N(0, 1/n_eff); frames 10 tau apart are independent
    r = np.corrcoef(a[:, ::10].ravel(), c[:, ::10].ravel())[0, 1]
    assert abs(r) < Z / np.sqrt(a[:, ::10].size)


def test_raw_uint32_key_accepted():
    np.testing.assert_array_equal(_sim(5, key=jax.random.PRNGKey(3)),
                                  _sim(5, key=jax.random.wrap_key_data(jax.random.PRNGKey(3))))


@pytest.mark.parametrize("method", ["exact", "exact_frames", "euler"])
def test_grid_equals_individual_calls(method):
    kw = dict(method=method, n_traces=3, key=jax.random.key(9))
    if method == "exact_frames":
        kw["substeps"] = None
    if method == "euler":
        # euler's static dead-time substep count is the grid's finest; keep tau fixed so the
        # counts coincide with the individual calls (see the simulate docstring)
        a = dict(temperature=np.array([[290.0], [300.0]]))
        b = dict(tracking_std=np.array([0.0, 1e-9, 2e-9]))
        kw["bias_tol"] = 1.0
    else:
        a = dict(k=np.array([[K], [2 * K]]))
        b = dict(exposure=np.array([0.2, 0.5, 1.0]) * TAU)
    (na, va), (nb, vb) = next(iter(a.items())), next(iter(b.items()))
    grid = _sim(20, **a, **b, **kw)
    assert grid.shape == (2, 3, 3, 20)
    for i in range(2):
        for j in range(3):
            one = _sim(20, **{na: va[i, 0], nb: vb[j]}, **kw)
            np.testing.assert_allclose(grid[i, j], one, rtol=1e-12, atol=1e-24)


def test_key_grid_gives_independent_streams():
    keys = jax.random.split(jax.random.key(1), 2)
    out = _sim(10, k=np.array([K, K]), key=keys)
    np.testing.assert_array_equal(out[1], _sim(10, key=keys[1]))
    assert not np.allclose(out[0], out[1])


@pytest.mark.parametrize("method", ["exact", "exact_frames"])
def test_chunking_and_burn_in_do_not_change_results(method):
    sub = 8 if method == "exact" else None
    full = _sim(60, method=method, substeps=sub, n_traces=2, burn_in_frames=5)
    chunked = _sim(60, method=method, substeps=sub, n_traces=2, burn_in_frames=5,
                   chunk_frames=7)
    np.testing.assert_allclose(full, chunked, rtol=1e-13)
    longer = _sim(65, method=method, substeps=sub, n_traces=2)
    np.testing.assert_allclose(full, longer[:, 5:], rtol=1e-13)


def test_default_chunks_are_few_and_waste_little():
    """Default chunking: the fewest chunks of at most max_chunk frames, and the frames computed
    beyond the run (a partial last chunk runs in full) are fewer than one max_chunk/16 step
    per chunk (a fixed max_chunk wasted up to a whole chunk)."""
    from blurtrap.simulate._scan_run import balanced_chunk as _balanced_chunk

    for max_chunk in (1, 2, 3, 16, 17, 100, 41527):
        for total in [*range(1, 200), 41528, 65536, 10**6 + 3]:
            c = _balanced_chunk(total, max_chunk)
            n = -(-total // c)
            assert c <= max(max_chunk, 1) and n == -(-total // max_chunk), (total, max_chunk, c)
            assert 0 <= n * c - total < n * max(1, max_chunk // 16), (total, max_chunk, c)


def test_progress_bar_per_chunk(capsys):
    """A tqdm bar (the declared progress dependency) on stderr, refreshed after each chunk."""
    _sim(30, chunk_frames=10, progress=True)
    err = capsys.readouterr().err
    assert "simulate" in err
    assert all(f"| {i}/3 [" in err for i in range(4)), err  # tqdm's format, every chunk
    assert "chunk/s" in err or "s/chunk" in err
    _sim(30, chunk_frames=10, progress=False)
    assert capsys.readouterr().err == ""


def test_float32_output_dtype_and_scale():
    x = _sim(200, n_traces=32, dtype=jnp.float32)
    assert x.dtype == jnp.float32 and np.all(np.isfinite(x))
    assert 0.5 < float(np.var(np.asarray(x, np.float64))) / S2 < 1.5


def test_windows_first_window_equals_single_exposure_exact_frames():
    """exact_frames draws window segments in order: the first window equals a single-exposure
    run's law; check the windows axis order follows the user's order."""
    x = _sim(300, exposure=ExposureWindows([0.8 * TAU, 0.1 * TAU]), substeps=None,
             method="exact_frames", n_traces=128)
    v = np.mean(np.asarray(x) ** 2, axis=(1, 2))
    assert v[1] > v[0]  # shorter window, larger variance (S decreasing)


# --- forces, profiles, injections ---------------------------------------------------------

def test_quartic_force_with_zero_k4_is_harmonic():
    a = _sim(30, method="euler", n_traces=4)
    b = _sim(30, method="euler", n_traces=4, force=quartic_force, force_params=(K, 0.0))
    c = _sim(30, method="euler", n_traces=4, force=harmonic_force, force_params=K)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    np.testing.assert_allclose(a, c, rtol=1e-12)


def test_quartic_force_narrows_distribution():
    k4 = 3 * K / S2  # U4 = k x^2/2 + k4 x^4/4 with k4 sigma^2 = 3 k: strongly anharmonic
    x = np.asarray(_sim(300, method="euler", n_traces=256, substeps=20, exposure=0.02 * TAU,
                        force=quartic_force, force_params=(K, k4), burn_in_frames=10))
    # Boltzmann reference for the (nearly instantaneous) position
    u = np.linspace(-6, 6, 4001) * np.sqrt(S2)
    p = np.exp(-(K * u**2 / 2 + k4 * u**4 / 4) / (BOLTZMANN * 295.0))
    ref = np.sum(u**2 * p) / np.sum(p)
    per = np.mean(x**2, axis=1)
    se = per.std(ddof=1) / np.sqrt(per.size)
    # euler bias at h/tau = 1e-3 (~(h/2) k_eff/k) and blur at W/tau=0.02 are < 1 % here
    assert abs(per.mean() - ref) < Z * se + 0.01 * ref
    assert ref < 0.7 * S2


def test_trapezoid_profile_variance():
    w, rise = 1.0 * TAU, 0.3 * TAU
    x = _sim(1000, n_traces=256, exposure=w, frame_interval=2 * TAU, substeps=60,
             exposure_profile=TrapezoidProfile(rise / w))
    pred = float(variance_general(TrapezoidKernel(w, rise), K, GAMMA))
    per = np.mean(np.asarray(x) ** 2, axis=1)
    se = per.std(ddof=1) / np.sqrt(per.size)
    assert abs(per.mean() - pred) < Z * se
    assert abs(per.mean() - float(measured_variance(K, GAMMA, w))) > Z * se


def test_tracking_noise_adds_variance_only():
    eps = 0.5 * np.sqrt(S2)
    kw = dict(n_traces=256, method="exact_frames", substeps=None, key=jax.random.key(4))
    a = np.asarray(_sim(500, **kw))
    b = np.asarray(_sim(500, tracking_std=eps, **kw))
    c = np.asarray(_sim(500, injections=(TrackingNoise(eps),), **kw))
    noise = b - a  # same key: the same Brownian part
    se = eps**2 * np.sqrt(2 / noise.size)
    assert abs(np.mean(noise**2) - eps**2) < Z * se
    assert abs(np.mean(noise[:, 1:] * noise[:, :-1])) < Z * eps**2 / np.sqrt(noise.size)
    assert abs(np.mean((c - a) ** 2) - eps**2) < Z * se


def test_random_walk_and_sinusoid_drift():
    kw = dict(n_traces=512, method="exact_frames", substeps=None, key=jax.random.key(8))
    a = np.asarray(_sim(200, **kw))
    D = 1e-14
    b = np.asarray(_sim(200, injections=(RandomWalkDrift(D),), **kw))
    d = b - a
    inc = d[:, -1] - d[:, 0]
    pred = 2 * D * 199 * TAU
    assert abs(np.mean(inc**2) - pred) < Z * pred * np.sqrt(2 / inc.size)
    s = np.asarray(_sim(200, injections=(SinusoidDrift(1e-9, 100 * TAU, phase=0.0),), **kw))
    t = np.arange(200) * TAU
    np.testing.assert_allclose(s - a, np.broadcast_to(1e-9 * np.sin(2 * np.pi * t / (100 * TAU)),
                                                      a.shape), atol=1e-20)


def test_timing_jitter_times_and_stationarity():
    std = 0.05 * TAU
    x, t = _sim(500, n_traces=256, exposure=0.5 * TAU, frame_interval=TAU, method="exact_frames",
                substeps=None, injections=(TimingJitter(std),), return_times=True)
    x, t = np.asarray(x), np.asarray(t)
    assert t.shape == x.shape
    off = t - np.arange(500) * TAU
    assert abs(off.std() / std - 1) < Z * np.sqrt(1 / (2 * off.size))
    per = np.mean(x**2, axis=1)
    pred = float(measured_variance(K, GAMMA, 0.5 * TAU))
    assert abs(per.mean() - pred) < Z * per.std(ddof=1) / np.sqrt(per.size)


def test_jittered_time_stamps_never_overlap_the_previous_exposure():
    """Jitter large enough that a frame would start before the previous exposure ends: the
    frame starts at the end of that exposure (dead time clipped at 0), and its returned time
    stamp says so. Before, the stamps kept the unclipped times (intervals shorter than the
    exposure, which the irregular-time likelihood rightly refuses)."""
    w = 0.8 * TAU
    x, t = _sim(400, n_traces=64, exposure=w, frame_interval=TAU, method="exact_frames",
                substeps=None, injections=(TimingJitter(0.1 * TAU),), return_times=True)
    gaps = np.diff(np.asarray(t), axis=-1)
    assert gaps.min() >= w * (1 - 1e-9)
    assert np.mean(np.isclose(gaps, w, rtol=1e-9, atol=0)) > 0.005  # clipping did happen
    assert np.all(np.isfinite(np.asarray(x)))


# --- bad input ------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(k=-1.0), r"k \(trap stiffness\) must be finite and > 0 N/m; got k = -1"),
        (dict(gamma=0.0), r"gamma .* > 0 N s/m; got gamma = 0"),
        (dict(exposure=2 * TAU), r"exposure must be <= frame_interval; got exposure = 0\.001074"),
        (dict(frame_interval=np.nan), r"frame_interval .* got frame_interval = nan"),
        (dict(temperature=-3.0), r"temperature .* got temperature = -3"),
        (dict(tracking_std=-1e-9), r"tracking_std .* >= 0 m; got tracking_std = -1e-09"),
        (dict(n_frames=0), r"n_frames must be an integer >= 1; got n_frames = 0"),
        (dict(n_traces=2.5), r"n_traces must be an integer >= 1; got n_traces = 2\.5"),
        (dict(key=None), r"key must be a JAX PRNG key.*got key=None"),
        (dict(method="rk4"), r"method must be one of .*got method = 'rk4'"),
        (dict(method="exact_frames", substeps=4), r"substeps is not used by method='exact_frames'"),
        (dict(substeps=0), r"substeps must be an integer >= 1; got substeps = 0"),
        (dict(force=quartic_force), r"force needs method='euler'"),
    ],
)
def test_bad_input(kw, match):
    n = kw.pop("n_frames", 5)
    with pytest.raises(ValueError, match=match):
        _sim(n, **kw)


def test_coarse_exact_substeps_warn():
    with pytest.warns(SubstepBiasWarning, match=r"substeps = 1 .*method='exact'.*bias"):
        _sim(3, exposure=TAU, frame_interval=TAU, substeps=1)


def test_traced_parameters_rejected():
    with pytest.raises(ValueError, match=r"k \[N/m\] is traced"):
        jax.jit(lambda k: _sim(3, k=k))(K)
