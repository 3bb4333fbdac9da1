"""How much work the exact likelihood's interval step does (benchmarks/RESULTS.md "Profile
intervals": a joint per-power fit of four recordings, 122 880 frames, spent 180-310 s in
``res.intervals``): each recording runs through its own frame chunks, to its own last frame;
the Wald-path check evaluates its 2n points and the estimate in one sweep over the frames;
only the parameters that need a profile interval are profiled. Counted, not timed: calls of
the chunk program and root finds; the numbers stay those of the previous way."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simconfig import DT, GAMMA, frames, rec

import blurtrap as bt
from blurtrap.inference import _exact_chunks, _profile, _profile_host
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import exact_nll, make_exact_args, make_layout

LENGTHS = (2600, 5000)  # 1 and 2 chunks of 4096 frames; padded together, 2 chunks each


def _joint():
    recs = [rec(frames(n, 60 + i, k)) for i, (n, k) in enumerate(zip(LENGTHS, (2e-5, 4e-5)))]
    layout = make_layout(recs, "per_recording", True)
    args = make_exact_args(recs, layout, get_model("standard"), mean="reml")
    return args, jnp.asarray([2e-5, 4e-5, GAMMA, 4e-18])


@pytest.fixture
def chunk_calls(monkeypatch):
    """The recordings (axis 1 of the points' parameters) of every chunk-program call."""
    calls = []
    run = _exact_chunks._chunk_jvp

    def counted(theta, *a):
        calls.append(theta.shape[1])
        return run(theta, *a)

    monkeypatch.setattr(_exact_chunks, "_chunk_jvp", counted)
    return calls


def test_each_recording_runs_to_its_own_last_frame(chunk_calls):
    """One pass: 1 + 2 chunk calls of one recording each (before: 2 calls of both
    recordings, the shorter one's second chunk all padding)."""
    args, scale = _joint()
    _exact_chunks.exact_chunk_pass(exact_nll, args, 1e-4)(jnp.zeros(4), scale)
    assert chunk_calls == [1, 1, 1]


def test_wald_path_in_one_sweep(chunk_calls):
    """The signed roots at the Wald ends of a joint fit from one sweep at the 2n + 1 points
    equal those of a pass per point (2n + 1 passes: 9 sweeps here)."""
    recs = [rec(frames(n, 60 + i, k)) for i, (n, k) in enumerate(zip(LENGTHS, (2e-5, 4e-5)))]
    src = bt.calibrate(recs, likelihood="exact", k="per_recording").interval_source
    assert src.value.size == 4
    args = (src.nll, src.args)
    pass_fn = _profile_host.chunked_pass(*args, "fd", 1e-4)
    values = _profile_host.chunked_values(*args, "fd")
    assert _profile_host.chunked_values(*args, "auto") is None
    chunk_calls.clear()
    swept = _profile_host.wald_path_roots(pass_fn, src.scale, src.value, src.cov, _profile.Z95,
                                          values)
    assert len(chunk_calls) == 3
    one_by_one = _profile_host.wald_path_roots(pass_fn, src.scale, src.value, src.cov,
                                               _profile.Z95)
    assert len(chunk_calls) == 3 + 9 * 3
    for got, want in zip(swept, one_by_one):
        assert np.all(np.abs(want - 1.96) < 0.2), want
        np.testing.assert_allclose(got, want, rtol=1e-9)


def test_only_the_needed_parameters_are_profiled(monkeypatch):
    """With only k needing a profile interval, two root finds run (before: six, one per end
    of every parameter), and k's interval is the one every end computed gives."""
    x = bt.simulate(2e-5, GAMMA, 0.1 * DT, DT, 3000, key=jax.random.key(4),
                    method="exact_frames", tracking_std=0.0)
    res = bt.calibrate(bt.Recording(np.asarray(x, float).ravel(), frame_interval=DT,
                                    exposure=0.1 * DT), likelihood="exact")
    assert set(res.interval_kinds.values()) == {"profile"}  # eps^2 at its bound: all three
    finds = []
    run = _profile_host._root_find

    def counted(*a):
        finds.append(a[5])
        return run(*a)

    monkeypatch.setattr(_profile_host, "_root_find", counted)
    monkeypatch.setattr(_profile, "needs_profile", lambda *a, **kw: np.array([True, False, False]))
    ivs, kinds = res.interval_source(res)
    assert finds == [0, 0] and kinds == {"k": "profile"}
    np.testing.assert_allclose(ivs["k"], res.intervals["k"], rtol=1e-12)
