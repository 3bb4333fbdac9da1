"""bt.sweep: statistics against a direct computation, resumption, labels and errors."""

import json
import sys

import jax
import jax.random as jr
import numpy as np
import pytest

import blurtrap as bt

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from _sweep_case import DT, GRID, KW, K, run  # noqa: E402


@pytest.fixture(scope="module")
def full():
    return run()


def _same(a, b):
    assert set(a.data) == set(b.data)
    for k in a.data:
        assert np.array_equal(a.data[k], b.data[k], equal_nan=True), k


def test_statistics_equal_a_direct_computation(full):
    """The streamed statistics equal numpy over every recording of the cell: the same keys
    (fold_in of cell and chunk index), the same fits, mean/SD/coverage computed in one go."""
    assert full.dims == ("k", "exposure", "model") and full.shape == (3, 2, 2)
    key = jr.key(11)
    for g in range(6):
        i, j = np.unravel_index(g, (3, 2))
        k, w = GRID["k"][i], GRID["exposure"][j]
        y = np.concatenate([np.asarray(bt.simulate(
            k, GRID["gamma"], w, DT, 2048, key=jr.fold_in(jr.fold_in(key, g), c),
            n_traces=8, method="exact_frames", tracking_std=0.5e-9, dtype=np.float64))
            for c in range(2)])
        for m, model in enumerate(KW["models"]):
            b = [bt.calibrate_batch(y[c * 8:(c + 1) * 8], frame_interval=DT, exposure=w,
                                    model=model, gof_threshold=0.0) for c in range(2)]
            ok = np.concatenate([x.success for x in b])
            assert full["n_ok"][i, j, m] == ok.sum() and full["n_items"][i, j, m] == 16
            for p, true in (("k", k), ("gamma", GRID["gamma"])):
                v = np.concatenate([getattr(x, p) for x in b])[ok]
                e = np.concatenate([getattr(x, p + "_err") for x in b])[ok]
                np.testing.assert_allclose(full["mean_" + p][i, j, m], v.mean(), rtol=1e-13)
                np.testing.assert_allclose(full["sd_" + p][i, j, m], v.std(ddof=1), rtol=1e-10)
                np.testing.assert_allclose(full["se_" + p][i, j, m], e.mean(), rtol=1e-13)
                np.testing.assert_allclose(full["bias_" + p][i, j, m],
                                           100 * (v.mean() - true) / true, rtol=1e-10)
                cover = np.mean(np.abs(v - true) <= 1.959963984540054 * e)
                assert full["coverage_" + p][i, j, m] == cover
    # the naive model fits no tracking noise: no statistics for it
    assert np.all(np.isnan(full["mean_tracking_var"][..., 0]))
    assert np.all(np.isfinite(full["mean_tracking_var"][..., 1]))


def test_naive_model_is_biased_where_the_standard_model_is_not(full):
    """Blur, aliasing and tracking noise bias the naive fit by many standard errors of the
    mean (SEM = SD / sqrt(n_ok), from the sweep's own SD); the standard model stays within
    4 SEM in every cell (16 recordings per cell: 4 SEM is far in the t_15 tail)."""
    for p in ("k", "gamma"):
        z = full["bias_" + p] / (100 * full["sd_" + p] / np.sqrt(full["n_ok"])
                                 / full["true_" + p])
        assert np.all(np.abs(z[..., 0]) > 4), (p, z[..., 0])
        assert np.all(np.abs(z[..., 1]) < 4), (p, z[..., 1])


class Stop(Exception):
    pass


def test_interrupted_sweep_resumes_to_the_same_result(full, tmp_path, capsys):
    out = tmp_path / "state.npz"
    seen = []

    def stop_after_first(done, total):
        seen.append((done, total))
        if done == 1:
            raise Stop

    with pytest.raises(Stop):
        run(out=out, callback=stop_after_first)
    assert seen == [(1, 2)] and out.exists()
    part = run(out=out, callback=lambda d, t: seen.append((d, t)))
    assert seen == [(1, 2), (2, 2)]  # only the second chunk was computed again
    assert part.complete
    _same(part, full)
    capsys.readouterr()
    again = run(out=out, callback=lambda d, t: seen.append((d, t)), progress=True)
    assert seen == [(1, 2), (2, 2)]  # nothing left to do
    err = capsys.readouterr().err  # the tqdm bar: 2 chunks x 6 cells, all done
    assert "sweep: 100%" in err and "12/12" in err, err
    _same(again, full)
    with pytest.raises(ValueError, match="different sweep"):
        run(out=out, n_frames=1024)


