"""Photodiode filter (``detector_filter``) and hydrodynamic friction (``hydrodynamics``) in the
simulator, against independent references: the position PSD written here from the physics
(a complex-friction response function, not the package's algebra), folded by a brute-force
NumPy alias sum, and the frame autocovariance from a periodic trapezoid integral of it.
Monte Carlo checks use fixed keys and 4-sigma bounds with the SE from the spread over traces.
"""

import jax
import numpy as np
import pytest

from blurtrap.physics import BOLTZMANN, frame_autocovariance
from blurtrap.simulate import HydrodynamicFriction, PhotodiodeFilter, simulate
from blurtrap.simulate._spectral import folded_psd

T = 295.0
Z = 4.0


def water_eta(temp):
    return 2.414e-5 * 10.0 ** (247.8 / (temp - 140.0))


def ref_continuous_psd(f, k, gamma, w, radius=None, f3db=None, alpha=None, temp=T, wall=None):
    """Two-sided PSD [m^2/Hz] of the detected position: response function of
    m x'' = -k x - gamma(f) x' + noise with the fluctuation-dissipation theorem,
    P = 2 kT Re gamma(f) / |k - m w^2 - i w gamma(f)|^2, times sinc^2(f W) |H(f)|^2, with the
    oscillating-sphere friction gamma(f) = gamma0 (1 + (1 - i) sqrt(f/f_nu) - (2i/9) f/f_nu)
    (Stokes + Basset + half the displaced fluid's mass; Landau & Lifshitz section 24); with
    ``wall`` (bead centre to a surface) divided by Tolic-Norrelykke et al.'s (2006, eq. D6)
    denominator (then gamma(0) = gamma0 / (1 - 9 R / (16 wall)))."""
    f = np.asarray(f, dtype=float)
    om = 2 * np.pi * f
    kt = BOLTZMANN * temp
    if radius is None:
        gam = gamma + 0j * f
        mass = 0.0
    else:
        eta, rho_f, rho_b = water_eta(temp), 997.0, 1050.0
        f_nu = eta / (rho_f * np.pi * radius**2)
        x = f / f_nu  # gamma(-f) = conj(gamma(f)): the friction kernel is real in time
        gam = gamma * (1 + (1 - 1j * np.sign(f)) * np.sqrt(np.abs(x)) - 2j / 9 * x)
        if wall is not None:
            c, s = 9 / 16 * radius / wall, np.sqrt(np.abs(x))
            eps = (2 * wall - radius) / radius * s
            den = 1 - c * (1 - (1 - 1j) / 3 * s + 2j / 9 * np.abs(x)
                           - 4 / 3 * (1 - np.exp(-(1 - 1j) * eps)))
            gam = gam / np.where(f < 0, np.conj(den), den)
        mass = 4 / 3 * np.pi * radius**3 * rho_b
    p = 2 * kt * gam.real / np.abs(k - mass * om**2 - 1j * om * gam) ** 2
    p = p * np.sinc(f * w) ** 2
    if f3db is not None:
        h = alpha + (1 - alpha) / (1 + 1j * f / f3db)
        p = p * np.abs(h) ** 2
    return p


