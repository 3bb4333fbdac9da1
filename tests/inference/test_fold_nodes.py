"""The folded spectrum on log-spaced nodes (blurtrap.inference._nodes), used by TrapModel.psd
for long records of models without closed form, against the exact folded sum at every
ordinate (``fold_nodes=0``): PSD and Whittle log-likelihood, and the estimates of a full
calibrate on a filtered photodiode record."""

import dataclasses
import os
import sys

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from blurtrap.inference._nodes import MIN_ORDINATES, hermite_log, node_plan, use_nodes
from blurtrap.inference._problems import spectral_model_psd, spectral_nll

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))
from _fold_helpers import GAMMA, K  # noqa: E402,F401
from _fold_helpers import record as _record  # noqa: E402
from _fold_helpers import spec as _spec  # noqa: E402


def _exact(spec):
    return dataclasses.replace(spec, model=dataclasses.replace(spec.model, fold_nodes=0))


# photodiode (W -> 0) and camera (W = dt), each folded effect at typical and extreme values,
# with drift (an additive effect, never interpolated) included
CASES = [
    (1e-5, 1e-9, "standard+drift+hydrodynamics", [[0.75e-6], [3e-6], [1e-7]]),
    (1e-5, 1e-9, "standard+drift+detector_filter",
     [[8e3, 0.4], [100.0, 0.1], [4e4, 0.9], [1e5, 1.0]]),
    (1 / 1500, 1 / 1500, "standard+drift+exposure_kernel", [[0.5], [0.01], [0.2]]),
]


@pytest.mark.parametrize("dt,w,model,extras", CASES)
def test_model_psd_on_nodes_matches_exact_folded_sum(dt, w, model, extras):
    """Max relative error of the model PSD over all 2^13 ordinates < 1e-7 (measured <= 2.7e-8,
    next to Nyquist) for k from 1/30 to 30 x the simulated one, and the Whittle sum within
    3e-4 of the exact one (relative 1e-8 of a sum of ~3e4; measured <= 3e-5): a
    likelihood-ratio statistic moves by far less than the ~1 it must reach to count."""
    spec = _spec([_record(dt, w, 2**14)], model)
    assert use_nodes(spec.f) and not use_nodes(spec.f, 0)
    exact = _exact(spec)
    psd, nll = eqx.filter_jit(spectral_model_psd), eqx.filter_jit(spectral_nll)
    for ex in extras:
        for k in (K, 30 * K, K / 30):
            p = jnp.asarray([k, GAMMA, 4e-18, 1e-16] + ex)
            ref = np.asarray(psd(p, exact))
            approx = np.asarray(psd(p, spec))
            assert np.max(np.abs(approx / ref - 1.0)) < 1e-7, (model, ex, k)
            nll_ref = float(nll(p, exact))
            assert abs(float(nll(p, spec)) - nll_ref) < 3e-4, (model, ex, k)


def test_short_records_and_exact_option_skip_the_nodes():
    """Below MIN_ORDINATES ordinates (and with fold_nodes=0) the model is the exact sum,
    bit for bit; above, it is not (the check can fail)."""
    for n, same in ((MIN_ORDINATES, True), (2**14, False)):
        spec = _spec([_record(1e-5, 1e-9, n)], "standard+detector_filter")
        p = jnp.asarray([K, GAMMA, 4e-18, 8e3, 0.4])
        psd = eqx.filter_jit(spectral_model_psd)
        a = np.asarray(psd(p, spec))
        b = np.asarray(psd(p, _exact(spec)))
        assert np.array_equal(a, b) == same, n


def test_hermite_reproduces_cubics_and_node_values():
    """The interpolation is exact on a cubic in the node index (fourth-order slopes, Hermite
    cubic) and at the nodes themselves; zero and negative frequencies take |f|."""
    f = jnp.asarray(np.concatenate([[0.0, -3.0], np.geomspace(1.0, 1e4, 5000)]))[None, :]
    nodes, left, t = node_plan(f, 64)
    u = left + t  # position in node-index units
    cubic = lambda x: 0.3 - 0.2 * x + 0.01 * x**2 - 1e-4 * x**3  # noqa: E731
    y = cubic(jnp.arange(64.0))[None, :]
    np.testing.assert_allclose(hermite_log(y, left, t), cubic(u), rtol=0, atol=1e-12)
    np.testing.assert_allclose(nodes[0, [0, -1]], [1.0, 1e4], rtol=1e-12)
    assert float(u[0, 0]) == 0.0
    assert float(u[0, 1]) == pytest.approx(63 * np.log(3.0) / np.log(1e4), rel=1e-12)
