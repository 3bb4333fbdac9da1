"""Fits with held parameters (``calibrate(..., fixed=...)``) run the full objective's own pass
restricted to the free parameters (``_newton.ReducedObjective``), in the Whittle fit's
ordinate chunks: checked against JAX autodiff of the plain reduced function (written here,
not the package's), and by counting compilations at a new record length.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simconfig import GAMMA, assert_chunk_sums_are_the_whole, frames, rec

import blurtrap as bt
from blurtrap.inference import _chunked
from blurtrap.inference._fixed import reduce as reduce_fixed
from blurtrap.inference._fixed import reduced_objective
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import make_layout, spectral_nll
from blurtrap.inference._spectral import _spectral_args


def _plain_reduced(q, a):
    """The reduced objective as a plain function (the reference: autodiff of this)."""
    return spectral_nll(a.full.at[jnp.asarray(a.free)].set(q), a.inner)


@pytest.mark.parametrize("model", ["standard", "standard+drift"])
@pytest.mark.parametrize("fixed", [{"gamma": (GAMMA, 0.0)}, {"tracking_var": (0.0, 0.0)}],
                         ids=["gamma", "tracking_var at 0"])
def test_reduced_pass_equals_autodiff_of_the_reduced_function(model, fixed):
    """Value, gradient and Hessian of the held-parameter objective, summed over its ordinate
    chunks, equal JAX autodiff of the plain reduced function on all ordinates, to 1e-11 of
    the largest entry: the fused Whittle pass (``standard``) and a model with an effect; a
    held value above 0 (the full pass sliced) and tracking_var held at 0 (autodiff)."""
    m = get_model(model)
    recs = [rec(frames(40_000, 3))]  # 20 000 ordinates: two chunks
    layout = make_layout(recs, "shared", True, tuple(p.name for p in m.extra_params))
    a = _spectral_args(recs, layout, m, 1, None)
    scale = np.array([2.1e-5, 1.05 * GAMMA, 5e-18, 1e-20][:len(layout.names)])
    _, fscale, fargs = reduce_fixed(layout.names, scale, a, fixed)
    assert fargs.positive == ("gamma" in fixed)
    red = reduced_objective(spectral_nll)
    assert _chunked.chunked_applies(red, fargs)
    chunks = _chunked.ordinate_chunks(fargs)
    assert len(chunks) == 2
    x = jnp.asarray([0.03, -0.02, 0.2][:fscale.shape[0]])
    assert_chunk_sums_are_the_whole(red, _plain_reduced, chunks, x, fscale, fargs)


def test_held_fit_at_a_new_length_compiles_no_fit_program(compiles):
    """After one held-gamma Whittle calibration of two chunks, one of a new length in a new
    bucket compiles none of the fit's programs (before: one compiled Newton loop of the
    reduced objective per padded length) nor the held-value test's gradients (before: one
    per padded length); k agrees with the truth."""
    y = frames(150_000, 51)
    fixed = {"gamma": GAMMA}
    fit_programs = ("_chunk_pass", "_update", "_start", "_finish", "_coarse", "_newton",
                    "_bfgs", "SpectralObjective")
    jax.clear_caches()
    bt.calibrate(rec(y[:40_000]), likelihood="whittle", fixed=fixed)
    compiles.reset()
    res = bt.calibrate(rec(y), likelihood="whittle", fixed=fixed)
    assert res.converged and abs(res.k / 2e-5 - 1) < 5 * res.k_err / 2e-5
    assert [n for n in compiles.names if any(p in n for p in fit_programs)] == [], \
        compiles.names


def test_held_error_gradients_summed_over_chunks_equal_the_whole():
    """The gradients behind the propagation of held errors and the held-value test, summed
    over ordinate chunks (a model folded on nodes: each chunk carries the
    record's span), equal JAX's gradient of the Whittle objective on all ordinates (1e-10)."""
    from blurtrap.inference._fixed import _grads
    from blurtrap.inference._problems import _spectral_nll

    m = get_model("standard+exposure_kernel")
    recs = [rec(frames(40_000, 4))]
    layout = make_layout(recs, "shared", True, tuple(p.name for p in m.extra_params))
    a = _spectral_args(recs, layout, m, 1, None)
    assert _chunked.objective_chunkable(spectral_nll, a) and _chunked._spans_nodes(a)
    p0 = np.array([2.1e-5, 1.05 * GAMMA, 5e-18, 1.4e-6])
    pts = np.stack([p0, p0 * 1.01, p0 * 0.98])
    got = _grads(spectral_nll, pts, a)
    want = np.asarray(jax.vmap(jax.grad(_spectral_nll), in_axes=(0, None))(jnp.asarray(pts), a))
    assert got.shape == want.shape == (3, 4)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.max(np.abs(want)))


def test_held_error_gradients_of_the_exact_likelihood_in_frame_chunks():
    """The same gradients of the exact likelihood, carried through its frame chunks (a
    record of a new length compiles nothing), equal JAX's gradient of ``exact_nll`` on the
    whole record (1e-9), two recordings of different lengths, one point with eps^2 at its
    bound 0 (the natural parameters, no logarithm)."""
    from blurtrap.inference._exact_chunks import exact_chunk_grads
    from blurtrap.inference._fixed import _grads
    from blurtrap.inference._problems import exact_nll, make_exact_args

    recs = [rec(frames(5000, 5)), rec(frames(9000, 6))]
    m = get_model("standard")
    a = make_exact_args(recs, make_layout(recs, "per_recording", True, ()), m)
    assert exact_chunk_grads(exact_nll, a) is not None
    p0 = np.array([2.1e-5, 1.9e-5, 1.05 * GAMMA, 5e-18])
    pts = np.stack([p0, p0 * 1.01, p0 * np.array([0.98, 1.0, 1.0, 0.0])])
    got = _grads(exact_nll, pts, a)
    want = np.asarray(jax.vmap(jax.grad(exact_nll), in_axes=(0, None))(jnp.asarray(pts), a))
    assert got.shape == want.shape == (3, 4)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))


def test_held_exact_fit_at_a_new_length_compiles_nothing_for_held_errors(compiles):
    """A held gamma with an error on records short enough for the exact likelihood: a new
    length compiles no exact-likelihood program for the propagated errors (before: the
    gradient batch of ``exact_nll`` per padded length, ~2 s)."""
    y = frames(9_200, 53)
    fixed = {"gamma": (GAMMA, 0.03 * GAMMA)}
    bt.calibrate(rec(y[:4096]), likelihood="exact", fixed=fixed)
    compiles.reset()
    res = bt.calibrate(rec(y[4096:]), likelihood="exact", fixed=fixed)
    assert res.converged and abs(res.k / 2e-5 - 1) < 3 * res.k_err / 2e-5
    assert [n for n in compiles.names if "exact_nll" in n or "_chunk_jvp" in n] == [], \
        compiles.names


def test_short_stokes_fit_at_a_new_length_compiles_no_fit_program(compiles):
    """``friction="stokes"`` with a bead whose hydrodynamics are added (a spectrum folded on
    nodes): after one record of 3000 frames (1500 ordinates, too few for nodes by
    themselves), one of 5000 frames (a new bucket, on nodes) compiles none of the fit's
    programs (before: one compiled Newton loop per bucket below 4096 ordinates and a chunk
    program above, 13.8 s); k agrees with the truth."""
    y = frames(8_000, 52, k=5e-5)
    meta = {"bead_radius_m": 1.53e-6, "viscosity_Pa_s": 0.00093}
    fit_programs = ("_chunk_pass", "_update", "_start", "_finish", "_coarse", "_newton",
                    "_bfgs", "SpectralObjective")
    first = bt.calibrate(rec(y[:3000], metadata=meta), friction="stokes")
    assert "hydrodynamics" in first.model
    compiles.reset()
    res = bt.calibrate(rec(y[3000:], metadata=meta), friction="stokes")
    assert res.converged and abs(res.k / 5e-5 - 1) < 3 * res.k_err / 5e-5
    assert [n for n in compiles.names if any(p in n for p in fit_programs)] == [], \
        compiles.names
