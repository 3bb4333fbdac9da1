"""Spectra of the effect models used by diagnose, against independent references: brute-force
alias sums of the continuous PSDs written here (NumPy), and a Monte Carlo of random walks
for the drift's expected periodogram."""

import jax.numpy as jnp
import numpy as np
import pytest

from blurtrap.effects import Hydrodynamics
from blurtrap.inference._models import TrapModel
from blurtrap.physics import BOLTZMANN

T = 295.0
R = 1.0e-6
# water at T and 0.1 MPa: IAPWS 2008 viscosity and IAPWS-95 density (reference values, not
# computed by blurtrap; the model uses blurtrap.physics.water_viscosity / water_density)
ETA = 0.000957811  # [Pa s]
RHO_W = 997.807  # [kg/m^3]
GAMMA = 6 * np.pi * ETA * R
K = 5e-5


def ref_psd(f, dt, w, effect, n_alias=20000, wall=None):
    """Brute-force alias sum (|n| <= 20 000) of the continuous PSD of the detected position;
    ``wall``: distance of the bead centre to a surface (hydrodynamics)."""
    fs = 1 / dt
    n = np.arange(-n_alias, n_alias + 1)[:, None]
    ff = f[None, :] + n * fs
    om = 2 * np.pi * ff
    kt = BOLTZMANN * T
    if effect == "hydrodynamics":  # response function with gamma(-f) = conj(gamma(f))
        x = np.abs(ff) / (ETA / (RHO_W * np.pi * R**2))
        gam = GAMMA * (1 + (1 - 1j) * np.sqrt(x) - 2j / 9 * x)
        if wall is not None:  # Tolic-Norrelykke et al. (2006), eq. D6 (gamma_0 = GAMMA)
            c = 9 / 16 * R / wall
            eps = (2 * wall - R) / R * np.sqrt(x)
            gam = gam / (1 - c * (1 - (1 - 1j) / 3 * np.sqrt(x) + 2j / 9 * x
                                  - 4 / 3 * (1 - np.exp(-(1 - 1j) * eps))))
        gam = np.where(ff < 0, np.conj(gam), gam)
        mass = 4 / 3 * np.pi * R**3 * 1050.0
        p = 2 * kt * gam.real / np.abs(K - mass * om**2 - 1j * om * gam) ** 2
    else:
        p = 2 * kt * GAMMA / (K**2 + (om * GAMMA) ** 2)
    if effect == "exposure_kernel":  # trapezoid, rise = fall = 0.3 W
        h2 = (np.sinc(ff * w * 0.7) * np.sinc(ff * w * 0.3)) ** 2
    else:
        h2 = np.sinc(ff * w) ** 2
    if effect == "detector_filter":  # f3dB = 8 kHz, alpha = 0.4
        h2 = h2 * np.abs(0.4 + 0.6 / (1 + 1j * ff / 8e3)) ** 2
    return (p * h2).sum(axis=0)


EXTRAS = {"motion_blur": {},  # the standard model itself: blur + aliasing (+ eps^2 = 0)
          "hydrodynamics": {"hydro_radius": R},
          "detector_filter": {"f3db": 8e3, "diode_alpha": 0.4},
          "exposure_kernel": {"rise_fraction": 0.3}}


@pytest.mark.parametrize("effect", sorted(EXTRAS))
@pytest.mark.parametrize("w_frac", [1.0, 0.3, 1e-3])
def test_folded_effect_psd(effect, w_frac):
    """Folded model PSD (8 explicit aliases + Euler-Maclaurin tail) within 3e-5 of the
    brute-force 40 001-term alias sum, for the plain blur model and each effect, also for
    nearly instantaneous sampling (W = dt/1000), where the tail holds ~1/n_alias of the power
    near Nyquist."""
    dt = 1e-5
    w = w_frac * dt
    f = np.array([0.02, 0.1, 0.25, 0.4, 0.5]) / dt
    m = TrapModel() if effect == "motion_blur" else TrapModel().add(effect)
    assert m.n_alias <= 8  # the default: the tail, not the explicit sum, must do the work
    got = np.asarray(m.psd(jnp.asarray(f)[None, :], jnp.asarray([K]), jnp.asarray(GAMMA), 0.0,
                           jnp.asarray([dt]), jnp.asarray([w]), jnp.asarray([T]),
                           extras={k: jnp.asarray(v) for k, v in EXTRAS[effect].items()}))[0]
    np.testing.assert_allclose(got, ref_psd(f, dt, w, effect), rtol=3e-5)


@pytest.mark.parametrize("w_frac", [1.0, 1e-3])
def test_folded_hydrodynamics_near_a_wall(w_frac):
    """Bead centre 2.5 R from a surface: the folded model PSD, with gamma the zero-frequency
    friction of the wall formula (Stokes / (1 - 9 R/(16 h))), matches the brute-force alias
    sum of the response-function PSD with the wall's frequency-dependent friction within
    3e-5, and differs from the bulk one (the wall lowers the high-frequency friction)."""
    dt, h = 1e-5, 2.5 * R
    w = w_frac * dt
    f = np.array([0.02, 0.1, 0.25, 0.4, 0.5]) / dt
    m = TrapModel().add(Hydrodynamics(distance=h))
    gamma = GAMMA / (1 - 9 / 16 * R / h)
    got = np.asarray(m.psd(jnp.asarray(f)[None, :], jnp.asarray([K]), jnp.asarray(gamma), 0.0,
                           jnp.asarray([dt]), jnp.asarray([w]), jnp.asarray([T]),
                           extras={"hydro_radius": jnp.asarray(R)}))[0]
    np.testing.assert_allclose(got, ref_psd(f, dt, w, "hydrodynamics", wall=h), rtol=3e-5)
    assert np.max(np.abs(got / ref_psd(f, dt, w, "hydrodynamics") - 1)) > 1e-2


def test_drift_expected_periodogram_is_twice_the_increment_psd():
    """A sampled random walk (increments of variance 2 D dt) has expected periodogram
    D dt^2 / sin^2(pi f dt) at every Fourier frequency j >= 1 (twice the 'PSD'
    D dt^2 / (2 sin^2)): the drift effect models exactly that. Monte Carlo over 400 walks,
    band means of periodogram/model, SE from the spread over walks (ordinates of one walk are
    correlated through its end-to-end displacement)."""
    rng = np.random.default_rng(20061225)
    n, dt, d = 1024, 1e-3, 2e-16
    y = np.cumsum(rng.normal(0.0, np.sqrt(2 * d * dt), (400, n)), axis=1)
    y = y - y.mean(axis=1, keepdims=True)
    per = np.abs(np.fft.rfft(y, axis=1)[:, 1:]) ** 2 * dt / n
    f = np.arange(1, n // 2 + 1) / (n * dt)
    m = TrapModel().add("drift")
    model = np.asarray(m.extra[0].psd_add(jnp.asarray(f), dt, {"drift_diffusion": d}))
    q = per / model
    for band in (slice(0, 4), slice(4, 64), slice(64, 512)):
        walk_means = q[:, band].mean(axis=1)
        est, se = walk_means.mean(), walk_means.std(ddof=1) / np.sqrt(walk_means.size)
        assert abs(est - 1) < 4 * se, (band, est, se)
        assert abs(est - 0.5) > 10 * se  # the factor 2 is resolved
