"""bt.sweep: statistics against a direct computation, resumption, labels and errors."""

import itertools
import json
import sys
from typing import Any

import jax
import jax.random as jr
import numpy as np
import pytest

import blurtrap as bt

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from _sweep_case import DT, GRID, KW, PSD_BLOCKS, K, run  # noqa: E402


@pytest.fixture(scope="module")
def full():
    return run()


def _same(a, b):
    assert set(a.data) == set(b.data)
    for k in a.data:
        assert np.array_equal(a.data[k], b.data[k], equal_nan=True), k


def test_statistics_equal_a_direct_computation(full):
    """The streamed statistics equal numpy over every recording of the cell: the same keys
    (fold_in of cell and chunk index), the same fits (per method: calibrate_batch with
    n_blocks 1 for "whittle", 16 for "psd:16"), mean/SD/coverage
    computed in one go."""
    assert full.dims == ("k", "exposure", "model", "method") and full.shape == (3, 2, 2, 2)
    assert list(full.coords["method"]) == ["whittle", "psd:16"]
    key = jr.key(11)
    for g in range(6):
        i, j = np.unravel_index(g, (3, 2))
        k, w = GRID["k"][i], GRID["exposure"][j]
        y = np.concatenate([np.asarray(bt.simulate(
            k, GRID["gamma"], w, DT, 2048, key=jr.fold_in(jr.fold_in(key, g), c),
            n_traces=8, method="exact_frames", tracking_std=0.5e-9, dtype=np.float64))
            for c in range(2)])
        for (m, model), (q, blocks) in itertools.product(
                enumerate(KW["models"]), enumerate((1, PSD_BLOCKS[i]))):
            at = (i, j, m, q)
            assert full["n_blocks"][at] == blocks
            b = [bt.calibrate_batch(y[c * 8:(c + 1) * 8], frame_interval=DT, exposure=w,
                                    model=model, n_blocks=blocks, gof_threshold=0.0)
                 for c in range(2)]
            ok = np.concatenate([x.success for x in b])
            assert full["n_ok"][at] == ok.sum() and full["n_items"][at] == 16
            for p, true in (("k", k), ("gamma", GRID["gamma"])):
                v = np.concatenate([getattr(x, p) for x in b])[ok]
                e = np.concatenate([getattr(x, p + "_err") for x in b])[ok]
                np.testing.assert_allclose(full["mean_" + p][at], v.mean(), rtol=1e-13)
                np.testing.assert_allclose(full["sd_" + p][at], v.std(ddof=1), rtol=1e-10)
                np.testing.assert_allclose(full["se_" + p][at], e.mean(), rtol=1e-13)
                np.testing.assert_allclose(full["bias_" + p][at],
                                           100 * (v.mean() - true) / true, rtol=1e-10)
                cover = np.mean(np.abs(v - true) <= 1.959963984540054 * e)
                assert full["coverage_" + p][at] == cover
    # the naive model fits no tracking noise: no statistics for it
    assert np.all(np.isnan(full["mean_tracking_var"][..., 0, :]))
    assert np.all(np.isfinite(full["mean_tracking_var"][..., 1, :]))


def test_naive_model_is_biased_where_the_standard_model_is_not(full):
    """Blur, aliasing and tracking noise bias the naive fit by many standard errors of the
    mean (SEM = SD / sqrt(n_ok), from the sweep's own SD); the standard model stays within
    4 SEM in every cell (16 recordings per cell: 4 SEM is far in the t_15 tail)."""
    for p in ("k", "gamma"):
        z = full["bias_" + p] / (100 * full["sd_" + p] / np.sqrt(full["n_ok"])
                                 / full["true_" + p])
        z = z[..., 0]  # the Whittle fits (the blocked PSD's naive k bias is 3.996 SEM at 1 cell)
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
    for methods in (("whittle",), ("psd", "whittle"), ("whittle", "psd:8")):
        with pytest.raises(ValueError, match="different sweep"):  # the methods are its identity
            run(out=out, methods=methods)
    assert seen == [(1, 2), (2, 2)]


