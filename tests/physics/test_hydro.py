"""Hydrodynamics and water properties against independent references: the published formulas
re-evaluated here in mpmath (written from the papers, not from blurtrap), the IAPWS check
values, IAPWS-95 / IAPWS 2008 reference values, and numerical integrals."""

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from scipy import integrate, optimize

import blurtrap.physics as ph
from blurtrap.physics import BOLTZMANN

mp.mp.dps = 40

# IAPWS 2008 viscosity (Huber et al. 2009), Table 1 and the nonzero entries of Table 2,
# H[(i, j)]: i the power of (1/T - 1), j the power of (rho - 1)
H_I = [1.67752, 2.20462, 0.6366564, -0.241605]
H_IJ = {(0, 0): 5.20094e-1, (1, 0): 8.50895e-2, (2, 0): -1.08374, (3, 0): -2.89555e-1,
        (0, 1): 2.22531e-1, (1, 1): 9.99115e-1, (2, 1): 1.88797, (3, 1): 1.26613,
        (5, 1): 1.20573e-1, (0, 2): -2.81378e-1, (1, 2): -9.06851e-1, (2, 2): -7.72479e-1,
        (3, 2): -4.89837e-1, (4, 2): -2.57040e-1, (0, 3): 1.61913e-1, (1, 3): 2.57399e-1,
        (0, 4): -3.25372e-2, (3, 4): 6.98452e-2, (4, 5): 8.72102e-3, (3, 6): -4.35673e-3,
        (5, 6): -5.93264e-4}


def mp_iapws(t, rho):
    """Huber et al. (2009) eqs. (2), (11), (12) with mu_2 = 1, in mpmath [Pa s]."""
    tb, rb = mp.mpf(t) / mp.mpf("647.096"), mp.mpf(rho) / 322
    mu0 = 100 * mp.sqrt(tb) / mp.fsum(mp.mpf(h) / tb**i for i, h in enumerate(H_I))
    s = mp.fsum(mp.mpf(h) * (1 / tb - 1) ** i * (rb - 1) ** j for (i, j), h in H_IJ.items())
    return mu0 * mp.exp(rb * s) * mp.mpf("1e-6")


# Huber et al. (2009), Table 4: T [K], rho [kg/m^3], mu [uPa s] (with mu_2 = 1)
IAPWS_TABLE4 = [(298.15, 998.0, 889.735100), (298.15, 1200.0, 1437.649467),
                (373.15, 1000.0, 307.883622), (433.15, 1.0, 14.538324),
                (433.15, 1000.0, 217.685358), (873.15, 1.0, 32.619287),
                (873.15, 100.0, 35.802262), (873.15, 600.0, 77.430195),
                (1173.15, 1.0, 44.217245), (1173.15, 100.0, 47.640433),
                (1173.15, 400.0, 64.154608)]

# liquid water at 0.1 MPa: T [K], IAPWS-95 density [kg/m^3], IAPWS 2008 viscosity [Pa s]
# (reference values evaluated with CoolProp 8.0.0, which is not a test dependency)
IAPWS_01MPA = [(273.16, 999.8430880, 1.79113501e-3), (277.13, 999.9742172, 1.56830212e-3),
               (293.15, 998.2065435, 1.00159655e-3), (298.15, 997.0470390, 8.90022674e-4),
               (313.15, 992.2157713, 6.52728560e-4), (333.15, 983.1952445, 4.66034759e-4),
               (353.15, 971.7898039, 3.54050298e-4), (372.75, 958.6357599, 2.82768195e-4)]


@pytest.mark.parametrize("t,rho,mu", IAPWS_TABLE4)
def test_iapws_viscosity_check_values(t, rho, mu):
    got = float(ph.iapws_viscosity(t, rho)) * 1e6
    assert abs(got - mu) <= 1e-6, got  # the table gives 6 decimals
    assert got == pytest.approx(float(mp_iapws(t, rho)) * 1e6, rel=1e-13)


