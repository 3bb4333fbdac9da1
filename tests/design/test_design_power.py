"""Experiment design over laser powers (``bt.design(..., laser_powers=...)``, k = c P): the
power-series information against a brute-force numpy Whittle information (the closed-form
frame spectrum written here in numpy, derivatives by central differences, summed over the
Fourier frequencies of each recording), what a power series identifies at dt >> tau, the
candidates' table / dict / CLI, and bad input."""

import json
import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.cli import main
from blurtrap.design import relative_se

KB = 1.380649e-23
T = 295.0
GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
K = 5e-5  # at the reference power (p = 1)
DT = 1 / 1500
EPS2 = 4e-18  # (2 nm)^2
POWERS = (0.5, 1.0, 2.0)


def _blur(a):
    """S(alpha) = 2/a - 2 (1 - exp(-a)) / a^2, by its series below a = 0.1."""
    a = np.asarray(a, dtype=float)
    series = sum(2 * (-a) ** n / math.factorial(n + 2) for n in range(14))
    safe = np.where(a < 0.1, 1.0, a)
    return np.where(a < 0.1, series, 2 / safe - 2 * (-np.expm1(-safe)) / safe**2)


def _psd(f, k, gamma, w, dt, eps2):
    """Closed-form discrete PSD of blurred, sampled, noisy frames (numpy; DESIGN item 5)."""
    s2, tau = KB * T / k, gamma / k
    a = w / tau
    b = (np.sinh(a / 2) / (a / 2)) ** 2
    rho = math.exp(-dt / tau)
    th = 2 * np.pi * f * dt
    c0 = s2 * _blur(a) + eps2
    return dt * (c0 + 2 * s2 * b * (rho * np.cos(th) - rho**2)
                 / (1 - 2 * rho * np.cos(th) + rho**2))


def brute_information(recs, c, gamma=GAMMA, eps2=EPS2):
    """Sum over recordings (dt, W, N, p) of 1/2 sum_j g g^T at the Fourier frequencies f_j =
    j / (N dt), j = 1..N-1, g = d log P / d (log c, log gamma, log eps^2) by central
    differences, with k = c p for the recording at power p."""
    th0 = np.log([c, gamma, eps2])
    info = np.zeros((3, 3))
    for dt, w, n, p in recs:
        f = np.arange(1, int(n)) / (int(n) * dt)

        def logp(th, f=f, dt=dt, w=w, p=p):
            cc, gg, e2 = np.exp(th)
            return np.log(_psd(f, cc * p, gg, w, dt, e2))

        g = np.stack([(logp(th0 + h) - logp(th0 - h)) / 2e-5 for h in 1e-5 * np.eye(3)], axis=1)
        info += 0.5 * g.T @ g
    return info


def brute_se(recs, c, **kw):
    return np.sqrt(np.diag(np.linalg.inv(brute_information(recs, c, **kw))))


def test_power_series_information_is_the_sum_over_powers_of_the_whittle_information():
    """relative_se of a power series (recordings (dt, W, N, p)): the SEs of log c, log gamma,
    log eps^2 equal the brute-force information's to its O(1/N) difference from the
    continuum average (as in test_design: 2e-3 relative). The powers matter: the same
    recordings at p = 1 give SEs off by far more than the tolerance."""
    recs = [(DT, DT, 8192, 0.5), (DT, 0.3 * DT, 8192, 1.0), (DT, DT, 8192, 2.0)]
    ours = np.asarray(relative_se(recs, [K], GAMMA, T, EPS2, DT, False, True))[0]
    ref = brute_se(recs, K)
    np.testing.assert_allclose(ours, ref, rtol=3e-3)
    at_one = brute_se([r[:3] + (1.0,) for r in recs], K)
    assert np.max(np.abs(at_one / ref - 1)) > 0.1
    # a k range: worst over it, each k scaled by the powers
    two = np.asarray(relative_se(recs, [K, 2 * K], GAMMA, T, EPS2, DT, False, True))
    np.testing.assert_allclose(two[1], brute_se(recs, 2 * K), rtol=3e-3)


