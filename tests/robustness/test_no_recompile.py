"""No recompilation on repeated calls with new data of the same shapes (and determinism of the
repeated call).

XLA compilations are counted with ``jax.monitoring``: every executable JAX builds or loads
(from the in-memory miss path, including persistent-cache loads) records the event
``/jax/core/compile/backend_compile_duration`` with the function name. Each test warms a
public function up on data A, repeats the call on A (the result must be identical to the
byte: determinism, with ``np.random.seed`` changed in between and the global numpy RNG state
left untouched), then calls it on new data B of the same shapes and asserts that nothing was
compiled.
"""

import json
import warnings

import jax
import numpy as np
import pytest
from _simconfig import DT, GAMMA, sim

import blurtrap as bt
from blurtrap.inference import _screen_fit, _screen_stacked


def test_counter_sees_compilations(compiles):
    """The counter must be able to fail: a fresh jitted function compiles once per shape."""
    f = jax.jit(lambda x: x * 3.0 + 1.0)
    f(np.ones(3))
    assert len(compiles.names) == 1
    compiles.reset()
    f(np.full(3, 2.0))
    assert compiles.names == []
    f(np.ones(4))
    assert len(compiles.names) == 1


def camera(k, n_frames, seed, n_traces=1):
    x = bt.simulate(k, GAMMA, DT, DT, n_frames, key=jax.random.key(seed), method="exact_frames",
                    tracking_std=2e-9, n_traces=n_traces)
    return np.asarray(x, dtype=np.float64).reshape(n_traces, n_frames)


def rec(y):
    return bt.Recording(y, frame_interval=DT, exposure=DT)


def _repeat_is_identical(fn, data, dump):
    """Call twice with a different global numpy seed in between; identical bytes, global RNG
    state untouched."""
    np.random.seed(10)
    state = np.random.get_state()[1].copy()
    first = dump(fn(data))
    assert np.array_equal(np.random.get_state()[1], state)
    np.random.seed(20)
    assert dump(fn(data)) == first


def _dump_result(res):
    return json.dumps(res.to_dict(), sort_keys=True)  # floats as repr: exact


# ---- simulate ---------------------------------------------------------------------------------
SIM_SETTINGS = [
    ("exact_frames", dict(method="exact_frames")),
    ("exact, fixed substeps", dict(method="exact", substeps=8)),
]


@pytest.mark.parametrize("kw", [s[1] for s in SIM_SETTINGS], ids=[s[0] for s in SIM_SETTINGS])
def test_simulate_new_key_and_parameters_no_recompile(compiles, kw):
    sim(jax.random.key(0), **kw)
    compiles.reset()
    sim(jax.random.key(1), **kw)
    sim(jax.random.key(2), k=7e-5, gamma=2 * GAMMA, exposure=3e-4, frame_interval=2 * DT,
        tracking_std=3e-9, temperature=300.0, **kw)
    assert compiles.names == []


def test_simulate_auto_substeps_new_parameters_no_recompile(compiles):
    """substeps=None rounds the automatic substep count (a static scan length) up to a power
    of two: k = 3e-5 and 8e-5 N/m (alpha = W k/gamma = 0.11 and 0.30, raw counts 5 and 8)
    share the bucket of 8 substeps and must not recompile; k = 1.2e-4 (raw count 10, bucket
    16) must, which shows the counter sees the scan length."""
    bt.simulate(3e-5, GAMMA, 1e-4, DT, 1024, key=jax.random.key(0))
    compiles.reset()
    bt.simulate(8e-5, GAMMA, 1e-4, DT, 1024, key=jax.random.key(1))
    assert compiles.names == []
    bt.simulate(1.2e-4, GAMMA, 1e-4, DT, 1024, key=jax.random.key(2))
    assert compiles.names != []