def test_labels_dataframe_xarray_summary_plot(full, monkeypatch):
    assert list(full.coords["k"]) == GRID["k"] and list(full.coords["model"]) == ["naive",
                                                                                  "standard"]
    df = full.to_dataframe()
    assert len(df) == 12 and list(df.columns[:3]) == ["k", "exposure", "model"]
    row = df[(df.k == 2 * K) & (df.exposure == DT) & (df.model == "standard")].iloc[0]
    assert row.bias_k == full["bias_k"][1, 1, 1]
    pytest.importorskip("xarray")
    ds = full.to_xarray()
    assert float(ds.bias_k.sel(k=2 * K, exposure=DT, model="standard")) == row.bias_k
    assert ds.k.attrs["units"] == "N/m"
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match="to_xarray needs xarray"):
        full.to_xarray()
    back = json.loads(json.dumps(full.to_dict()))
    assert back["dims"] == ["k", "exposure", "model"] and back["attrs"]["n_traces"] == 16
    assert back["data"]["bias_k"][1][1][1] == row.bias_k
    text = full.summary()
    assert "k [pN/nm]" in text and "exposure [ms]" in text and "0.1 | 0.2685 | standard" in text
    fig = full.plot(x="exposure", y="bias_k")
    assert len(fig.axes[0].lines) == 3 * 2 + 1  # k x model lines and the zero line
    with pytest.raises(ValueError, match="x must be a numeric grid axis"):
        full.plot(x="model")
    with pytest.raises(ValueError, match="y must be a statistic"):
        full.plot(x="k", y="bias")


def test_radius_and_injection_axes():
    res = bt.sweep({"k": K, "radius": [0.5e-6, 1e-6], "exposure": 1e-4, "frame_interval": 1e-4,
                    "injections": {"none": (), "noise": (bt.TrackingNoise(5e-9),)}},
                   n_frames=1024, n_traces=8, key=jr.key(2), models=("standard",),
                   progress=False)
    assert res.dims == ("radius", "injections", "model")
    eta = float(bt.physics.water_viscosity(295.0))
    np.testing.assert_allclose(res["true_gamma"][:, 0, 0], 6 * np.pi * eta
                               * np.array([0.5e-6, 1e-6]), rtol=1e-14)
    # 5 nm of injected tracking noise shows in the fitted eps^2 (true eps^2 is 0 here)
    assert np.all(res["mean_tracking_var"][:, 1, 0] > 10 * res["mean_tracking_var"][:, 0, 0])


@pytest.mark.parametrize("grid, kw, match", [
    ({"k": K, "gamma": 1e-8, "exposure": 1e-3, "frame_interval": 1e-4}, {},
     "exposure <= frame_interval; got exposure = 0.001 s"),
    ({"k": [K, -1.0], "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4}, {},
     r"grid\['k'\] \(trap stiffness\) must be finite and > 0 N/m; got -1 N/m"),
    ({"k": K, "exposure": 1e-4, "frame_interval": 1e-4}, {}, "exactly one of 'gamma'"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4}, {}, "grid needs 'frame_interval'"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4, "kk": 1}, {},
     "unknown grid parameter 'kk'"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4}, {"n_traces": 10,
     "chunk_traces": 4}, "n_traces must be a multiple of chunk_traces .*; got n_traces = 10, chunk_traces = 4"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4}, {"out": "x.json"},
     "out must be a path ending in .npz; got out = 'x.json'"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4}, {"models": "naive"},
     "models must be a non-empty sequence"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4}, {"key": None},
     "key must be a JAX PRNG key"),
    ({"k": K, "gamma": 1e-8, "exposure": 1e-4, "frame_interval": 1e-4}, {"n_frames": 8},
     "n_frames must be an integer >= 16; got n_frames = 8"),
])
def test_bad_input_is_named(grid, kw, match):
    args = {"n_frames": 64, "n_traces": 4, "key": jax.random.key(0), "progress": False, **kw}
    with pytest.raises(ValueError, match=match):
        bt.sweep(grid, **args)