def test_at_dt_much_larger_than_tau_a_power_series_identifies_what_one_recording_cannot():
    """500 fps, k = 0.5 pN/nm at p = 1 (dt/tau = 36 at the lowest power): the frames are
    independent, so one recording gives one variance, kT/k S(W k/gamma) + eps^2, and cannot
    separate k, gamma and eps^2 at any exposure or power (brute-force SE of gamma > 100 %,
    131 s of frames). Three powers at one exposure W = 100 us (alpha = 0.9-3.6 across the
    powers: the curvature of S in k W / gamma) identify all three in the same time."""
    dt, k, n = 1 / 500, 5e-4, 65536
    series = [(dt, 1e-4, n // 3, p) for p in POWERS]
    se = brute_se(series, k)
    assert se[0] < 0.1 and se[1] < 0.5
    ours = np.asarray(relative_se(series, [k], GAMMA, T, EPS2, dt, False, True))[0]
    np.testing.assert_allclose(ours, se, rtol=3e-3)
    assert _gamma_precision(brute_information(series, k)) > 10.0  # SE of gamma < 32 %
    for p in POWERS:
        for w in (1e-6, 3e-5, 1e-4, 3e-4, 1e-3, dt):
            # one recording: 1 / SE(log gamma)^2 < 1 (it is ~1e-8, rounding of a singular F)
            assert _gamma_precision(brute_information([(dt, w, n, p)], k)) < 1.0, (p, w)


def _gamma_precision(info):
    """1 / var(log gamma) = the Schur complement of the other parameters' block (stable where
    the information is singular, unlike the diagonal of its inverse)."""
    o = [0, 2]
    return info[1, 1] - info[1, o] @ np.linalg.solve(info[np.ix_(o, o)], info[o, 1])


@pytest.fixture(scope="module")
def dt_tau_design():
    """The design of the test above with the powers available and the determinant target
    (k and gamma both needed): only the power series (exposure per power optimised)
    identifies them."""
    return bt.design(k=5e-4, gamma=GAMMA, max_fps=500, total_time=65536 / 500,
                     tracking_std=2e-9, target="determinant", laser_powers=(2, 0.5, 1),
                     series=(1,))


def test_design_recommends_the_power_series_at_dt_much_larger_than_tau(dt_tau_design):
    r = dt_tau_design
    assert r.best.label.startswith("optimised power series")
    assert r.best.laser_powers == POWERS  # sorted
    for c in r.candidates:
        if c is not r.best and len(c.recordings) == 1:  # one recording: never identified
            assert "not identified" in c.label and c.objective == math.inf
        for dt, w, _ in c.recordings:
            assert dt >= (1 / 500) * (1 - 1e-9) and 1e-6 * (1 - 1e-9) <= w <= dt * (1 + 1e-9)
    recs = [r_ + (p,) for r_, p in zip(r.best.recordings, r.best.laser_powers)]
    assert sum(dt * n for dt, _, n, _ in recs) == pytest.approx(65536 / 500, rel=1e-6)
    se = brute_se(recs, 5e-4)
    np.testing.assert_allclose([r.predicted_se["k"], r.predicted_se["gamma"]], se[:2],
                               rtol=3e-3)
    cov = np.linalg.inv(brute_information(recs, 5e-4))
    assert r.best.objective == pytest.approx(np.linalg.det(cov[:2, :2]) ** 0.25, rel=3e-3)


def test_power_candidates_in_table_dict_and_single_power(dt_tau_design):
    r = dt_tau_design
    labels = [c.label for c in r.candidates]
    assert any(lb.startswith("power series 0.5/1/2 P, W = dt") for lb in labels)
    assert any(lb.startswith("best single power") for lb in labels)
    d = r.to_dict()
    assert d["settings"]["laser_powers"] == list(POWERS)
    assert [x["laser_power_relative"] for x in d["best"]["recordings"]] == list(POWERS)
    naive = next(x for x in d["candidates"] if x["label"].startswith("W = dt"))
    assert all("laser_power_relative" not in x for x in naive["recordings"])
    text = r.summary()
    assert "@0.5P" in text and "@2P" in text and "linear_power" in text
    # the W = dt power series is what its label says, SEs from the brute-force information
    wdt = next(c for c in r.candidates if c.label.startswith("power series"))
    assert [w for _, w, _ in wdt.recordings] == [1 / 500] * 3
    se = brute_se([x + (p,) for x, p in zip(wdt.recordings, wdt.laser_powers)], 5e-4)
    np.testing.assert_allclose(wdt.predicted_se["k"][0], se[0], rtol=3e-3)


@pytest.mark.parametrize("powers", [(1.0,), (1.0, 1.0), (0.5, -1.0), (0.5, float("nan")),
                                    ("0.5", 1.0), (True, 2.0), 2.0, "0.5,1", [[0.5, 1.0]]])
def test_bad_laser_powers_are_named(powers):
    with pytest.raises(ValueError, match=r"laser_powers must be .* got laser_powers = "):
        bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=4096, laser_powers=powers)


def test_current_design_with_powers_is_checked():
    with pytest.raises(ValueError, match="laser power"):
        bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=4096, series=(),
                  current=[(DT, DT, 4096, 1.0), (DT, DT, 4096, -2.0)])
    with pytest.raises(ValueError, match="every recording or for none"):
        bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=4096, series=(),
                  current=[(DT, DT, 4096, 1.0), (DT, DT, 4096)])


