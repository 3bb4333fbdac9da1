"""The irregular-time likelihood's finite-difference Newton pass in fixed-size frame chunks
(``blurtrap.inference._exact_chunks.IrregularChunk``): the same numbers as the pass on the
whole record, and a recording of a new length compiles no fit program.

References: the pass on the whole (bucket-padded) record with JAX reverse-mode gradients
(``_newton.fd_hessian_pass`` of ``irregular_nll``: no chunks, no forward mode), and the dense
multivariate normal of frames at the recorded times (covariance written out from the OU
kernel in numpy, ``tests/_irregular_gen.py``). Frames come from that generator, not from
blurtrap's simulator. Fits are compared with the chunked pass off
(``_exact_chunks.FRAME_CHUNK = None``, the compiled whole-record pass): estimates to 1e-10
relative, errors to 1e-8. Compilations are counted as in test_no_recompile.py.
"""

import _irregular_gen as gen
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simconfig import DT, GAMMA

import blurtrap as bt
from blurtrap.inference import _exact_chunks
from blurtrap.inference._fixed import reduce as reduce_fixed
from blurtrap.inference._fixed import reduced_objective
from blurtrap.inference._irregular import irregular_nll, make_irregular_args
from blurtrap.inference._models import get_model
from blurtrap.inference._newton import fd_hessian_pass
from blurtrap.inference._problems import make_layout

K, T, EPS = 2e-5, 295.0, 2e-9
W = 0.5 * DT


def times(n, seed):
    """Frame starts with a wandering clock (independent intervals dt (1 + 0.2 N(0, 1)),
    every one at least the exposure)."""
    rng = np.random.default_rng(seed)
    d = DT * np.clip(1.0 + 0.2 * rng.normal(size=n - 1), W / DT, None)
    return np.concatenate([[0.0], np.cumsum(d)])


def rec(n, seed, offset=3e-7, eps=EPS, w=W):
    """Frames at :func:`times`; with ``eps = 0`` and ``w = 0.1 dt`` eps^2 ends at its bound."""
    s = times(n, seed)
    y = gen.frames(s, w, K, GAMMA, T, eps**2, np.random.default_rng(seed + 1), offset)
    return bt.Recording(y, frame_interval=float(np.median(np.diff(s))), times=s, exposure=w,
                        allow_irregular=True)


def _args(lengths, mean, k_mode="shared", model="standard"):
    recs = [rec(n, 70 + i) for i, n in enumerate(lengths)]
    layout = make_layout(recs, k_mode, get_model(model).noise)
    return make_irregular_args(recs, layout, get_model(model), mean=mean), layout


def _scale(layout):
    s = [2.1e-5] * layout.n_k + [1.05 * GAMMA]
    return jnp.asarray(s + [5e-18] * (len(layout.names) - len(s)))


def _close(got, want, rtol):
    got, want = np.asarray(got), np.asarray(want)
    assert np.max(np.abs(got - want)) <= rtol * np.max(np.abs(want)), (got, want)


@pytest.mark.parametrize("mean, lengths, k_mode, model", [
    ("zero", (1300,), "shared", "standard"),
    ("reml", (700, 1500), "per_recording", "standard"),
    ("profile", (900,), "shared", "naive"),
], ids=["zero, 1 recording", "reml, 2 recordings", "profile, naive"])
def test_chunked_pass_equals_the_whole_record_pass(monkeypatch, mean, lengths, k_mode, model):
    """Value, gradient and difference Hessian from chunks of 256 frames (a recording ending
    inside a chunk, one whose frames end chunks before the other's, bucket padding after
    both; frames offset by 300 nm) equal the reverse-mode pass on the whole padded record:
    value to 1e-13, gradient to 1e-11, Hessian (gradient differences / 2e-4) to 1e-9."""
    monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", 256)
    a, layout = _args(lengths, mean, k_mode, model)
    assert a.ys.shape[1] > max(lengths)  # bucket padding
    scale = _scale(layout)
    pass_fn = _exact_chunks.exact_chunk_pass(irregular_nll, a, 1e-4)
    assert pass_fn is not None
    for x in (jnp.zeros(len(scale)), jnp.asarray(np.linspace(0.2, -0.3, len(scale)))):
        want = eqx.filter_jit(fd_hessian_pass(irregular_nll, 1e-4))(x, scale, a)
        got = pass_fn(x, scale)
        for g, w, tol in zip(got, want, (1e-13, 1e-11, 1e-9)):
            _close(g, w, tol)


def _dense_reml(y, cov):
    """REML log-likelihood with the dense covariance (numpy; independent of blurtrap)."""
    n = y.size
    ci = np.linalg.inv(cov)
    one = np.ones(n)
    s11 = one @ ci @ one
    r = y - (one @ ci @ y) / s11
    logdet = np.linalg.slogdet(cov)[1]
    return -0.5 * ((n - 1) * np.log(2 * np.pi) + logdet + r @ ci @ r + np.log(s11))


