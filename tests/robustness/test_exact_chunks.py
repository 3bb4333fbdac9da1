"""The exact likelihood's finite-difference Newton pass in fixed-size frame chunks
(``blurtrap.inference._exact_chunks``): the same numbers as the pass on the whole record, and
a recording of a new length compiles no fit program.

References: the pass on the whole (bucket-padded) record, JAX reverse-mode gradients
(``_newton.fd_hessian_pass`` of ``exact_nll``: no chunks, no forward mode), and a dense
Toeplitz Gaussian log-likelihood in numpy/scipy. Fits are compared with the chunked pass off
(``_exact_chunks.FRAME_CHUNK = None``, the previous compiled pass): estimates to 1e-10
relative, errors to 1e-8. Compilations are counted as in test_no_recompile.py.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simconfig import GAMMA, frames, rec
from scipy.linalg import toeplitz

import blurtrap as bt
from blurtrap.inference import _exact_chunks
from blurtrap.inference._fixed import reduce as reduce_fixed
from blurtrap.inference._fixed import reduced_objective
from blurtrap.inference._models import get_model
from blurtrap.inference._newton import fd_hessian_pass
from blurtrap.inference._problems import exact_nll, make_exact_args, make_layout


def _args(lengths, mean, k_mode="shared", offset=3e-7):
    recs = [rec(frames(n, 70 + i) + offset) for i, n in enumerate(lengths)]
    layout = make_layout(recs, k_mode, True)
    return make_exact_args(recs, layout, get_model("standard"), mean=mean), layout


def _scale(layout):
    return jnp.asarray([2.1e-5] * layout.n_k + [1.05 * GAMMA, 5e-18])


def _close(got, want, rtol):
    got, want = np.asarray(got), np.asarray(want)
    assert np.max(np.abs(got - want)) <= rtol * np.max(np.abs(want)), (got, want)


@pytest.mark.parametrize("mean", ["zero", "profile", "reml"])
@pytest.mark.parametrize("lengths, k_mode", [((1300,), "shared"),
                                             ((700, 2100), "per_recording")],
                         ids=["1 recording", "2 recordings"])
def test_chunked_pass_equals_the_whole_record_pass(monkeypatch, mean, lengths, k_mode):
    """Value, gradient and difference Hessian from chunks of 512 frames (a recording ending
    inside a chunk, one whose frames end chunks before the other's, bucket padding after
    both; frames offset by 300 nm) equal the reverse-mode pass on the whole padded record:
    value to 1e-13, gradient to 1e-11, Hessian (gradient differences / 2e-4) to 1e-9."""
    monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", 512)
    a, layout = _args(lengths, mean, k_mode)
    assert a.ys.shape[1] == 2048 or a.ys.shape[1] == 4096  # bucket padding
    assert len(_exact_chunks.frame_chunks(a, 512)) == -(-max(lengths) // 512)
    scale = _scale(layout)
    for x in (jnp.zeros(len(scale)), jnp.asarray(np.linspace(0.2, -0.3, len(scale)))):
        want = eqx.filter_jit(fd_hessian_pass(exact_nll, 1e-4))(x, scale, a)
        got = _exact_chunks.exact_chunk_pass(exact_nll, a, 1e-4)(x, scale)
        for g, w, tol in zip(got, want, (1e-13, 1e-11, 1e-9)):
            _close(g, w, tol)


def _dense_reml(y, c0, c1, rho):
    """REML log-likelihood with the dense Toeplitz covariance (numpy; independent)."""
    n = y.size
    cov = toeplitz(np.concatenate([[c0], c1 * rho ** np.arange(n - 1)]))
    ci = np.linalg.inv(cov)
    one = np.ones(n)
    s11 = one @ ci @ one
    mu = (one @ ci @ y) / s11
    r = y - mu
    logdet = np.linalg.slogdet(cov)[1]
    return -0.5 * ((n - 1) * np.log(2 * np.pi) + logdet + r @ ci @ r + np.log(s11))


def test_chunked_value_equals_dense_toeplitz(monkeypatch):
    """The chunked pass's value at ``x = 0`` is minus the dense REML log-likelihood (numpy)
    of the frames (300 frames in chunks of 64) to 1e-10 relative."""
    monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", 64)
    a, layout = _args((300,), "reml")
    scale = _scale(layout)
    value = _exact_chunks.exact_chunk_pass(exact_nll, a, 1e-4)(jnp.zeros(3), scale)[0]
    c0, c1, rho = (float(v[0]) for v in get_model("standard").moments(
        scale[:1], scale[1], scale[2], a.meta.dt, a.meta.w, a.meta.temp))
    want = -_dense_reml(np.asarray(a.ys[0, :300]), c0, c1, rho)
    assert abs(float(value) / want - 1) < 1e-10, (float(value), want)


def test_held_parameters_use_the_chunked_pass():
    """With a held parameter (reduced objective) the chunked pass applies and equals the
    whole-record pass; other objectives get None (the compiled pass)."""
    a, layout = _args((2500,), "reml")
    scale = _scale(layout)
    free, fscale, fargs = reduce_fixed(layout.names, scale, a, {"gamma": (GAMMA, 0.0)})
    red = reduced_objective(exact_nll)
    x = jnp.asarray([0.05, -0.1])
    got = _exact_chunks.exact_chunk_pass(red, fargs, 1e-4)(x, fscale)
    want = eqx.filter_jit(fd_hessian_pass(red, 1e-4))(x, fscale, fargs)
    for g, w, tol in zip(got, want, (1e-13, 1e-11, 1e-9)):
        _close(g, w, tol)
    assert _exact_chunks.exact_chunk_pass(lambda p, z: exact_nll(p, z), a, 1e-4) is None


@pytest.mark.parametrize("kw, lengths", [
    ({}, (4700,)),
    ({"k": "per_recording"}, (2100, 5200)),
    ({"fixed": {"gamma": GAMMA}}, (3100,)),
], ids=["1 recording", "2 recordings", "gamma held"])
def test_chunked_fit_equals_the_compiled_pass(monkeypatch, kw, lengths):
    """``calibrate(likelihood="exact")`` with the chunked pass gives the estimates (1e-10),
    errors (1e-8), log-likelihood and goodness of fit of the compiled whole-record pass."""
    data = bt.RecordingSet([rec(frames(n, 80 + i)) for i, n in enumerate(lengths)]) \
        if len(lengths) > 1 else rec(frames(lengths[0], 80))
    out = {}
    for chunk in (_exact_chunks.FRAME_CHUNK, None):
        monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", chunk)
        out[chunk] = bt.calibrate(data, likelihood="exact", **kw)
    a, b = out[None], out[_exact_chunks.FRAME_CHUNK or 4096]
    assert a.converged and b.converged and a.param_names == b.param_names
    np.testing.assert_allclose(b.values, a.values, rtol=1e-10, atol=0)
    np.testing.assert_allclose(b.errors, a.errors, rtol=1e-8, atol=0)
    assert b.extras["loglik"] == pytest.approx(a.extras["loglik"], rel=1e-13)
    assert abs(a.gof["statistic"] / b.gof["statistic"] - 1) < 1e-10


def test_new_length_compiles_no_exact_fit_program(compiles, monkeypatch):
    """After a first exact calibration, recordings in new buckets (4096 and 16 384 padded
    frames) compile none of the exact fit's programs; with the chunked pass off the same
    sequence compiles the pass again (the check can fail)."""
    y = frames(12_000, 90)
    fit_programs = ("_chunk_jvp", "_start", "_finish", "_update", "_chunk_pass", "pass_fn",
                    "_fd", "value_and_grad")

    def fit_compiles():
        return [n for n in compiles.names if any(p in n for p in fit_programs)]

    for chunk, expect_none in ((_exact_chunks.FRAME_CHUNK, True), (None, False)):
        monkeypatch.setattr(_exact_chunks, "FRAME_CHUNK", chunk)
        jax.clear_caches()  # other tests may have compiled these buckets already
        bt.calibrate(rec(y[:4500]), likelihood="exact")  # 8192 frames
        compiles.reset()
        for n in (2600, 12_000):
            res = bt.calibrate(rec(y[:n]), likelihood="exact")
            assert res.converged and abs(res.k / 2e-5 - 1) < 5 * res.k_err / 2e-5
        assert (fit_compiles() == []) == expect_none, compiles.names