def test_current_power_series_is_evaluated_with_its_powers():
    """No optimisation (series=(), no laser_powers): the user's power series is scored by the
    brute-force information of its recordings at their powers."""
    cur = [(DT, DT, 8192, p) for p in POWERS]
    r = bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=8192, tracking_std=2e-9,
                  series=(), current=cur)
    c = next(c for c in r.candidates if c.label == "your current design")
    assert c.laser_powers == POWERS
    se = brute_se(cur, K)
    np.testing.assert_allclose([c.predicted_se[n][0] for n in ("k", "gamma", "tracking_var")],
                               se, rtol=3e-3)


def test_design_cli_powers(capsys):
    code = main(["design", "--k", "0.5", "--radius-um", "1.53", "--max-fps", "500",
                 "--total-s", "131.072", "--tracking-nm", "2", "--target", "determinant",
                 "--series", "1", "--powers", "0.5,1,2", "--json"])
    out = capsys.readouterr().out
    assert code == 0
    doc = json.loads(out)
    assert doc["settings"]["laser_powers"] == [0.5, 1.0, 2.0]
    assert doc["best"]["label"].startswith("optimised power series")
    assert [x["laser_power_relative"] for x in doc["best"]["recordings"]] == [0.5, 1.0, 2.0]


@pytest.mark.parametrize("arg, match", [("0.5,x", "comma-separated"),
                                        ("1", "--powers takes at least 2 distinct powers")])
def test_design_cli_bad_powers(capsys, arg, match):
    code = main(["design", "--k", "0.05", "--radius-um", "1", "--max-fps", "1000",
                 "--frames", "4096", "--powers", arg])
    assert code != 0
    assert match in capsys.readouterr().err


def test_design_figure_marks_the_power_candidates(dt_tau_design):
    """The figure (one marker per candidate) still works with power series among them; their
    legend entries carry the powers in the label."""
    import matplotlib.pyplot as plt

    fig = dt_tau_design.plot()
    try:
        marks = [ln for ln in fig.axes[0].get_lines() if ln.get_gid() == "candidate"]
        assert len(marks) == len(dt_tau_design.candidates)
        assert marks[0].get_label().startswith("recommended: optimised power series 0.5/1/2 P")
    finally:
        plt.close(fig)
