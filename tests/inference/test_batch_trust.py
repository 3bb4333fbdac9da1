"""calibrate_batch applies calibrate's checks, refusals and goodness of fit per item.

Clean inputs are built without blurtrap's simulator: the exact AR(1) recursion
x_{n+1} = rho x_n + sqrt(sigma2 (1 - rho^2)) z of the trapped bead sampled instantaneously
(exposure 1e-9 dt, i.e. W ~ 0), plus white tracking noise. The unidentifiable camera case
(W = dt, dt/tau = 12) uses the package's exact frame sampler for the blur.
"""

import json
import math

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.data import _recording
from blurtrap.inference import FitError, _batch_checks
from blurtrap.inference._frames import temporal_information

DT = 1 / 1500
W0 = DT * 1e-9  # (almost) instantaneous sampling: the AR(1) frames below
GAMMA = 6 * math.pi * 9.5e-4 * 0.765e-6
KT = 1.380649e-23 * 295.0
K = 0.5 * GAMMA / DT  # dt/tau = 0.5: k, gamma and eps^2 well identified
N = 32768  # > 2^14 frames: calibrate's default is then the Whittle likelihood too


def ar1(k, n, b, *, eps=2e-9, seed=0, dt=DT):
    """``b`` exact OU frames (instantaneous sampling) plus white noise of std ``eps`` [m]."""
    rng = np.random.default_rng(seed)
    tau, s2 = GAMMA / k, KT / k
    rho = math.exp(-dt / tau)
    x = np.empty((b, n))
    x[:, 0] = rng.normal(0.0, math.sqrt(s2), b)
    z = rng.normal(0.0, math.sqrt(s2 * (1 - rho * rho)), (b, n))
    for i in range(1, n):
        x[:, i] = rho * x[:, i - 1] + z[:, i]
    return x + eps * rng.normal(size=(b, n))


@pytest.fixture(scope="module")
def mixed():
    """Rows 0, 2, 4, 6 clean; 1 in nm; 3 with a NaN at frame 17; 5 with a 30 nm, 50 Hz line."""
    x = ar1(K, N, 7, seed=1)
    x[1] *= 1e9
    x[3, 17] = np.nan
    x[5] += 30e-9 * np.sin(2 * np.pi * 50.0 * np.arange(N) * DT)
    return x, bt.calibrate_batch(x, frame_interval=DT, exposure=W0)


CLEAN = [0, 2, 4, 6]


def test_bad_rows_get_their_own_status(mixed):
    _, b = mixed
    assert b.status[1].startswith("invalid: positions look like nm or pixels, not m")
    assert b.status[3] == "invalid: NaN at frame 17"
    assert b.status[5].startswith("inadequate: goodness of fit p ")
    assert "line at 49.9" in b.status[5] or "line at 50" in b.status[5], b.status[5]
    for i in (1, 3, 5):
        assert not b.success[i]
        for v in (b.k, b.k_err, b.gamma, b.gamma_err, b.tracking_var, b.tracking_var_err):
            assert np.isnan(v[i])
    assert b.gof_p[5] < 1e-9 and np.isnan(b.gof_p[1]) and np.isnan(b.gof_p[3])
    assert list(b.status[CLEAN]) == ["ok"] * 4 and b.success[CLEAN].all()
    json.dumps(b.to_dict())  # NaN values and the new fields serialise


def test_clean_rows_equal_a_batch_of_only_clean_rows(mixed):
    x, b = mixed
    rows = CLEAN + CLEAN[:3]  # the same batch shape (no new compilation), clean rows only
    c = bt.calibrate_batch(x[rows], frame_interval=DT, exposure=W0)
    assert list(c.status) == ["ok"] * 7
    for name in ("k", "k_err", "gamma", "gamma_err", "tracking_var", "tracking_var_err",
                 "gof_p", "gof_statistic", "lag1_z"):
        np.testing.assert_allclose(getattr(c, name)[:4], getattr(b, name)[CLEAN], rtol=1e-10,
                                   err_msg=name)


def test_clean_rows_agree_with_calibrate(mixed):
    """k within 0.1 SE of calibrate's on the same row (here the same Whittle fit: 1e-7), the
    goodness of fit equal to calibrate's result.gof, and honest against the truth."""
    x, b = mixed
    for i in CLEAN[:2]:
        one = bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=W0))
        assert abs(b.k[i] - one.k) < 0.1 * one.k_err
        assert abs(b.gamma[i] - one.gamma) < 0.1 * one.gamma_err
        assert b.gof_dof == one.gof["dof"]
        assert abs(b.gof_p[i] - one.gof["p_value"]) < 1e-6
        assert abs(b.gof_statistic[i] / one.gof["statistic"] - 1) < 1e-6
        assert abs(b.k[i] - K) < 5 * b.k_err[i]


