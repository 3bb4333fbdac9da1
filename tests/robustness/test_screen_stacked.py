"""diagnose's screening fits of models folded on nodes run on stacked ordinate chunks
(``blurtrap.inference._screen_stacked``): one compiled BFGS program for records of many
lengths. Checked here against JAX autodiff of the Whittle objective on all ordinates at once
(no chunks, no stack, the fold inside the graph): value, reverse-mode gradient and
forward-mode derivative; and the node values given to the model against the model folding
them itself. The new-bucket compile check and the screening minima against per-length BFGS
are in test_no_recompile.py."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _simconfig import GAMMA

import blurtrap as bt
from blurtrap.inference import _chunked, _screen_stacked
from blurtrap.inference._models import get_model
from blurtrap.inference._nodes import NodeValues, node_plan, use_nodes
from blurtrap.inference._problems import (
    _spectral_nll,
    make_layout,
    spectral_nll,
    spectral_node_logp,
)
from blurtrap.inference._spectral import _spectral_args

DT_PD, W_PD = 1e-5, 1e-8  # photodiode: 100 kHz, 10 ns


def _args(model, lengths):
    recs = [bt.Recording(np.asarray(bt.simulate(5e-5, GAMMA, W_PD, DT_PD, n,
                                                key=jax.random.key(80 + i),
                                                method="exact_frames",
                                                tracking_std=2e-9))[0],
                         frame_interval=DT_PD, exposure=W_PD)
            for i, n in enumerate(lengths)]
    m = get_model(model)
    layout = make_layout(recs, "per_recording", True, tuple(p.name for p in m.extra_params))
    return _spectral_args(recs, layout, m, 1, None)


@pytest.fixture(scope="module")
def hydro_args():
    # 40 000 and 23 000 samples: 20 000 ordinates padded to 32 768, 2 real chunks of 16 384
    return _args("standard+hydrodynamics+drift", (40_000, 23_000))


def _p(a):
    return jnp.asarray([5.2e-5, 4.7e-5, 1.04 * GAMMA, 4e-18, 1.6e-6, 1e-20][:len(a.layout.names)])


@pytest.mark.parametrize("chunk, n_chunks", [(None, 2), (4096, 5)],
                         ids=["2 chunks, one trip", "5 chunks, two trips"])
def test_stacked_objective_equals_the_whole_objective(hydro_args, monkeypatch, chunk,
                                                      n_chunks):
    """Value (1e-12; the plain call, as BFGS's last evaluation, and inside the derivatives),
    gradient by reverse mode and directional derivative by forward mode (1e-9 of the largest
    entry) of the stacked objective equal autodiff of the whole objective; 20 000 real
    ordinates of 32 768 in chunks of 16 384 (one trip of the loop) or 4096 (two trips, the
    second partly padding). The next capacity (more padding) gives the same value; more
    chunks than the largest capacity are not stacked."""
    if chunk is not None:
        monkeypatch.setattr(_chunked, "CHUNK", chunk)
    a = hydro_args
    assert _screen_stacked.applies(spectral_nll, a)
    s = _screen_stacked.stack(a)
    cap, group = _screen_stacked.CAPACITIES[0], _screen_stacked.GROUP
    assert int(s.n) == n_chunks and s.f.shape == (cap // group, 2, group * _chunked.CHUNK)
    p = _p(a)
    want_v, want_g = jax.jit(jax.value_and_grad(_spectral_nll))(p, a)
    got_v, got_g = jax.jit(jax.value_and_grad(_screen_stacked.stacked_nll))(p, s)
    assert float(got_v) == pytest.approx(float(want_v), rel=1e-12)
    plain = jax.jit(_screen_stacked.stacked_nll)(p, s)
    assert float(plain) == pytest.approx(float(want_v), rel=1e-12)
    scale = np.max(np.abs(np.asarray(want_g * p)))
    np.testing.assert_allclose(np.asarray(got_g * p), np.asarray(want_g * p), rtol=0,
                               atol=1e-9 * scale)
    dp = p * jnp.linspace(0.3, -0.2, p.size)
    _, jvp = jax.jit(lambda q: jax.jvp(lambda z: _screen_stacked.stacked_nll(z, s), (q,),
                                       (dp,)))(p)
    assert float(jvp) == pytest.approx(float(jnp.dot(want_g, dp)), abs=1e-9 * scale)
    # the smallest capacity that holds the chunks (the same sums), none beyond the largest
    monkeypatch.setattr(_screen_stacked, "CAPACITIES", (n_chunks - 1, 2 * n_chunks + 2))
    s2 = _screen_stacked.stack(a)
    assert s2.f.shape == ((2 * n_chunks + 2) // group, 2, group * _chunked.CHUNK)
    assert float(jax.jit(_screen_stacked.stacked_nll)(p, s2)) == pytest.approx(
        float(want_v), rel=1e-12)
    monkeypatch.setattr(_screen_stacked, "CAPACITIES", (n_chunks - 1,))
    assert _screen_stacked.stack(a) is None


def test_given_node_values_equal_the_models_own_fold(hydro_args):
    """The model spectrum with its node values given (``SpectralArgs.nodes``) equals
    the model folding them itself (1e-13); node values for a closed-form model are an
    error."""
    import equinox as eqx

    from blurtrap.inference._problems import spectral_model_psd

    a = hydro_args
    p = _p(a)
    y = spectral_node_logp(p, a)
    assert y.shape == (2, a.model.fold_nodes)
    _, left, t = node_plan(a.f, a.model.fold_nodes)
    given = eqx.tree_at(lambda z: z.nodes, a, NodeValues(y, left, t),
                        is_leaf=lambda z: z is None)
    np.testing.assert_allclose(np.asarray(spectral_model_psd(p, given)),
                               np.asarray(spectral_model_psd(p, a)), rtol=1e-13, atol=0)
    m = get_model("standard")
    with pytest.raises(ValueError, match="node values are given"):
        m.psd(a.f, p[:2], p[2], p[3], DT_PD, W_PD, 295.0, nodes=NodeValues(y, left, t))


def test_no_stack_where_nothing_is_folded_on_nodes():
    """Closed-form models (the fused pass or autodiff) are not stacked."""
    assert not _screen_stacked.applies(spectral_nll, _args("standard+drift", (40_000,)))


def test_a_record_too_short_for_nodes_is_stacked_on_its_span():
    """A record too short to fold on nodes by itself (2000 ordinates) is stacked in one
    chunk whose nodes span it: the stacked value equals autodiff of the whole objective
    (exact fold) to the nodes' accuracy (1e-9 of the value), and its chunk sums to 1e-12."""
    a = _args("standard+hydrodynamics", (4_000,))
    assert not use_nodes(a.f, a.model.fold_nodes) and _screen_stacked.applies(spectral_nll, a)
    s = _screen_stacked.stack(a)
    assert int(s.n) == 1
    p = _p(a)
    got = float(jax.jit(_screen_stacked.stacked_nll)(p, s))
    assert got == pytest.approx(float(jax.jit(_spectral_nll)(p, a)), rel=1e-9)
    chunks = sum(float(_spectral_nll(p, c)) for c in _chunked.ordinate_chunks(a))
    assert got == pytest.approx(chunks, rel=1e-12)
