"""The streaming reduction: chunk merges against numpy over all values at once."""

import types

import numpy as np
import pytest

from blurtrap.sweeps import _stats as st


def _batch(k, k_err, status):
    n = len(k)
    ok = np.array([s == "ok" for s in status])
    return types.SimpleNamespace(
        k=k, k_err=k_err, gamma=k * 1e-3, gamma_err=k_err * 1e-3,
        tracking_var=np.zeros(n), tracking_var_err=np.zeros(n), success=ok,
        status=np.array(status), at_bound=np.zeros(n, dtype=bool))


@pytest.mark.parametrize("offset", [0.0, 1e8])
def test_chunked_mean_and_variance_match_numpy(rng, offset):
    """Uneven chunks, failed items and a large offset (where the one-pass formula
    sum(x^2) - n mean^2 loses every digit of a unit-variance spread at 1e8)."""
    sizes = [7, 1, 30, 12, 50]
    true = offset + 0.5
    acc = st.empty(1, 1)
    vals, errs, stats = [], [], []
    for n in sizes:
        k = offset + rng.standard_normal(n)
        e = np.abs(1.0 + 0.1 * rng.standard_normal(n))
        status = rng.choice(["ok", "ok", "ok", "not converged", "refused: dt >> tau"], n)
        b = _batch(k, e, list(status))
        acc = st.merge(acc, {f: v[None, None] for f, v in st.chunk_stats(b, {
            "k": true, "gamma": true * 1e-3, "tracking_var": 0.0}).items()})
        vals.append(k[status == "ok"])
        errs.append(e[status == "ok"])
        stats += list(status)
    v, e = np.concatenate(vals), np.concatenate(errs)
    out = st.summarise(acc, {"k": np.array([true]), "gamma": np.array([true * 1e-3]),
                             "tracking_var": np.array([0.0])})
    np.testing.assert_allclose(out["mean_k"][0, 0], v.mean(), rtol=1e-15)
    np.testing.assert_allclose(out["sd_k"][0, 0], v.std(ddof=1), rtol=1e-9)
    np.testing.assert_allclose(out["se_k"][0, 0], e.mean(), rtol=1e-14)
    assert out["coverage_k"][0, 0] == np.mean(np.abs(v - true) <= 1.959963984540054 * e)
    assert out["n_ok"][0, 0] == v.size and out["n_items"][0, 0] == sum(sizes)
    assert out["n_not_converged"][0, 0] == stats.count("not converged")
    assert out["n_refused"][0, 0] == stats.count("refused: dt >> tau")
    # eps^2 is not a parameter of this (fake) model: no statistics, not zeros
    assert np.isnan(out["mean_tracking_var"][0, 0]) and np.isnan(out["sd_tracking_var"][0, 0])


def test_empty_cells_give_nan_not_errors():
    acc = st.empty(2, 1)
    out = st.summarise(acc, {p: np.ones(2) for p in st.FITTED})
    assert np.all(np.isnan(out["mean_k"])) and np.all(out["n_ok"] == 0)