def test_labels_dataframe_xarray_summary_plot(full, monkeypatch):
    assert list(full.coords["k"]) == GRID["k"] and list(full.coords["model"]) == ["naive",
                                                                                  "standard"]
    df = full.to_dataframe()
    assert len(df) == 24 and list(df.columns[:4]) == ["k", "exposure", "model", "method"]
    row = df[(df.k == 2 * K) & (df.exposure == DT) & (df.model == "standard")
             & (df.method == "psd:16")].iloc[0]
    assert row.bias_k == full["bias_k"][1, 1, 1, 1] and row.n_blocks == PSD_BLOCKS[1]
    assert row.bias_k != full["bias_k"][1, 1, 1, 0]  # the Whittle fits of the same traces
    pytest.importorskip("xarray")
    ds = full.to_xarray()
    # a dict: sel's keyword `method` is its own (inexact matching), not the axis
    assert float(ds.bias_k.sel({"k": 2 * K, "exposure": DT, "model": "standard",
                                "method": "psd:16"})) == row.bias_k
    assert list(ds.method.values) == ["whittle", "psd:16"]
    assert ds.k.attrs["units"] == "N/m"
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match="to_xarray needs xarray"):
        full.to_xarray()
    back = json.loads(json.dumps(full.to_dict()))
    assert back["dims"] == ["k", "exposure", "model", "method"]
    assert back["attrs"]["n_traces"] == 16 and back["coords"]["method"] == ["whittle", "psd:16"]
    assert back["data"]["bias_k"][1][1][1][1] == row.bias_k
    text = full.summary()
    assert "k [pN/nm]" in text and "exposure [ms]" in text and "method" in text
    assert "0.1 | 0.2685 | standard | psd:16 | " in text
    assert "blocks" not in text  # the block count is no failure
    fig = full.plot(x="exposure", y="bias_k")
    assert len(fig.axes[0].lines) == 3 * 2 * 2 + 1  # k x model x method lines, the zero line
    assert "0.1, standard, psd:16" in [ln.get_label() for ln in fig.axes[0].lines]
    for x in ("model", "method"):
        with pytest.raises(ValueError, match="x must be a numeric grid axis"):
            full.plot(x=x)
    with pytest.raises(ValueError, match="y must be a statistic"):
        full.plot(x="k", y="bias")


def test_radius_and_injection_axes():
    res = bt.sweep({"k": K, "radius": [0.5e-6, 1e-6], "exposure": 1e-4, "frame_interval": 1e-4,
                    "injections": {"none": (), "noise": (bt.TrackingNoise(5e-9),)}},
                   n_frames=1024, n_traces=8, key=jr.key(2), models=("standard",),
                   progress=False)
    assert res.dims == ("radius", "injections", "model", "method")
    assert res.shape == (2, 2, 1, 1) and list(res.coords["method"]) == ["whittle"]
    eta = float(bt.physics.water_viscosity(295.0))
    np.testing.assert_allclose(res["true_gamma"][:, 0, 0, 0], 6 * np.pi * eta
                               * np.array([0.5e-6, 1e-6]), rtol=1e-14)
    # 5 nm of injected tracking noise shows in the fitted eps^2 (true eps^2 is 0 here)
    assert np.all(res["mean_tracking_var"][:, 1, 0, 0]
                  > 10 * res["mean_tracking_var"][:, 0, 0, 0])


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


ONE_CELL = {"k": K, "gamma": K * 0.537e-3, "exposure": DT, "frame_interval": DT}


