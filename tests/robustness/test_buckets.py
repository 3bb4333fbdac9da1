"""Shape buckets: padded lengths are rounded up to a few bucket sizes so that recordings of
different lengths reuse compiled fits, and the padding changes no result.

Results with bucketing on are compared with bucketing off (``_problems.BUCKET_STEPS = None``:
every array padded only to the longest recording, the previous behaviour): estimates to
1e-10 relative, standard errors to 5e-8. The SEs come from the Hessian at the last Newton
iterate before the final step, and the coarse start-value grid (``_binned_args``) is cut
from the padded ordinates, so the Newton path (not the optimum) differs with the padding:
measured 1.2e-8 on gamma's SE with two recordings, 1e-9 with one.
Compilations are counted as in test_no_recompile.py.

The default Whittle fit runs in fixed-size ordinate chunks with its Newton loop on the host
(``_chunked``), so a new bucket compiles none of its programs once a recording of two chunks
was fitted: checked against the single compiled Newton loop (``_chunked.CHUNK = None``) and
against JAX autodiff of the whole objective.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simconfig import DT, GAMMA, assert_chunk_sums_are_the_whole, frames, rec

import blurtrap as bt
from blurtrap.inference import _chunked, _problems
from blurtrap.inference._irregular import irregular_nll, make_irregular_args
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import (
    _spectral_nll,
    bucket_length,
    exact_nll,
    make_exact_args,
    make_layout,
    spectral_nll,
)
from blurtrap.inference._spectral import _spectral_args
from blurtrap.inference._whittle_pass import _binned_args

STEPS = _problems.BUCKET_STEPS  # the package default (powers of two)
QUARTER = (1.0, 1.25, 1.5, 1.75)
NAMES = ("k", "gamma", "tracking_var")



@pytest.fixture
def buckets(monkeypatch):
    """``set(on)``: bucketing on (the package default) or off for this test."""
    def set_(on):
        monkeypatch.setattr(_problems, "BUCKET_STEPS", STEPS if on else None)
    return set_


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
    next bucket does (the counter can fail). The caches are cleared first: the exact fit
    compiles no fit program for a new bucket (frame chunks, test_exact_chunks.py), so what
    the next bucket compiles (eager ops at its shape) must not come from other tests."""
    buckets(True)
    jax.clear_caches()
    ya, yb, yc = frames(n_a, 1), frames(n_b, 2, k=3e-5), frames(n_c, 3)
    bt.calibrate(rec(ya), **kw)
    compiles.reset()
    res = bt.calibrate(rec(yb), **kw)
    assert compiles.names == [], compiles.names
    assert res.converged and abs(res.k / 3e-5 - 1) < 5 * res.k_err / 3e-5
    bt.calibrate(rec(yc), **kw)
    assert compiles.names != []


# ------------------------------------------------------------------------------------------
# The default Whittle fit in fixed-size ordinate chunks (blurtrap.inference._chunked)
# ------------------------------------------------------------------------------------------
def _whittle_args(lengths, k_mode="shared"):
    recs = [rec(frames(n, 30 + i)) for i, n in enumerate(lengths)]
    model = get_model("standard")
    layout = make_layout(recs, k_mode, True)
    return _spectral_args(recs, layout, model, 1, None)


def test_chunk_sums_equal_autodiff_of_the_whole_objective():
    """Value, gradient and Hessian summed over the chunks (the last one padded, bucket
    padding skipped) equal JAX autodiff of the Whittle objective on all ordinates at once
    (an independent reference: no fused pass, no chunks), to 1e-11 relative."""
    a = _whittle_args((40_000, 23_000), "per_recording")  # 20 000 ordinates: 2 chunks
    assert a.f.shape[-1] == 32768 and _chunked.CHUNK == 16384
    chunks = _chunked.ordinate_chunks(a)
    assert len(chunks) == 2 and all(c.f.shape == (2, 16384) for c in chunks)
    scale = jnp.asarray([2.1e-5, 1.9e-5, 1.05 * GAMMA, 5e-18])
    x = jnp.asarray([0.03, -0.02, 0.01, 0.2])
    assert_chunk_sums_are_the_whole(spectral_nll, _spectral_nll, chunks, x, scale, a)


def test_binned_ordinates_equal_the_jax_grouping():
    """The host twin of the coarse start-value grouping equals ``_binned_args``."""
    a = _whittle_args((40_000,))
    a = eqx.tree_at(lambda z: z.weight, a, a.weight.at[0, 100:140].set(0.0))  # empty groups
    for width in (2, 16, 32):
        ref, got = _binned_args(a, width), _chunked.binned_ordinates(a, width)
        for name in ("f", "s2", "power", "weight"):
            np.testing.assert_allclose(np.asarray(getattr(got, name)),
                                       np.asarray(getattr(ref, name)), rtol=1e-14, atol=0)