@pytest.mark.parametrize("t,rho,mu", IAPWS_01MPA)
def test_water_at_01mpa_against_iapws(t, rho, mu):
    assert float(ph.water_density(t)) == pytest.approx(rho, rel=6e-6)
    assert float(ph.water_viscosity(t)) == pytest.approx(mu, rel=1.5e-5)
    # the combination is the formulation at the correlation's density, nothing else
    assert float(ph.water_viscosity(t)) == pytest.approx(
        float(mp_iapws(t, float(ph.water_density(t)))), rel=1e-13)


def tanaka_density(tc):
    """CIPM density of SMOW, Tanaka et al., Metrologia 38, 301 (2001), eq. (1), 0-40 C."""
    tc = mp.mpf(tc)
    a1, a2, a3 = mp.mpf("-3.983035"), mp.mpf("301.797"), mp.mpf("522528.9")
    a4, a5 = mp.mpf("69.34881"), mp.mpf("999.974950")
    return a5 * (1 - (tc + a1) ** 2 * (tc + a2) / (a3 * (tc + a4)))


def test_water_density_values_and_maximum():
    tc = np.linspace(0.01, 40.0, 41)
    got = np.asarray(ph.water_density(273.15 + tc))
    ref = np.array([float(tanaka_density(t)) for t in tc])
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    assert float(ph.water_density(293.15)) == pytest.approx(998.2, abs=0.01)
    best = optimize.minimize_scalar(lambda t: -float(ph.water_density(t)), (275.0, 277.0, 279.0),
                                    tol=1e-10)
    assert best.x - 273.15 == pytest.approx(3.98, abs=0.02)  # maximum density at 3.98 C
    assert -best.fun == pytest.approx(999.972, abs=2e-3)


@pytest.mark.parametrize("t", [250.0, 373.5, 25.0, float("nan")])
def test_water_temperature_range(t):
    with pytest.raises(ValueError, match=r"temperature must be within \[273.15, 373.15\] K"):
        ph.water_viscosity(t)
    with pytest.raises(ValueError, match="temperature must be within"):
        ph.water_density(np.array([295.0, t]))


def test_water_functions_trace_and_differentiate():
    t = jnp.asarray(300.0)
    assert float(jax.jit(ph.water_viscosity)(t)) == pytest.approx(float(ph.water_viscosity(t)),
                                                                   rel=1e-14)
    for fn in (ph.water_viscosity, ph.water_density):
        g = float(jax.jit(jax.grad(fn))(t))
        fd = (float(fn(t + 1e-3)) - float(fn(t - 1e-3))) / 2e-3
        assert g == pytest.approx(fd, rel=1e-6)
    v = jax.vmap(ph.water_viscosity)(jnp.linspace(280.0, 360.0, 5))
    assert np.all(np.diff(np.asarray(v)) < 0)


def test_stokes_and_faxen():
    r, eta = 1.5e-6, 0.00089
    assert float(ph.stokes_friction(r, eta)) == pytest.approx(6 * np.pi * eta * r, rel=1e-15)
    assert float(ph.faxen_factor(r, jnp.inf)) == 1.0  # bulk: x = 0
    assert float(ph.faxen_factor(r, 1e6 * r)) == pytest.approx(1 + 9 / 16 * 1e-6, rel=1e-12)

    def mp_faxen(x):
        x = mp.mpf(x)
        return 1 / (1 - mp.mpf(9) / 16 * x + x**3 / 8 - mp.mpf(45) / 256 * x**4 - x**5 / 16)

    for x in (0.5, 0.1, 0.3, 0.9):
        assert float(ph.faxen_factor(r, r / x)) == pytest.approx(float(mp_faxen(x)), rel=1e-14)
    assert float(ph.faxen_factor(1.0, 2.0)) == pytest.approx(1.3861252115059222, rel=1e-14)
    # published values of the same series (lumicks/pylake test_faxen, R = 0.25 um)
    got = ph.faxen_factor(0.25e-6, 0.25e-6 + np.array([40e-9, 120e-9, 200e-9]))
    np.testing.assert_allclose(got, [2.1352513786215033, 1.6311828228718854, 1.4516296587727144],
                               rtol=1e-12)