def test_unidentifiable_items_are_refused_like_calibrate():
    """A stiff trap on a slow camera (W = dt, dt/tau = 12) with 2 nm tracking noise: the
    frames carry no temporal information. calibrate refuses every row; the batch must refuse
    every item (the old batch returned 77/200 "ok" with k a median 33x the truth)."""
    k = 12 * GAMMA / DT
    x = np.asarray(bt.simulate(k, GAMMA, DT, DT, 4096, key=jax.random.key(3),
                               method="exact_frames", tracking_std=2e-9, n_traces=200))
    x = x.reshape(200, 4096)
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=DT)
    assert all(s.startswith("refused: no temporal information") for s in b.status), \
        np.unique(b.status)
    assert not b.success.any() and np.isnan(b.k).all() and np.isnan(b.k_err).all()
    for i in range(3):
        with pytest.raises(FitError, match="cannot identify gamma"):
            bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=DT))


def test_empty_batch_is_a_clear_error():
    with pytest.raises(ValueError, match="no records"):
        bt.calibrate_batch(np.zeros((0, 4096)), frame_interval=DT, exposure=DT)


@pytest.mark.parametrize("model", ["standard+drift", "blur+line_noise"])
def test_a_model_with_effects_is_a_clear_error(model):
    """The batch fits the core models; a model with effects was a raw KeyError from inside
    the compiled fit."""
    x = ar1(K, 4096, 2, seed=4)
    with pytest.raises(ValueError, match=r"calibrate_batch fits the core models.*"
                       + model.split("+")[1] + r".*calibrate"):
        bt.calibrate_batch(x, frame_interval=DT, exposure=DT, model=model)


def test_inf_row_and_shared_unit_slips():
    x = ar1(K, 4096, 2, seed=4)
    x[0, 5] = -np.inf
    x[0, 9] = np.nan
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=W0)
    assert b.status[0] == "invalid: inf at frame 5 (2 non-finite values)"
    assert b.status[1] == "ok"
    with pytest.raises(ValueError, match="Celsius"):
        bt.calibrate_batch(x, frame_interval=DT, exposure=W0, temperature=22.0)
    with pytest.raises(ValueError, match="looks like ms"):
        bt.calibrate_batch(x, frame_interval=1.5, exposure=1e-3)


def test_checks_are_calibrates():
    """The thresholds are Recording's and temporal_information's; the per-row z is
    temporal_information's z."""
    assert _batch_checks.MAX_POSITION_STD_M == _recording._MAX_PLAUSIBLE_POSITION_STD_M
    assert _batch_checks.MAX_INTERVAL_S == _recording._MAX_PLAUSIBLE_INTERVAL_S
    assert _batch_checks.MIN_TEMPERATURE_K == _recording._MIN_PLAUSIBLE_TEMPERATURE_K
    assert _batch_checks.Z_MIN == 5.0
    x = ar1(K, 1000, 3, seed=5)
    x[1] = ar1(60 * GAMMA / DT, 1000, 1, seed=6)[0]  # dt >> tau: z ~ 0
    z = _batch_checks.row_stats(x)[:, 5]
    for i in range(3):
        r = bt.Recording(x[i], frame_interval=DT, exposure=W0)
        assert abs(z[i] - temporal_information(r)[1]) < 1e-9 * max(1.0, abs(z[i]))
    with pytest.raises(ValueError, match="look like nm"):
        bt.Recording(x[0] * 1e9, frame_interval=DT, exposure=W0)
    st = _batch_checks.prefit_status(_batch_checks.row_stats(np.stack([x[0] * 1e9, x[1]])),
                                     True)
    assert st[0].startswith("invalid: positions look like nm") and st[1].startswith("refused")


def test_false_alarm_rate_of_the_goodness_of_fit():
    """400 honest items (4096 frames, 29 dof): none inadequate at the default threshold
    1e-4 (expected 0.04; P(>= 2) ~ 1e-3), and the p-values are calibrated: the number
    below 0.05 is Binomial(400, 0.05) (mean 20, SD 4.4; allowed 6-36)."""
    x = ar1(K, 4096, 400, seed=7)
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=W0)
    flagged = sum(s.startswith("inadequate") for s in b.status)
    assert flagged <= 1
    assert (b.status == "ok").sum() >= 399
    assert 6 <= (b.gof_p < 0.05).sum() <= 36