@pytest.mark.parametrize("kw, lengths", [
    ({}, (70_000,)),
    ({"k": "per_recording"}, (40_000, 100_000)),
], ids=["1 recording", "2 recordings"])
def test_chunked_fit_equals_one_compiled_fit(monkeypatch, kw, lengths):
    """The chunked fit with its Newton loop on the host gives the estimates, errors and
    goodness of fit of the single compiled Newton loop (``_chunked.CHUNK = None``)."""
    data = bt.RecordingSet([rec(frames(n, 40 + i)) for i, n in enumerate(lengths)]) \
        if len(lengths) > 1 else rec(frames(lengths[0], 40))
    out = {}
    for chunk in (_chunked.CHUNK, None):
        monkeypatch.setattr(_chunked, "CHUNK", chunk)
        out[chunk] = bt.calibrate(data, **kw)
    a, b = out[None], out[_chunked.CHUNK or 16384]
    assert a.converged and b.converged
    assert a.param_names == b.param_names
    np.testing.assert_allclose(b.values, a.values, rtol=1e-10, atol=0)
    np.testing.assert_allclose(b.errors, a.errors, rtol=1e-8, atol=0)
    assert a.gof["dof"] == b.gof["dof"]
    assert abs(a.gof["statistic"] / b.gof["statistic"] - 1) < 1e-10
    np.testing.assert_allclose(b.extras["ratio"], a.extras["ratio"], rtol=1e-12)


def test_new_length_compiles_no_fit_program(compiles, monkeypatch):
    """After a first Whittle calibration of at least two chunks, recordings of new lengths in
    new buckets (2^17 and 2^19 padded ordinates) compile none of the fit's programs; with
    the chunks off the same sequence compiles the whole Newton loop again (the check can
    fail)."""
    y = frames(600_000, 50)
    fit_programs = ("_chunk_pass", "_update", "_start", "_finish", "_coarse", "_newton",
                    "spectral_model_psd")

    def fit_compiles():
        return [n for n in compiles.names if any(p in n for p in fit_programs)]

    for chunk, expect_none in ((_chunked.CHUNK, True), (None, False)):
        monkeypatch.setattr(_chunked, "CHUNK", chunk)
        jax.clear_caches()  # other tests may have compiled these buckets already
        bt.calibrate(rec(y[:40_000 if chunk else 20_000]))  # 2^15 / 2^14 ordinates
        compiles.reset()
        for n in ((150_000, 600_000) if chunk else (40_000,)):
            res = bt.calibrate(rec(y[:n]))
            assert res.converged and abs(res.k / 2e-5 - 1) < 5 * res.k_err / 2e-5
        assert (fit_compiles() == []) == expect_none, compiles.names


def test_exact_fit_host_loop_equals_compiled_loop(monkeypatch):
    """The finite-difference Newton fit of the exact likelihood with its loop on the host
    (only the pass compiled per padded length) equals the single compiled loop."""
    data = bt.RecordingSet([rec(frames(n, 60 + n)) for n in (2100, 2600)])
    out = {}
    for host in (True, False):
        monkeypatch.setattr(_chunked, "HOST_NEWTON", host)
        out[host] = bt.calibrate(data, likelihood="exact", k="per_recording")
    assert out[True].converged and out[False].converged
    np.testing.assert_allclose(out[True].values, out[False].values, rtol=1e-10, atol=0)
    np.testing.assert_allclose(out[True].errors, out[False].errors, rtol=1e-8, atol=0)
    assert out[True].extras["loglik"] == pytest.approx(out[False].extras["loglik"], rel=1e-13)


# ------------------------------------------------------------------------------------------
# Models with effects in the same chunks (autodiff of each chunk's sum)
# ------------------------------------------------------------------------------------------
def _effect_args(model, lengths, k_mode="shared"):
    recs = [rec(frames(n, 30 + i)) for i, n in enumerate(lengths)]
    m = get_model(model)
    layout = make_layout(recs, k_mode, True, tuple(p.name for p in m.extra_params))
    return _spectral_args(recs, layout, m, 1, None)


@pytest.mark.parametrize("model, spans", [("standard+drift", False),
                                          ("standard+hydrodynamics", True)])
