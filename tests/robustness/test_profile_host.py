"""Profile-likelihood intervals with their loops on the host over the chunked passes
(``inference/_profile_host.py``): the same end points as the single compiled program
(``_profile._profile_ends``), and a recording of a new length compiles no interval program.

The compiled program is the reference here; it is checked against independent profiles and
by coverage in tests/inference/test_boundary.py and benchmarks/RESULTS_boundary.md."""

import _irregular_gen as gen
import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference import _profile, _profile_host

DT = 1.0 / 1500.0
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6
#: interval programs: the compiled profile and Wald-path programs, and the host loops' pieces
PROGRAMS = ("_profile_ends", "_wald_path_roots", "_chunk_pass", "_chunk_jvp", "_update",
            "_start", "_finish", "value_and_grad", "pass_fn")


def frames(n, seed, w=0.1, eps=0.0):
    """Frames of a camera at exposure ``w`` dt with tracking error ``eps`` (m); at w = 0.1
    and eps = 0, eps^2 ends at or near its bound: every interval is profiled."""
    x = bt.simulate(2e-5, GAMMA, w * DT, DT, n, key=jax.random.key(seed),
                    method="exact_frames", tracking_std=eps)
    return np.asarray(x, dtype=np.float64).ravel()


def rec(y, w=0.1):
    return bt.Recording(y, frame_interval=DT, exposure=w * DT)


def jittered(n, seed):
    """Frames at irregular times (a wandering clock, intervals dt (1 + 0.05 N(0, 1))) from the
    dense OU covariance (tests/_irregular_gen.py), W = 0.1 dt, no tracking error."""
    rng = np.random.default_rng(seed)
    s = gen.clock("wander", n, DT, 0.05, rng)
    y = gen.frames(s, 0.1 * DT, 2e-5, GAMMA, 295.0, 0.0, rng)
    return bt.Recording(y, frame_interval=float(np.median(np.diff(s))), times=s,
                        exposure=0.1 * DT, allow_irregular=True)


CASES = {
    "whittle": (lambda: rec(frames(20_000, 3)), {}),
    "exact": (lambda: rec(frames(3000, 4)), {"likelihood": "exact"}),
    "exact, gamma held": (lambda: rec(frames(4000, 5, 1.0, 2e-9), 1.0),
                          {"likelihood": "exact", "fixed": {"gamma": GAMMA}}),
    "irregular": (lambda: jittered(1500, 7), {"likelihood": "exact"}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_host_profile_equals_the_compiled_program(monkeypatch, case):
    """Host loops over the chunked pass vs the one compiled program (``_profile_host.HOST`` off):
    the same kinds and end points to 1e-8 relative (measured 1e-12 to 1e-9)."""
    make, kw = CASES[case]
    data = make()
    out = {}
    calls = []
    host_ends = _profile.host_profile_ends
    monkeypatch.setattr(_profile, "host_profile_ends",
                        lambda *a: calls.append(1) or host_ends(*a))
    for host in (True, False):
        monkeypatch.setattr(_profile_host, "HOST", host)
        calls.clear()
        res = bt.calibrate(data, **kw)
        out[host] = (res.intervals, res.interval_kinds)
        assert bool(calls) == host  # the host loops ran, and only with HOST on
    assert out[True][1] == out[False][1]
    assert "profile" in out[True][1].values()
    for name, (lo, hi) in out[False][0].items():
        got = out[True][0][name]
        assert np.all(np.isfinite([lo, hi, *got])), (name, got, (lo, hi))
        np.testing.assert_allclose(got, (lo, hi), rtol=1e-8, atol=1e-300, err_msg=name)


@pytest.mark.parametrize("likelihood, n_first, n_new, check_off", [
    ("exact", 3000, 5000, False), ("whittle", 20_000, 40_000, True)])
def test_new_length_compiles_no_interval_program(compiles, monkeypatch, likelihood, n_first,
                                                 n_new, check_off):
    """After a first calibration with profiled intervals, a recording in a new bucket
    compiles no interval program; with the host profile off (one compiled program per padded
    length) the same sequence compiles ``_profile_ends`` again (the check can fail: shown on
    the Whittle case; compiling the exact likelihood's program twice would add ~35 s)."""
    y = frames(n_new, 6)
    kw = {"likelihood": likelihood}
    for host, expect_none in ((True, True), (False, False))[:2 if check_off else 1]:
        monkeypatch.setattr(_profile_host, "HOST", host)
        jax.clear_caches()
        first = bt.calibrate(rec(y[:n_first]), **kw)
        assert "profile" in first.interval_kinds.values()
        res = bt.calibrate(rec(y[:n_new]), **kw)
        compiles.reset()
        kinds = res.interval_kinds
        assert "profile" in kinds.values()
        lo, hi = res.intervals["k"]
        assert lo < 2e-5 < hi or abs(res.k / 2e-5 - 1) < 5 * res.k_err / 2e-5
        got = [n for n in compiles.names if any(p in n for p in PROGRAMS)]
        assert (got == []) == expect_none, compiles.names