def test_at_bound_flags_items_with_eps2_held_at_zero():
    """Without tracking noise the fit holds eps^2 at 0 in about half the items; those are
    flagged (their k error is conditional on eps^2 = 0), as calibrate's result.at_bounds."""
    x = ar1(K, N, 7, eps=0.0, seed=8)  # the fixture's shape: no new compilation
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=W0)
    assert b.success.all()
    assert b.at_bound.any() and not b.at_bound.all()
    assert b.at_bound[np.isnan(b.tracking_var_err)].all()
    for i in range(7):
        one = bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=W0))
        assert b.at_bound[i] == ("tracking_var" in one.at_bounds), i


def test_blocked_psd_items_get_calibrates_goodness_of_fit():
    """n_blocks > 1 (Gamma likelihood of block averages): the same p-value as
    calibrate(method='psd', n_blocks=8), and a 50 Hz line is still found."""
    n = 16384
    x = ar1(K, n, 3, seed=21)
    x[2] += 30e-9 * np.sin(2 * np.pi * 50.0 * np.arange(n) * DT)
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=W0, n_blocks=8)
    assert list(b.status[:2]) == ["ok", "ok"]
    assert b.status[2].startswith("inadequate") and "line at 4" in b.status[2], b.status[2]
    for i in range(2):
        one = bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=W0), method="psd",
                           n_blocks=8)
        assert abs(b.k[i] / one.k - 1) < 1e-8
        assert b.gof_dof == one.gof["dof"] and abs(b.gof_p[i] - one.gof["p_value"]) < 1e-6


def test_clipped_and_coarsely_quantised_rows_are_refused_like_calibrate():
    # a detector saturating at +1.5 std, and positions rounded to 30 nm (std 20 nm):
    # calibrate refuses both; so must the batch, item by item
    x = ar1(K, 8192, 3, seed=4)
    sd = float(np.std(x[0]))
    x[1] = np.minimum(x[1], 1.5 * sd)
    x[2] = np.round(x[2] / 30e-9) * 30e-9
    for i in (1, 2):
        with pytest.raises(ValueError, match="saturated|quantised"):
            bt.calibrate(bt.Recording(x[i], frame_interval=DT, exposure=W0))
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=W0)
    assert b.status[0] == "ok"
    assert b.status[1].startswith("refused: item 1") and "saturated (clipped)" in b.status[1]
    assert b.status[2].startswith("refused: item 2") and "quantised in steps" in b.status[2]
    assert np.isnan(b.k[1]) and np.isnan(b.k[2])


def test_refusals_number_items_across_the_whole_batch():
    # rows are checked in blocks (16 on the host, 64 per fitted chunk): a refusal must name
    # the item's index in the whole batch, not within its block (it was chunk-local)
    x = ar1(K, 2048, 70, seed=6)
    for i in (3, 67):
        x[i] = np.minimum(x[i], 1.2 * float(np.std(x[i])))
    b = bt.calibrate_batch(x, frame_interval=DT, exposure=W0)
    for i in (3, 67):
        assert b.status[i].startswith(f"refused: item {i} "), b.status[i]
    assert sum(s.startswith("refused") for s in b.status) == 2


def test_rows_in_another_unit_in_the_plausible_std_range_are_named():
    """Positions in mm (std ~5 um, under the 10 um check) came back "ok" with k and gamma
    1e-6 x the truth, and 1000 x too small ones "ok" with 1e6 x (a sixth independent pass);
    calibrate notes the first and refuses the second. Now: "implausible" (values kept) and
    "invalid". A stiff trap (std 4.5 nm) sampled at dt = tau / 2."""
    k = 2e-4
    dt = 0.5 * GAMMA / k
    x = ar1(k, 8192, 3, seed=9, dt=dt, eps=0.2e-9)
    kw = dict(frame_interval=dt, exposure=1e-9 * dt)
    mm = bt.calibrate_batch(x * 1e3, **kw)
    assert all(s.startswith("implausible: ") and "gamma = " in s
               and "check the position unit" in s for s in mm.status), mm.status
    assert np.allclose(mm.k / k, 1e-6, rtol=0.3) and not mm.success.any()
    tiny = bt.calibrate_batch(x * 1e-3, **kw)
    assert all(s.startswith("invalid: positions far too small") for s in tiny.status)
    ok = bt.calibrate_batch(x, **kw)
    assert ok.success.all(), ok.status
    assert bt.calibrate_batch(x * 1e3, **kw, check_units=False).success.all()
