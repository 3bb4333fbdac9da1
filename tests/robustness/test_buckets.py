"""Shape buckets: padded lengths are rounded up to a few bucket sizes so that recordings of
different lengths reuse compiled fits, and the padding changes no result.

Results with bucketing on are compared with bucketing off (``_problems.BUCKET_STEPS = None``:
every array padded only to the longest recording, the previous behaviour): estimates to
1e-10 relative, standard errors to 5e-8. The SEs come from the Hessian at the last Newton
iterate before the final step, and the coarse start-value grid (``_binned_args``) is cut
from the padded ordinates, so the Newton path (not the optimum) differs with the padding:
measured 1.2e-8 on gamma's SE with two recordings, 1e-9 with one.
Compilations are counted as in test_no_recompile.py.
"""

import jax
import numpy as np
import pytest
from _simconfig import DT, GAMMA
from test_no_recompile import CompileCounter

import blurtrap as bt
from blurtrap.inference import _problems
from blurtrap.inference._irregular import irregular_nll, make_irregular_args
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import bucket_length, exact_nll, make_exact_args, make_layout

STEPS = _problems.BUCKET_STEPS  # the package default (powers of two)
QUARTER = (1.0, 1.25, 1.5, 1.75)
NAMES = ("k", "gamma", "tracking_var")


@pytest.fixture
def compiles():
    counter = CompileCounter()
    jax.monitoring.register_event_duration_secs_listener(counter)
    yield counter
    jax.monitoring.unregister_event_duration_listener(counter)


@pytest.fixture
def buckets(monkeypatch):
    """``set(on)``: bucketing on (the package default) or off for this test."""
    def set_(on):
        monkeypatch.setattr(_problems, "BUCKET_STEPS", STEPS if on else None)
    return set_


def frames(n, seed, k=2e-5):
    x = bt.simulate(k, GAMMA, DT, DT, n, key=jax.random.key(seed), method="exact_frames",
                    tracking_std=2e-9)
    return np.asarray(x, dtype=np.float64).ravel()


def rec(y, **kw):
    return bt.Recording(y, frame_interval=DT, exposure=DT, **kw)


def test_bucket_length_is_a_small_set_of_sizes(monkeypatch):
    """At least n, monotone, few distinct sizes, n when off: powers of two by default (at
    most 2x padding), at most 25 % padding above 64 with quarter steps."""
    n = np.arange(1, 200_000)
    for steps, over, n_sizes in ((STEPS, 2.0, 2), (QUARTER, 1.25, 3)):
        monkeypatch.setattr(_problems, "BUCKET_STEPS", steps)
        b = np.array([bucket_length(int(v)) for v in n])
        assert np.all(b >= n) and np.all(np.diff(b) >= 0)
        assert np.all(b[n > 64] < over * n[n > 64] + 1e-9)
        assert len(np.unique(b[(n >= 50_000) & (n <= 70_000)])) == n_sizes
    assert bucket_length(65536) == 65536 and bucket_length(65537) == 81920
    monkeypatch.setattr(_problems, "BUCKET_STEPS", (1.0,))
    assert bucket_length(65537) == 131072 and bucket_length(3000) == 4096
    monkeypatch.setattr(_problems, "BUCKET_STEPS", None)
    assert bucket_length(12345) == 12345


def _compare(a, b):
    for name in NAMES:
        va, vb = getattr(a, name), getattr(b, name)
        assert abs(vb / va - 1) < 1e-10, (name, va, vb)
        ea, eb = getattr(a, name + "_err"), getattr(b, name + "_err")
        assert abs(eb / ea - 1) < 5e-8, (name + "_err", ea, eb)
    assert a.gof["dof"] == b.gof["dof"]
    assert abs(a.gof["statistic"] / b.gof["statistic"] - 1) < 1e-10


@pytest.mark.parametrize("kw, lengths", [
    ({"likelihood": "whittle"}, (11_000,)),
    ({"likelihood": "whittle", "k": "per_recording"}, (9000, 11_000)),
    ({"likelihood": "exact"}, (2600,)),
    ({"likelihood": "exact", "k": "per_recording"}, (2100, 2600)),
], ids=["whittle", "whittle, 2 recordings", "exact", "exact, 2 recordings"])
def test_bucketing_changes_no_result(buckets, kw, lengths):
    data = bt.RecordingSet([rec(frames(n, 10 + i)) for i, n in enumerate(lengths)]) \
        if len(lengths) > 1 else rec(frames(lengths[0], 10))
    out = {}
    for on in (True, False):
        buckets(on)
        out[on] = bt.calibrate(data, **kw)
    _compare(out[True], out[False])
    assert out[True].intervals.keys() == out[False].intervals.keys()
    for name, (lo, hi) in out[False].intervals.items():
        lo2, hi2 = out[True].intervals[name]
        assert abs(lo2 / lo - 1) < 1e-8 and abs(hi2 / hi - 1) < 1e-8, name
    if "f" in out[True].extras:  # residual ordinates shown without the bucket padding
        assert np.shape(out[True].extras["f"]) == np.shape(out[False].extras["f"])


@pytest.mark.parametrize("mean", ["zero", "profile", "reml"])
def test_exact_likelihood_ignores_masked_frames(buckets, mean):
    """The exact (and irregular-time) likelihood with extra masked frames equals the
    unpadded one for every mean treatment, at parameters away from the optimum; the frames
    have a large offset so that a mean leaking the padding would show."""
    recs = [rec(frames(n, 20 + n) + 3e-7) for n in (1100, 900)]  # padded to 2048 frames
    t = np.arange(700) * DT + np.random.default_rng(1).uniform(-0.1 * DT, 0.1 * DT, 700)
    jit = [bt.Recording(frames(700, 5) + 3e-7, frame_interval=float(np.median(np.diff(t))),
                        exposure=0.5 * DT, times=t, allow_irregular=True)]
    model = get_model("standard")
    p = np.array([2.4e-5, 1.1 * GAMMA, 3e-18])
    for data, make, nll in ((recs, make_exact_args, exact_nll),
                            (jit, make_irregular_args, irregular_nll)):
        layout = make_layout(data, "shared", True)
        vals = {}
        for on in (True, False):
            buckets(on)
            a = make(data, layout, model, mean=mean)
            vals[on] = (float(nll(p, a)), a.ys.shape[1])
        assert vals[True][1] > vals[False][1]  # padding was added
        assert abs(vals[True][0] / vals[False][0] - 1) < 1e-12, (make.__name__, vals)


@pytest.mark.parametrize("kw, n_a, n_b, n_c", [
    ({"likelihood": "whittle"}, 9000, 12_000, 17_000),  # 8192 ordinates; 16384
    ({"likelihood": "exact"}, 2600, 3900, 4200),  # 4096 frames; 8192
], ids=["whittle", "exact"])
def test_new_length_in_the_same_bucket_does_not_recompile(compiles, buckets, kw, n_a, n_b,
                                                          n_c):
    """A second recording of another length in the same bucket compiles nothing; one in the
    next bucket does (the counter can fail)."""
    buckets(True)
    ya, yb, yc = frames(n_a, 1), frames(n_b, 2, k=3e-5), frames(n_c, 3)
    bt.calibrate(rec(ya), **kw)
    compiles.reset()
    res = bt.calibrate(rec(yb), **kw)
    assert compiles.names == [], compiles.names
    assert res.converged and abs(res.k / 3e-5 - 1) < 5 * res.k_err / 3e-5
    bt.calibrate(rec(yc), **kw)
    assert compiles.names != []