def test_chunked_value_equals_the_dense_normal(monkeypatch):
    """The chunked pass's value at ``x = 0`` is minus the dense REML log-likelihood (numpy,
    covariance from the OU kernel at the recorded times) of 300 frames in chunks of 64, to
    1e-10 relative."""
    monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", 64)
    r = rec(300, 5)
    layout = make_layout([r], "shared", True)
    a = make_irregular_args([r], layout, get_model("standard"))
    scale = _scale(layout)
    value = _exact_chunks.exact_chunk_pass(irregular_nll, a, 1e-4)(jnp.zeros(3), scale)[0]
    cov = gen.frame_covariance(np.asarray(r.times), W, float(scale[0]), float(scale[1]), T,
                               float(scale[2]))
    want = -_dense_reml(np.asarray(r.positions), cov)
    assert abs(float(value) / want - 1) < 1e-10, (float(value), want)


def test_held_parameters_use_the_chunked_pass():
    """With a held parameter (reduced objective) the chunked pass applies and equals the
    whole-record pass."""
    a, layout = _args((1500,), "reml")
    scale = _scale(layout)
    free, fscale, fargs = reduce_fixed(layout.names, scale, a, {"gamma": (GAMMA, 0.0)})
    red = reduced_objective(irregular_nll)
    x = jnp.asarray([0.05, -0.1])
    got = _exact_chunks.exact_chunk_pass(red, fargs, 1e-4)(x, fscale)
    want = eqx.filter_jit(fd_hessian_pass(red, 1e-4))(x, fscale, fargs)
    for g, w, tol in zip(got, want, (1e-13, 1e-11, 1e-9)):
        _close(g, w, tol)


@pytest.mark.parametrize("bound", [False, True], ids=["interior", "eps^2 at its bound"])
def test_chunked_fit_equals_the_compiled_pass(monkeypatch, bound):
    """``calibrate`` of two irregular recordings with the chunked pass (chunks of 512 frames)
    gives the estimates (1e-10), errors (1e-8) and log-likelihood of the compiled
    whole-record pass; with eps^2 at its bound the others' errors come from the
    natural-parameter Hessian, by gradients in the same chunks (compiled on the whole record
    with the chunks off)."""
    kw, seed = ({"eps": 0.0, "w": 0.1 * DT}, 84) if bound else ({}, 80)
    data = bt.RecordingSet([rec(n, seed + i, **kw) for i, n in enumerate((1100, 2600))])
    out = {}
    for chunk in (512, None):  # 512: both recordings span several chunks
        monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", chunk)
        out[chunk] = bt.calibrate(data, likelihood="exact", k="per_recording")
    a, b = out[None], out[512]
    assert a.converged and b.converged and a.param_names == b.param_names
    assert a.at_bounds == b.at_bounds == (("tracking_var",) if bound else ())
    # eps^2 at its bound: ~1e-30 m^2 either way (0 to rounding)
    np.testing.assert_allclose(b.values, a.values, rtol=1e-10, atol=1e-25 if bound else 0)
    np.testing.assert_allclose(b.errors, a.errors, rtol=1e-8, atol=0)
    assert b.extras["loglik"] == pytest.approx(a.extras["loglik"], rel=1e-13)


def test_new_length_compiles_no_irregular_fit_program(compiles, monkeypatch):
    """After a first calibration of an irregular recording, one in a new bucket compiles
    none of the fit's programs (eps^2 at its bound: the errors' natural-parameter Hessian
    included); with the chunked pass off the same sequence compiles the pass again (the
    check can fail)."""
    fit_programs = ("_chunk_jvp", "_start", "_finish", "_update", "_chunk_pass", "pass_fn",
                    "_fd", "value_and_grad", "natural_hessian")

    def fit_compiles():
        return [n for n in compiles.names if any(p in n for p in fit_programs)]

    kw = {"eps": 0.0, "w": 0.1 * DT}
    first, second = rec(1500, 90, **kw), rec(2600, 90, **kw)  # 2048, then 4096 padded frames
    for chunk, expect_none in ((_exact_chunks.FRAME_CHUNK, True), (None, False)):
        monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", chunk)
        jax.clear_caches()  # other tests may have compiled these buckets already
        assert bt.calibrate(first, likelihood="exact").at_bounds == ("tracking_var",)
        compiles.reset()
        res = bt.calibrate(second, likelihood="exact")
        assert res.converged and abs(res.k / K - 1) < 5 * res.k_err / K
        assert res.at_bounds == ("tracking_var",)
        assert (fit_compiles() == []) == expect_none, compiles.names