# ---- calibrate ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "n_frames, kw",
    [(16384, {}), (16384, {"likelihood": "exact"}), (16384, {"likelihood": "whittle"})],
    ids=["default (exact at 16384 frames)", "likelihood=exact", "likelihood=whittle"],
)
def test_calibrate_deterministic_and_no_recompile(compiles, n_frames, kw):
    ya, yb = camera(2e-5, n_frames, 1)[0], camera(3e-5, n_frames, 2)[0]
    _repeat_is_identical(lambda y: bt.calibrate(rec(y), **kw), ya, _dump_result)
    compiles.reset()
    res = bt.calibrate(rec(yb), **kw)
    assert compiles.names == [], compiles.names
    assert res.converged and abs(res.k / 3e-5 - 1) < 5 * res.k_err / 3e-5


def test_calibrate_batch_deterministic_and_no_recompile(compiles):
    ya, yb = camera(2e-5, 4096, 3, n_traces=4), camera(3e-5, 4096, 4, n_traces=4)
    run = lambda y: bt.calibrate_batch(y, frame_interval=DT, exposure=DT)  # noqa: E731
    _repeat_is_identical(run, ya, lambda b: json.dumps(b.to_dict(), sort_keys=True, default=str))
    compiles.reset()
    out = run(yb)
    assert compiles.names == [], compiles.names
    assert np.all(out.success)


# ---- sample_posterior -----------------------------------------------------------------------------
def _post(y, seed=0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bt.ShortChainWarning)
        return bt.sample_posterior(rec(y), n_steps=20, seed=seed)


def _dump_post(p):
    return b"".join(np.asarray(p.samples[k]).tobytes() for k in sorted(p.samples)) + \
        np.asarray(p.chain).tobytes() + np.asarray(p.log_prob).tobytes()


def test_sample_posterior_deterministic_and_no_recompile(compiles):
    ya, yb = camera(2e-5, 16384, 5)[0], camera(3e-5, 16384, 6)[0]
    _repeat_is_identical(_post, ya, _dump_post)
    assert _dump_post(_post(ya, seed=1)) != _dump_post(_post(ya, seed=0))  # the seed matters
    compiles.reset()
    _post(yb)  # maximum-likelihood start + both walker-batch shapes of the log-posterior
    assert compiles.names == [], compiles.names


# ---- diagnose ---------------------------------------------------------------------------------
def test_diagnose_new_record_of_the_same_bucket_no_recompile(compiles):
    """diagnose screens a line at each record's most significant spike with the width of its
    frequency resolution 1/T: a second record of another length in the same padded bucket
    (40 000 and 50 000 frames: 32 768 ordinates; widths 1/T differ) compiles nothing. With the
    line's frequency and width static in the model, each record compiled the screening fit
    again (2.2 s measured)."""
    y = camera(5e-5, 50_000, 7)[0]
    bt.diagnose(rec(y[:40_000]))
    compiles.reset()
    d = bt.diagnose(rec(y))
    assert compiles.names == [], compiles.names
    assert "line_noise" in {r.effect for r in d.ranking}


@pytest.mark.parametrize("detector", ["camera", "photodiode"])
def test_diagnose_record_in_a_new_bucket_compiles_no_screening_fit(compiles, monkeypatch,
                                                                   detector):
    """diagnose's screening fits (``fit_nll_only``) run the chunked Newton loop where it
    applies, and BFGS on stacked ordinate chunks for the models folded on nodes
    (``_screen_stacked``: the photodiode's detector_filter and hydrodynamics): after 40 000
    samples (32 768 padded ordinates), a record of 70 000 (65 536) compiles none of their
    programs. As BFGS on the padded ordinates (``_screen_fit.SCREEN_CHUNKED = False``,
    ``_screen_stacked.STACKED = False``) they are compiled per padded length (2.6 s per
    candidate measured at 2^17 frames, 3-5 s per folded one): the check can fail. Both ways
    give the same screening minima (delta log-likelihoods to 5e-3: two BFGS runs that may
    stop at different points of detector_filter's flat valley; equal to 1e-3 here)."""
    if detector == "camera":
        y, make = camera(5e-5, 70_000, 8)[0], rec
    else:
        y = np.asarray(bt.simulate(5e-5, GAMMA, 1e-8, 1e-5, 70_000, key=jax.random.key(9),
                                   method="exact_frames", tracking_std=2e-9))[0]

        def make(z):
            return bt.Recording(z, frame_interval=1e-5, exposure=1e-8)

    programs = ("_bfgs", "_chunk_pass", "_update", "_start", "_finish", "_newton", "_coarse")
    ranks = {}
    for fixed in (True, False):
        monkeypatch.setattr(_screen_fit, "SCREEN_CHUNKED", fixed)
        monkeypatch.setattr(_screen_stacked, "STACKED", fixed)
        bt.diagnose(make(y[:40_000]))
        compiles.reset()
        d = bt.diagnose(make(y))
        got = [n for n in compiles.names if any(p in n for p in programs)]
        assert (got == []) == fixed, compiles.names
        ranks[fixed] = {r.effect: r.delta_loglik for r in d.ranking
                        if r.delta_loglik is not None}
    if detector == "photodiode":
        assert {"detector_filter", "hydrodynamics"} <= set(ranks[True])
    assert ranks[True].keys() == ranks[False].keys()
    for name, dl in ranks[True].items():
        assert dl == pytest.approx(ranks[False][name], abs=5e-3), name