@pytest.mark.parametrize("kw, match", [
    ({"methods": ("whittle", "exact")}, r"unknown calibration method methods\[1\] = 'exact'; "
     r"expected 'whittle' \(Whittle likelihood\), 'psd' .* or 'psd:B'"),
    ({"methods": ("Whittle",)}, r"unknown calibration method methods\[0\] = 'Whittle'"),
    ({"methods": (1,)}, r"unknown calibration method methods\[0\] = 1; expected"),
    ({"methods": ("psd:1",)}, r"methods\[0\] = 'psd:1': the block count B of 'psd:B' must be "
     r"an integer >= 2 \(use 'whittle' for one block\); got '1'"),
    ({"methods": ("psd:x",)}, r"methods\[0\] = 'psd:x': .* got 'x'"),
    ({"methods": ("psd:16",)}, r"methods\[0\] = 'psd:16' leaves 4 frames per block of "
     r"n_frames = 64; need >= 8 \(at most 8 blocks\)"),
    ({"methods": "whittle"}, "methods must be a non-empty sequence of calibration method names"),
    ({"methods": ()}, "methods must be a non-empty sequence"),
    ({"methods": ("psd", "whittle", "psd")}, r"methods must be distinct; got \['psd', 'whittle', "
     r"'psd'\]"),
    ({"methods": ("psd:8", "psd:08")}, "methods must be distinct"),
    ({"methods": ("whittle",), "n_blocks": 4}, r"pass the calibration method as methods or as "
     r"n_blocks, not both; got methods = \('whittle',\), n_blocks = 4"),
    ({"n_blocks": 0}, r"n_blocks must be an integer >= 1 \(1: Whittle, > 1: blocked PSD\); got "
     "n_blocks = 0"),
    ({"n_blocks": 2.0}, "n_blocks must be an integer >= 1 .*; got n_blocks = 2.0"),
])
def test_bad_methods_are_named(kw, match):
    args = {"n_frames": 64, "n_traces": 4, "key": jax.random.key(0), "progress": False, **kw}
    with pytest.raises(ValueError, match=match):
        bt.sweep(ONE_CELL, **args)


def test_n_blocks_still_chooses_the_method():
    """The older n_blocks argument: 1 is methods=("whittle",), B > 1 is ("psd:B",); the
    numbers are those of the methods spelt out (and "psd:4" those of calibrate_batch with 4
    blocks, which differ from Whittle's)."""
    kw: dict[str, Any] = dict(n_frames=512, n_traces=4, key=jr.key(3), progress=False,
                              gof_threshold=0.0)
    old = bt.sweep(ONE_CELL, n_blocks=4, **kw)
    new = bt.sweep(ONE_CELL, methods=("psd:4",), **kw)
    assert list(old.coords["method"]) == ["psd:4"] and old["n_blocks"].ravel().tolist() == [4]
    _same(old, new)
    whittle = bt.sweep(ONE_CELL, n_blocks=1, **kw)
    assert list(whittle.coords["method"]) == ["whittle"]
    _same(whittle, bt.sweep(ONE_CELL, **kw))
    y = np.asarray(bt.simulate(K, ONE_CELL["gamma"], DT, DT, 512, key=jr.fold_in(
        jr.fold_in(jr.key(3), 0), 0), n_traces=4, method="exact_frames", dtype=np.float64))
    b = bt.calibrate_batch(y.reshape(4, 512), frame_interval=DT, exposure=DT, n_blocks=4,
                           model="standard", gof_threshold=0.0)
    np.testing.assert_allclose(old["mean_k"].ravel(), b.k[b.success].mean(), rtol=1e-13)
    assert old["mean_k"].ravel()[0] != whittle["mean_k"].ravel()[0]


def test_psd_uses_calibrates_default_block_count_per_cell():
    """"psd" picks, per cell, the block count calibrate(method="psd") uses at the cell's true
    tau: min(128, N // 64, N dt / (100 tau)) rounded down to a power of two. Hand-computed for
    2048-frame records at dt = tau / 2 (1024 tau: 10, 20, 40 blocks of 100 tau -> 8, 16, 32)
    and 512 frames (the N // 64 = 8 cap), and the sweep's statistic for one cell."""
    from blurtrap.sweeps._methods import default_blocks

    tau = 0.537e-3
    assert [default_blocks(2048, tau / 2, tau * f) for f in (1, 0.5, 0.25)] == [8, 16, 32]
    assert default_blocks(512, tau / 2, tau / 4) == 8
    assert default_blocks(256, tau / 2, tau * 20) == 1  # too short for 2 blocks: Whittle
    res = bt.sweep(ONE_CELL, n_frames=512, n_traces=4, key=jr.key(3), methods=("psd",),
                   progress=False, gof_threshold=0.0)
    expected = default_blocks(512, DT, ONE_CELL["gamma"] / ONE_CELL["k"])
    assert res["n_blocks"].ravel().tolist() == [expected]
    rec = bt.Recording(np.asarray(bt.simulate(K, ONE_CELL["gamma"], DT, DT, 512,
                                              key=jr.key(4), dtype=np.float64)).ravel(),
                       frame_interval=DT, exposure=DT)
    notes = " ".join(bt.calibrate(rec, method="psd").notes)  # tau estimated there: same count
    assert f"psd: {expected} blocks" in notes, notes