def mp_brenner(h_over_r):
    """Brenner (1961): exact perpendicular friction ratio (infinite series), in mpmath."""
    a = mp.acosh(mp.mpf(h_over_r))

    def term(n):
        num = 2 * mp.sinh((2 * n + 1) * a) + (2 * n + 1) * mp.sinh(2 * a)
        den = 4 * mp.sinh((n + mp.mpf(1) / 2) * a) ** 2 - (2 * n + 1) ** 2 * mp.sinh(a) ** 2
        return n * (n + 1) / ((2 * n - 1) * (2 * n + 3)) * (num / den - 1)

    return mp.mpf(4) / 3 * mp.sinh(a) * mp.nsum(term, [1, mp.inf])


@pytest.mark.parametrize("h_over_r,tol", [(1.01, 3e-3), (1.1, 7e-4), (1.5, 1e-4), (2.0, 4e-4),
                                          (3.0, 1e-4), (10.0, 1e-5), (100.0, 1e-8)])
def test_brenner_approximant_against_the_series(h_over_r, tol):
    got = float(ph.brenner_factor(1e-6, h_over_r * 1e-6))
    assert got == pytest.approx(float(mp_brenner(h_over_r)), rel=tol)


@pytest.mark.parametrize("fn", [ph.faxen_factor, ph.brenner_factor])
def test_wall_distance_errors(fn):
    with pytest.raises(ValueError, match="distance .* must exceed the radius; got distance = 1e-06"):
        fn(1e-6, 1e-6)
    with pytest.raises(ValueError, match="radius must be finite and > 0"):
        fn(-1e-6, 2e-6)
    with pytest.raises(Exception, match="must exceed the radius"):  # traced: eqx.error_if
        jax.block_until_ready(jax.jit(fn)(jnp.asarray(1e-6), jnp.asarray(0.5e-6)))


def mp_friction(f, radius, eta, rho, h=None):
    """gamma(f)/gamma_0: BS&F 2004 in bulk; Tolic-Norrelykke et al. 2006, eq. D6 at a wall."""
    f, radius = mp.mpf(f), mp.mpf(radius)
    f_nu = mp.mpf(eta) / (mp.pi * mp.mpf(rho) * radius**2)
    s = mp.sqrt(mp.mpc(f / f_nu))
    bulk = 1 + (1 - 1j) * s - 2j / mp.mpf(9) * f / f_nu
    if h is None:
        return bulk
    eps = (2 * mp.mpf(h) - radius) / radius * s
    den = 1 - mp.mpf(9) / 16 * radius / mp.mpf(h) * (
        1 - (1 - 1j) / 3 * s + 2j / mp.mpf(9) * f / f_nu - mp.mpf(4) / 3 * (1 - mp.exp(-(1 - 1j) * eps)))
    return bulk / den


R, ETA, RHO = 1.5e-6, 0.00089, 997.0
F = np.array([0.0, 1e-3, 37.0, 1e3, 5e4, 1e6, 3e7])


@pytest.mark.parametrize("h", [None, 1.6 * R, 3 * R, 20 * R])
def test_complex_friction_against_the_papers(h):
    got = np.asarray(ph.complex_friction(F, R, ETA, RHO, jnp.inf if h is None else h))
    ref = np.array([complex(mp_friction(f, R, ETA, RHO, h)) for f in F])
    np.testing.assert_allclose(got, ref, rtol=1e-13)
    neg = np.asarray(ph.complex_friction(-F, R, ETA, RHO, jnp.inf if h is None else h))
    np.testing.assert_allclose(neg, np.conj(ref), rtol=1e-13)  # a real response in time