def test_design_compiles_its_optimiser_once_for_every_series_and_budget(compiles):
    """bt.design's optimiser is one program for exposure series of 1 to 3 recordings, frames
    per recording or a total time, and photon-limited noise or not; the candidates'
    evaluation one program for a single stiffness or a range (before: one optimiser per
    series length and budget kind, 6-7 s of compilation and ~10 s of tracing each)."""
    common = {"radius": 1.53e-6, "max_fps": 1500.0, "tracking_std": 2e-9}
    bt.design(k=5e-5, total_time=60.0, series=(1,), **common)
    compiles.reset()
    res = bt.design(k=1e-4, n_frames=65536, series=(1, 2, 3), photon_limited=True,
                    laser_powers=(0.5, 1.0), **common)
    assert [c for c in res.candidates if c.label.startswith("optimised series of 3")]
    again = [n for n in compiles.names if n.startswith(
        ("jit(_minimise_all", "jit(_informations", "jit(_evaluate"))]
    assert again == []
    bt.design(k=(2e-5, 2e-4), n_frames=65536, series=(1,), **common)
    compiles.reset()
    bt.design(k=(5e-5, 5e-4), total_time=30.0, series=(2, 3), **common)
    assert [n for n in compiles.names if n.startswith(("jit(_minimise_all", "jit(_evaluate"))] == []


def _power_set(powers, seed, n_frames=4096):
    ys = camera(5e-5, n_frames, seed, n_traces=len(powers))
    return [bt.Recording(y, frame_interval=DT, exposure=DT, laser_power=p) for y, p in zip(ys, powers)]


@pytest.mark.parametrize("kw", [dict(likelihood="whittle"), dict(method="psd", n_blocks=4),
                                dict(likelihood="exact")])
def test_a_new_set_of_laser_powers_compiles_nothing_and_keeps_its_labels(compiles, kw):
    """k per power: a second trap at other laser powers (the k labels ``k[P=12 mW]`` are
    static fields of the layout) reuses the compiled fit, and every name in the result is
    its own powers', not the first set's."""
    first = bt.calibrate(_power_set((0.01, 0.02, 0.04), 1), k="per_power", **kw)
    assert first.param_names[:3] == ("k[P=10 mW]", "k[P=20 mW]", "k[P=40 mW]")
    compiles.reset()
    res = bt.calibrate(_power_set((0.012, 0.025, 0.05), 2), k="per_power", **kw)
    assert compiles.names == [], compiles.names
    labels = ("k[P=12 mW]", "k[P=25 mW]", "k[P=50 mW]")
    assert res.param_names[:3] == labels
    assert tuple(res.to_dict()["param_names"])[:3] == labels
    assert set(labels) <= set(res.intervals)
    assert all(lab in res.summary() for lab in labels)
    assert not any(old in res.summary() + " ".join(res.notes) for old in ("P=10 mW", "P=20 mW", "P=40 mW"))