def ref_folded(f, dt, n_alias=20000, **kw):
    """Brute-force alias sum over |n| <= n_alias (in blocks of aliases)."""
    fs = 1 / dt
    f = np.asarray(f, dtype=float)
    out = np.zeros_like(f)
    n_all = np.arange(-n_alias, n_alias + 1)
    for block in np.array_split(n_all, max(1, n_all.size * f.size // 2_000_000)):
        out += ref_continuous_psd(f[None, :] + block[:, None] * fs, **kw).sum(axis=0)
    return out


def ref_acov(lags, dt, m=4096, **kw):
    """C(n) = int_{-fs/2}^{fs/2} P_d(f) cos(2 pi f n dt) df by the periodic trapezoid rule."""
    fs = 1 / dt
    f = (np.arange(m) + 0.5) / m * fs - fs / 2
    pd = ref_folded(f, dt, n_alias=400, **kw)
    return np.array([np.sum(pd * np.cos(2 * np.pi * f * n * dt)) * fs / m for n in lags])


def mc_acov(x, lags):
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    per = np.stack([np.mean(x[:, : n - lag] * x[:, lag:], axis=1) for lag in lags])
    return per.mean(axis=1), per.std(axis=1, ddof=1) / np.sqrt(x.shape[0])


# photodiode-rate settings: 1.5 um bead, k = 0.05 pN/nm (tau = 0.53 ms), 20 kHz sampling
K = 5e-5
R = 1.5e-6
GAMMA = 6 * np.pi * water_eta(T) * R
DT = 5e-5


@pytest.mark.parametrize("w_frac", [1.0, 0.5])
@pytest.mark.parametrize("f3db,alpha", [(2e3, 0.4), (1e4, 0.0)])
def test_folded_psd_matches_brute_force(f3db, alpha, w_frac):
    """The spectral sampler's discrete PSD (128 aliases + integral tail) equals a 40 001-term
    alias sum of the independent reference, with and without hydrodynamics."""
    w = w_frac * DT
    tau = GAMMA / K
    sigma2 = BOLTZMANN * T / K
    f = np.linspace(0.0, 0.5, 17)[1:] / DT
    for radius in (None, R):
        p = {"w": np.asarray(w / tau), "f3db": np.asarray(f3db * tau), "alpha": np.asarray(alpha)}
        if radius is not None:
            eta = water_eta(T)
            p["f_nu"] = np.asarray(eta / (997.0 * np.pi * radius**2) * tau)
            m_star = 4 / 3 * np.pi * radius**3 * (1050.0 + 997.0 / 2)
            p["f_m"] = np.asarray(GAMMA / (2 * np.pi * m_star) * tau)
        got = np.asarray(folded_psd(jax.numpy.asarray(f * tau), p, DT / tau)) * sigma2 * tau
        ref = ref_folded(f, DT, k=K, gamma=GAMMA, w=w, radius=radius, f3db=f3db, alpha=alpha)
        np.testing.assert_allclose(got, ref, rtol=2e-6)


def test_folded_psd_without_blur_needs_the_tail():
    """Nearly instantaneous sampling (W = dt/1000): the alias sum converges like 1/n, so the
    integral tail carries ~0.5 % of the power near Nyquist; with it the error is < 1e-5."""
    w = DT / 1000
    tau = GAMMA / K
    sigma2 = BOLTZMANN * T / K
    f = np.array([0.1, 0.3, 0.45, 0.5]) / DT
    p = {"w": np.asarray(w / tau)}
    got = np.asarray(folded_psd(jax.numpy.asarray(f * tau), p, DT / tau)) * sigma2 * tau
    ref = ref_folded(f, DT, n_alias=200000, k=K, gamma=GAMMA, w=w)
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    short = np.asarray(folded_psd(jax.numpy.asarray(f * tau), p, DT / tau, n_alias=8))
    assert np.max(np.abs(short * sigma2 * tau / ref - 1)) < 1e-4  # the tail does the work


@pytest.mark.parametrize("method", ["exact_frames", "spectral"])
def test_photodiode_autocovariance(method):
    """Frames through the photodiode filter (f3dB = 2 kHz, alpha = 0.4, W = dt/2): lags 0-3
    and 10 agree with the reference autocovariance within 4 SE, and the filter's effect on
    them is many SE (the test can fail)."""
    w = DT / 2
    lags = [0, 1, 2, 3, 10]
    x = simulate(K, GAMMA, w, DT, 4000, key=jax.random.key(7), n_traces=256, method=method,
                 injections=(PhotodiodeFilter(2e3, 0.4),))
    assert x.shape == (256, 4000)
    est, se = mc_acov(x, lags)
    ref = ref_acov(lags, DT, k=K, gamma=GAMMA, w=w, f3db=2e3, alpha=0.4)
    assert np.all(np.abs(est - ref) < Z * se), (est - ref) / se
    plain = np.array([float(frame_autocovariance(n, K, GAMMA, w, DT)) for n in lags])
    assert np.abs(est[0] - plain[0]) > 10 * se[0]


def test_photodiode_alpha_one_is_the_plain_trap():
    """alpha = 1 (no slow part) reproduces the exact ARMA(1,1) frame moments (closed form)."""
    w, dt = 0.8 * GAMMA / K, 2 * GAMMA / K
    lags = [0, 1, 2]
    x = simulate(K, GAMMA, w, dt, 2000, key=jax.random.key(3), n_traces=256,
                 method="exact_frames", injections=(PhotodiodeFilter(1e3, 1.0),))
    est, se = mc_acov(x, lags)
    ref = np.array([float(frame_autocovariance(n, K, GAMMA, w, dt)) for n in lags])
    assert np.all(np.abs(est - ref) < Z * se), (est - ref) / se


def test_spectral_plain_trap_matches_closed_form():
    """method='spectral' without effects: the exact closed-form frame autocovariance
    C(0) = sigma2 S, C(n) = sigma2 B rho^n (DESIGN item 5), lags 0-3."""
    w, dt = 0.4 * GAMMA / K, 0.5 * GAMMA / K
    lags = [0, 1, 2, 3]
    x = simulate(K, GAMMA, w, dt, 2000, key=jax.random.key(5), n_traces=256, method="spectral")
    est, se = mc_acov(x, lags)
    ref = np.array([float(frame_autocovariance(n, K, GAMMA, w, dt)) for n in lags])
    assert np.all(np.abs(est - ref) < Z * se), (est - ref) / se


def test_hydrodynamic_spectrum():
    """100 kHz frames with frequency-dependent friction (R = 1.5 um): periodogram/reference
    ratios (each Exp(1)) averaged over traces in 8 bands agree within 4 SE
    (SE = 1/sqrt(ordinates)), and differ from the Lorentzian by many SE near Nyquist; lag 0-2
    covariances match. The record (620 tau) keeps finite-record leakage below ~0.2 %."""
    dt = 1e-5
    n, n_tr = 32768, 16
    x = np.asarray(simulate(K, GAMMA, dt, dt, n, key=jax.random.key(11), n_traces=n_tr,
                            method="spectral", injections=(HydrodynamicFriction(R),)))
    spec = np.abs(np.fft.rfft(x - x.mean(axis=1, keepdims=True), axis=1)[:, 1:-1]) ** 2 * dt / n
    f = np.arange(1, n // 2) / (n * dt)
    hyd = ref_folded(f, dt, n_alias=100, k=K, gamma=GAMMA, w=dt, radius=R)
    lor = ref_folded(f, dt, n_alias=100, k=K, gamma=GAMMA, w=dt)
    bands = np.array_split(np.arange(f.size), 8)
    sep = []
    for b in bands[1:]:  # the lowest band holds the finite-record leakage of the plateau
        se = 1 / np.sqrt(b.size * n_tr)
        ratio = np.mean(spec[:, b] / hyd[b])
        assert abs(ratio - 1) < Z * se, (f[b[0]], ratio, se)
        sep.append(abs(np.mean(spec[:, b] / lor[b]) - 1) / se)
    assert max(sep) > 10  # hydrodynamics is resolved: the test discriminates
    lags = [0, 1, 2]
    est, se = mc_acov(x, lags)
    ref = ref_acov(lags, dt, k=K, gamma=GAMMA, w=dt, radius=R)
    assert np.all(np.abs(est - ref) < Z * se), (est - ref) / se


def test_hydrodynamic_spectrum_near_a_wall():
    """As above with the bead centre at 2 R from a surface (``distance``; the simulator's gamma
    is the zero-frequency friction, here Stokes / (1 - 9/32)): band ratios to the wall
    reference within 4 SE, and many SE from the bulk spectrum with the same zero-frequency
    friction (the wall lowers the friction at high frequency)."""
    dt, n, n_tr = 1e-5, 16384, 8
    gamma = GAMMA / (1 - 9 / 32)
    inj = HydrodynamicFriction(R, viscosity=water_eta(T), fluid_density=997.0, distance=2 * R)
    x = np.asarray(simulate(K, gamma, dt, dt, n, key=jax.random.key(12), n_traces=n_tr,
                            method="spectral", injections=(inj,)))
    spec = np.abs(np.fft.rfft(x - x.mean(axis=1, keepdims=True), axis=1)[:, 1:-1]) ** 2 * dt / n
    f = np.arange(1, n // 2) / (n * dt)
    wall = ref_folded(f, dt, n_alias=100, k=K, gamma=GAMMA, w=dt, radius=R, wall=2 * R)
    bulk = ref_folded(f, dt, n_alias=100, k=K, gamma=gamma, w=dt, radius=R)
    sep = []
    for b in np.array_split(np.arange(f.size), 8)[1:]:
        se = 1 / np.sqrt(b.size * n_tr)
        ratio = np.mean(spec[:, b] / wall[b])
        assert abs(ratio - 1) < Z * se, (f[b[0]], ratio, se)
        sep.append(abs(np.mean(spec[:, b] / bulk[b]) - 1) / se)
    assert max(sep) > 10


def test_injection_errors():
    with pytest.raises(ValueError, match="f3db must be finite and > 0 Hz"):
        PhotodiodeFilter(-1.0, 0.5)
    with pytest.raises(ValueError, match="alpha .* must be in \\[0, 1\\]"):
        PhotodiodeFilter(1e3, 1.5)
    with pytest.raises(ValueError, match="radius must be finite and > 0 m"):
        HydrodynamicFriction(0.0)
    with pytest.raises(ValueError, match="distance .* must exceed the radius"):
        HydrodynamicFriction(R, distance=0.5 * R)
    with pytest.raises(ValueError, match="fluid_density must be finite and > 0 kg/m"):
        HydrodynamicFriction(R, fluid_density=-1.0)
    with pytest.raises(ValueError, match="use method='spectral'"):
        simulate(K, GAMMA, DT, DT, 10, key=jax.random.key(0), method="exact_frames",
                 injections=(HydrodynamicFriction(R),))
    with pytest.raises(ValueError, match="PhotodiodeFilter needs method='exact_frames'"):
        simulate(K, GAMMA, DT, DT, 10, key=jax.random.key(0), method="exact", substeps=4,
                 injections=(PhotodiodeFilter(1e3, 0.5),))
    with pytest.raises(ValueError, match="substeps is not used by method='spectral'"):
        simulate(K, GAMMA, DT, DT, 10, key=jax.random.key(0), method="spectral", substeps=4)


def test_grid_calls_equal_individual_calls():
    """Common random numbers over a parameter grid, as for the other methods."""
    ks = np.array([K, 2 * K])
    for method, inj in (("exact_frames", (PhotodiodeFilter(2e3, 0.4),)),):
        grid = np.asarray(simulate(ks, GAMMA, DT / 2, DT, 64, key=jax.random.key(1), n_traces=3,
                                   method=method, injections=inj))
        assert grid.shape == (2, 3, 64) and np.all(np.isfinite(grid))
        for i, k in enumerate(ks):
            one = np.asarray(simulate(k, GAMMA, DT / 2, DT, 64, key=jax.random.key(1),
                                      n_traces=3, method=method, injections=inj))
            np.testing.assert_allclose(grid[i], one, rtol=1e-12, atol=0)