def test_effect_chunk_sums_equal_autodiff_of_the_whole_objective(model, spans):
    """For a model with effects the chunks' autodiff value, gradient and Hessian, summed,
    equal autodiff of the objective on all ordinates at once, to 1e-11: pointwise spectra
    (drift) and a spectrum folded on nodes spanning the record (hydrodynamics: each chunk
    carries the record's frequency span; without it the nodes would follow the chunk)."""
    a = _effect_args(model, (40_000, 23_000), "per_recording")
    assert _chunked.args_chunkable(a) and _chunked._spans_nodes(a) == spans
    chunks = _chunked.ordinate_chunks(a)
    assert len(chunks) == 2 and all(c.f.shape == (2, 16384) for c in chunks)
    n = len(a.layout.names)
    scale = jnp.asarray([2.1e-5, 1.9e-5, 1.05 * GAMMA, 5e-18] + [1e-20] * (n - 4))
    if model.endswith("hydrodynamics"):
        scale = scale.at[4:].set(1.5e-6)
    x = jnp.asarray(np.linspace(0.03, -0.02, n))
    assert_chunk_sums_are_the_whole(spectral_nll, _spectral_nll, chunks, x, scale, a)
    psd = _chunked.model_psd_in_chunks(eqx.filter_jit(_problems.spectral_model_psd),
                                       jnp.asarray(scale * np.exp(x)), a)
    want = np.asarray(_problems.spectral_model_psd(scale * jnp.exp(x), a))
    np.testing.assert_allclose(psd, want, rtol=1e-12, atol=0)


@pytest.mark.parametrize("model, effects", [
    ("standard+drift", True), ("photodiode_aa+drift", True), ("photodiode_aa+drift", False)],
    ids=["fused pass, chunked loop", "autodiff pass, chunked loop",
         "autodiff pass, compiled loop"])
def test_chunked_fit_with_effects_equals_one_compiled_fit(monkeypatch, model, effects):
    """A model with drift on two recordings (drift at its bound 0: the errors from the
    natural-parameter Hessian summed over the chunks): the chunked host-Newton fit (the
    fused pass with drift's spectrum added for standard+drift; autodiff of each chunk's sum
    for the unaliased model, ``_chunked.EFFECTS``, the default), and the compiled loop with
    that Hessian and the fitted spectrum in chunks, give the estimates (1e-10), errors
    (1e-8) and goodness of fit of everything on the whole padded ordinates
    (``_chunked.CHUNK = None``)."""
    monkeypatch.setattr(_chunked, "EFFECTS", effects)
    data = bt.RecordingSet([rec(frames(n, 45 + i)) for i, n in enumerate((40_000, 70_000))])
    out = {}
    for chunk in (_chunked.CHUNK, None):
        monkeypatch.setattr(_chunked, "CHUNK", chunk)
        out[chunk] = bt.calibrate(data, model=model, k="per_recording", likelihood="whittle")
    a, b = out[None], out[_chunked.CHUNK or 16384]
    assert a.converged and b.converged and a.param_names == b.param_names
    assert np.isnan(a.errors[-1])  # drift at its bound: the unconstrained errors were used
    np.testing.assert_allclose(b.values, a.values, rtol=1e-10, atol=1e-30)
    np.testing.assert_allclose(b.errors, a.errors, rtol=1e-8, atol=0)
    assert abs(a.gof["statistic"] / b.gof["statistic"] - 1) < 1e-10


@pytest.mark.parametrize("effects", [True, False], ids=["chunked loop", "compiled loop"])
def test_new_length_with_effects_compiles_no_fit_program(compiles, monkeypatch, effects):
    """After a first standard+drift calibration, a recording in a new bucket compiles none
    of the fit's programs (Newton loop, Hessian at the bound, fitted spectrum) with the
    Newton loop in chunks (``_chunked.EFFECTS``, the default), and neither the Hessian at the
    bound nor the spectrum with the compiled loop; with the chunks off it compiles them again
    (can fail)."""
    monkeypatch.setattr(_chunked, "EFFECTS", effects)
    y = frames(150_000, 59)  # drift at its bound 0 in every fit below
    fit_programs = ("spectral_model_psd", "natural_hessian") + (
        ("_chunk_pass", "_update", "_start", "_finish", "_newton") if effects else ())
    for chunk, expect_none in ((_chunked.CHUNK, True), (None, False)):
        monkeypatch.setattr(_chunked, "CHUNK", chunk)
        jax.clear_caches()
        first = bt.calibrate(rec(y[:40_000]), model="standard+drift")
        compiles.reset()
        res = bt.calibrate(rec(y[:150_000]), model="standard+drift")
        assert np.isnan(first.errors[-1]) and np.isnan(res.errors[-1])  # Hessian at bound
        assert res.converged and abs(res.k / 2e-5 - 1) < 5 * res.k_err / 2e-5
        got = [n for n in compiles.names if any(p in n for p in fit_programs)]
        assert (got == []) == expect_none, compiles.names
