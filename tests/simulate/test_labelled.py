"""simulate(..., labelled=True): the grid's coordinates travel with the positions."""

import sys

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.simulate import ExposureWindows, LabelledFrames

K, TAU = 5e-5, 0.537e-3


def test_labelled_grid_has_named_axes_and_the_same_values():
    k = np.array([K, 2 * K, 3 * K])[:, None]
    w = np.array([0.2, 0.5]) * TAU
    kw = dict(key=jax.random.key(4), n_traces=3, method="exact_frames")
    plain = bt.simulate(k, K * TAU, w, TAU, 16, **kw)
    lab = bt.simulate(k, K * TAU, w, TAU, 16, labelled=True, **kw)
    assert isinstance(lab, LabelledFrames)
    assert np.array_equal(np.asarray(lab), np.asarray(plain))
    assert lab.dims == ("k", "exposure", "trace", "frame") and lab.shape == (3, 2, 3, 16)
    assert np.array_equal(lab.coord("k"), k[:, 0]) and np.array_equal(lab.coord("exposure"), w)
    assert lab.coords["gamma"][0] == () and float(lab.coords["gamma"][1]) == K * TAU
    assert lab.units["k"] == "N/m"
    # a cell picked by label is the cell picked by position
    i, j = 2, 1
    assert np.array_equal(np.asarray(lab)[list(lab.coord("k")).index(3 * K), j],
                          np.asarray(plain)[i, j])
    pytest.importorskip("xarray")
    da = lab.to_xarray()
    assert np.array_equal(da.sel(k=2 * K, exposure=w[0]).values, np.asarray(plain)[1, 0])
    assert da.attrs["units"] == "m" and float(da.gamma) == K * TAU


def test_parameters_sharing_an_axis_and_windows_and_times():
    k = np.array([K, 2 * K])
    lab = bt.simulate(k, k * TAU, ExposureWindows([0.1 * TAU, 0.5 * TAU]), TAU, 8,
                      key=jax.random.key(0), n_traces=2, method="exact_frames",
                      labelled=True, return_times=True)
    # k and gamma both vary along axis 0: neither names it alone
    assert lab.dims == ("grid_0", "window", "trace", "frame")
    assert lab.coords["k"][0] == ("grid_0",) and lab.coords["gamma"][0] == ("grid_0",)
    np.testing.assert_array_equal(lab.coord("window"), [0.1 * TAU, 0.5 * TAU])
    assert lab.times is not None and np.asarray(lab.times).shape[-1] == 8


def test_to_xarray_without_xarray(monkeypatch):
    lab = bt.simulate(K, K * TAU, TAU, TAU, 8, key=jax.random.key(0), labelled=True,
                      method="exact_frames")
    assert lab.dims == ("trace", "frame")
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match="to_xarray needs xarray"):
        lab.to_xarray()