def test_complex_friction_limits_and_published_values():
    # f -> 0: Stokes in bulk, Faxen to first order at a wall
    assert complex(ph.complex_friction(0.0, R, ETA, RHO)) == 1.0
    assert abs(complex(ph.complex_friction(1e-9, R, ETA, RHO)) - 1) < 1e-5
    assert complex(ph.complex_friction(0.0, R, ETA, RHO, 2 * R)) == pytest.approx(1 / (1 - 9 / 32))
    far = np.asarray(ph.complex_friction(F, R, ETA, RHO, 1e9 * R))  # O(R/h (1 + f/f_nu))
    np.testing.assert_allclose(far, np.asarray(ph.complex_friction(F, R, ETA, RHO)), rtol=1e-7)
    # lumicks/pylake test_complex_drag: gamma_0 = 1.16e-8 N s/m, R = 0.52 um, h = R + 25 nm
    g0, r = 1.16e-8, 0.52e-6
    f = np.array([-5000.0, 37.0, 1000.0, 5000.0, 8000.0])
    got = np.asarray(ph.complex_friction(f, r, g0 / (6 * np.pi * r), 997.0, r + 25e-9))
    np.testing.assert_allclose(got.real, [2.024434965031, 2.146433851928, 2.096663632939,
                                          2.024434965031, 1.992226321743], rtol=1e-9)
    np.testing.assert_allclose(got.imag, [-0.097554582022, 0.011630458607, 0.05320652377,
                                          0.097554582022, 0.11210831639], rtol=1e-8)


def mp_psd(f, k, radius, t, eta, rho_f, rho_b, h=None):
    """Tolic-Norrelykke et al. (2006), eq. D2 (two-sided), with the bulk Stokes gamma_0 and
    the bead's own mass in f_m (the fluid's added mass is in gamma(f)) [m^2/Hz]."""
    g0 = 6 * mp.pi * mp.mpf(eta) * mp.mpf(radius)
    d, fc = BOLTZMANN * mp.mpf(t) / g0, mp.mpf(k) / (2 * mp.pi * g0)
    f_m = g0 / (2 * mp.pi * 4 * mp.pi * mp.mpf(radius) ** 3 * mp.mpf(rho_b) / 3)
    g = mp_friction(abs(f), radius, eta, rho_f, h)
    af = abs(mp.mpf(f))
    return d / (2 * mp.pi**2) * g.real / ((fc + af * g.imag - af**2 / f_m) ** 2
                                          + (af * g.real) ** 2)


@pytest.mark.parametrize("h", [None, 1.6 * R, 4 * R])
def test_hydro_psd_against_the_papers(h):
    t, k, rho_b = 298.15, 2e-5, 1050.0
    eta, rho = float(ph.water_viscosity(t)), float(ph.water_density(t))
    gamma = 6 * np.pi * eta * R * (1.0 if h is None else 1 / (1 - 9 / 16 * R / h))  # gamma(0)
    f = np.concatenate([-F[1:4], F])
    got = np.asarray(ph.hydro_psd(f, k, gamma, R, t, distance=jnp.inf if h is None else h))
    ref = np.array([float(mp_psd(x, k, R, t, eta, rho, rho_b, h)) for x in f])
    np.testing.assert_allclose(got, ref, rtol=1e-12)


def test_bulk_psd_is_the_former_formula():
    """Berg-Sorensen & Flyvbjerg (2004), eq. (12), as blurtrap wrote it before (numpy)."""
    f = np.linspace(-2e6, 2e6, 101)
    d, fc, f_nu, f_m = 0.4, 250.0, 1.3e5, 4.1e6
    af = np.abs(f)
    r = np.sqrt(af / f_nu)
    old = d / (2 * np.pi**2) * (1 + r) / ((fc - af * r - af**2 / f_m) ** 2 + (af + af * r) ** 2)
    got = np.asarray(ph.hydro_lorentzian(f, d, fc, f_nu, f_m))
    np.testing.assert_allclose(got, old, rtol=1e-14)
    from blurtrap.physics import _effects  # the old import path is the same function

    assert _effects.hydro_lorentzian is ph.hydro_lorentzian
    assert _effects.water_viscosity is ph.water_viscosity


