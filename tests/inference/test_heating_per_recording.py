"""Laser heating: the fit reports the temperature and the friction of each recording (with
delta-method errors), and they match the truth of an independently generated power series."""

import dataclasses

import numpy as np
import pytest
from _xy_gen import principal_frames

import blurtrap as bt
from blurtrap.inference._heating import heating_rows
from blurtrap.physics import water_viscosity

T0, B_TRUE, C_TRUE, GAMMA0 = 295.0, 40.0, 1e-4, 9e-9
POWERS = (0.1, 0.2, 0.3, 0.4)
DT, W = 5e-4, 2.5e-4


def _series(seed, n=2**12):
    rng = np.random.default_rng(seed)
    recs = []
    for p in POWERS:
        t = T0 + B_TRUE * p
        g = GAMMA0 * float(water_viscosity(t) / water_viscosity(T0))
        x, _ = principal_frames(n, C_TRUE * p, C_TRUE * p, g, W, DT, rng, temperature=t)
        recs.append(bt.Recording(x + 2e-9 * rng.normal(size=n), frame_interval=DT, exposure=W,
                                 temperature=T0, laser_power=p))
    return recs


def test_heating_fit_reports_temperature_and_friction_per_power():
    res = bt.calibrate(_series(3), model="standard+laser_heating", k="per_power")
    rows = {label: (v, e) for label, v, e, _ in res.extras["per_recording"]}
    for p in POWERS:
        t_true = T0 + B_TRUE * p
        g_true = GAMMA0 * float(water_viscosity(t_true) / water_viscosity(T0))
        lab = f"[P={p * 1e3:g} mW]"
        t, te = rows["T" + lab]
        g, ge = rows["gamma" + lab]
        assert abs(t - t_true) < 3.5 * te, (p, t, te)
        assert abs(g - g_true) < 3.5 * ge, (p, g, ge)
    # the rows in the table and the JSON (Wald intervals: the profile ones are not the point)
    res = dataclasses.replace(res, interval_source=None)
    text = res.summary()
    assert "T[P=400 mW]" in text and "gamma[P=400 mW]" in text
    d = res.to_dict()
    assert {r["name"] for r in d["per_recording"]} >= {"T[P=100 mW]", "gamma[P=100 mW]"}


def test_heating_rows_against_finite_differences():
    """The delta-method errors equal a brute-force propagation through the same map."""

    class R:
        def __init__(self, p):
            self.temperature, self.laser_power = T0, p

    names = ("k", "gamma", "tracking_var", "heating")
    values = np.array([1e-5, 9e-9, 1e-18, 30.0])
    cov = np.diag([1e-14, (3e-10) ** 2, 1e-38, 4.0])
    cov[1, 3] = cov[3, 1] = 0.3 * 3e-10 * 2.0
    rows = heating_rows([R(0.3)], names, values, cov)
    (_, t, te, _), (_, g, ge, _) = rows

    def gamma_of(gv, bv):
        t_ = T0 + bv * 0.3
        return gv * float(water_viscosity(t_) / water_viscosity(T0))

    h = (1e-13, 1e-4)
    jac = np.array([(gamma_of(9e-9 + h[0], 30.0) - gamma_of(9e-9 - h[0], 30.0)) / (2 * h[0]),
                    (gamma_of(9e-9, 30.0 + h[1]) - gamma_of(9e-9, 30.0 - h[1])) / (2 * h[1])])
    c2 = cov[np.ix_([1, 3], [1, 3])]
    assert t == pytest.approx(T0 + 9.0)
    assert te == pytest.approx(0.3 * 2.0, rel=1e-12)
    assert g == pytest.approx(gamma_of(9e-9, 30.0), rel=1e-12)
    assert ge == pytest.approx(float(np.sqrt(jac @ c2 @ jac)), rel=1e-6)
    assert heating_rows([R(0.3)], ("k", "gamma"), values[:2], cov[:2, :2]) == ()