def test_near_surface_psd_tends_to_bulk():
    """The wall's effect falls like R/h: ~(3/4) R/h where the viscous penetration depth
    passes 2h (from f ~ f_nu (R/2h)^2 on), growing like (R/h) f/f_nu at high f (the wall
    changes the entrained mass); up to 10 MHz (f/f_nu ~ 80) it stays below 40 R/h."""
    t, k, gamma = 295.0, 2e-5, 6 * np.pi * 0.00095 * R
    f = np.logspace(0, 7, 15)
    bulk = np.asarray(ph.hydro_psd(f, k, gamma, R, t))
    assert np.array_equal(np.asarray(ph.hydro_psd(f, k, gamma, R, t, distance=jnp.inf)), bulk)
    dev = []
    for x in (1e-3, 1e-6, 1e-9):
        near = np.asarray(ph.hydro_psd(f, k, gamma, R, t, distance=R / x))
        dev.append(np.max(np.abs(near / bulk - 1)))
        assert dev[-1] < 40 * x, x
    assert dev[0] / dev[1] == pytest.approx(1e3, rel=0.01)  # first order in R/h


def _integral(fn, fc):
    edges = np.concatenate([[0.0], np.logspace(np.log10(fc) - 4, np.log10(fc) + 8, 61)])
    parts = [integrate.quad(fn, a, b, epsabs=0, epsrel=1e-12, limit=200)[0]
             for a, b in zip(edges[:-1], edges[1:])]
    return 2 * (sum(parts) + integrate.quad(fn, edges[-1], np.inf, limit=200)[0])


@pytest.mark.parametrize("h", [None, 1.6 * R])
@pytest.mark.parametrize("k", [1e-6, 1e-4])
def test_hydro_psd_equipartition(k, h):
    """The two-sided PSD integrates to kT/k over f (FDT with a causal gamma(f))."""
    t = 298.15
    gamma = float(ph.stokes_friction(R, ph.water_viscosity(t)))
    if h is not None:
        gamma *= float(ph.faxen_factor(R, h))
    dist = jnp.inf if h is None else h
    psd = jax.jit(lambda f: ph.hydro_psd(f, k, gamma, R, t, distance=dist))
    total = _integral(lambda f: float(psd(f)), k / (2 * np.pi * gamma))
    assert total == pytest.approx(BOLTZMANN * t / k, rel=1e-8)


def test_hydro_psd_gradients_and_transforms():
    t, k, gamma, f = 298.15, 2e-5, 2.5e-8, jnp.asarray(3e4)

    @jax.jit
    def fn(p):  # parameters scaled to O(1)
        return ph.hydro_psd(f, p[0] * 1e-5, p[1] * 1e-8, p[2] * 1e-6, t, distance=p[3] * 1e-6)

    p0 = jnp.asarray([k * 1e5, gamma * 1e8, R * 1e6, 4.0])
    grad = np.asarray(jax.jit(jax.grad(fn))(p0))
    for i in range(4):
        e = jnp.zeros(4).at[i].set(1e-5)
        fd = (float(fn(p0 + e)) - float(fn(p0 - e))) / 2e-5
        assert grad[i] == pytest.approx(fd, rel=1e-6), i
    bulk_grad = jax.jit(jax.grad(lambda r: ph.hydro_psd(f, k, gamma, r, t)))(R)
    assert np.isfinite(float(bulk_grad))
    at_zero = jax.jit(jax.grad(lambda p: ph.hydro_lorentzian(0.0, 1.0, 1.0, p, 2.0, 0.3)))(5.0)
    assert float(at_zero) == 0.0  # no NaN from sqrt(f/f_nu) at f = 0
    fs = jnp.linspace(1.0, 1e5, 7)
    batched = jax.jit(jax.vmap(lambda x: ph.hydro_psd(x, k, gamma, R, t)))(fs)
    np.testing.assert_allclose(batched, ph.hydro_psd(fs, k, gamma, R, t), rtol=1e-14)
