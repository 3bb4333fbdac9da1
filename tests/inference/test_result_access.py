"""Results people use without reading the source: parameters by name with units, an HTML
table for notebooks, a DataFrame (pandas optional)."""

import math
import sys

import numpy as np
import pytest

from blurtrap.inference import CalibrationResult

KB = 1.380649e-23


@pytest.fixture
def res():
    return CalibrationResult(
        method="likelihood", model="standard", param_names=("k", "gamma", "tracking_var"),
        values=np.array([5e-5, 2.74e-8, 4e-18]), covariance=np.diag([1e-12, 1e-18, 1e-36]),
        temperature=295.0, k_per_recording=np.array([5e-5]), k_per_recording_err=np.array([1e-6]),
        gof={}, n_recordings=1, n_frames=65536)


def test_parameter_by_name_with_units(res):
    k = res["k"]
    assert (k.value, k.error, k.unit, k.lab_unit) == (5e-5, pytest.approx(1e-6), "N/m", "pN/nm")
    assert k.lab_value == pytest.approx(0.05) and k.lab_error == pytest.approx(1e-3)
    assert k.description == "trap stiffness"
    lo, hi = k.interval  # Wald here: value +- 1.96 SE
    assert (lo, hi) == (pytest.approx(5e-5 - 1.96e-6, rel=1e-3), pytest.approx(5e-5 + 1.96e-6,
                                                                                rel=1e-3))
    g = res["gamma"]
    assert g.unit == "N s/m" and g.lab_unit == "pN s/um" and g.lab_value == pytest.approx(0.0274)
    assert res["tracking_var"].lab_unit == "nm^2"
    d = res["D"]
    assert d.value == pytest.approx(KB * 295.0 / 2.74e-8)
    assert d.error == pytest.approx(d.value * 1e-9 / 2.74e-8)  # relative SE of gamma
    assert d.lab_unit == "um^2/s" and math.isnan(d.interval[0])
    assert "pN/nm" in repr(k) and "trap stiffness" in repr(k)
    with pytest.raises(KeyError, match="no parameter 'kappa'.*'k', 'gamma'"):
        res["kappa"]


def test_html_table_for_notebooks(res):
    html = res._repr_html_()
    assert html.startswith("<pre>") and "pN/nm" in html and "&lt;" not in html[:5]
    assert "0.05" in html


def test_dataframe(res):
    pd = pytest.importorskip("pandas")
    df = res.to_dataframe()
    assert isinstance(df, pd.DataFrame)
    assert list(df.index) == ["k", "gamma", "tracking_var", "D"]
    assert df.loc["k", "lab_value"] == pytest.approx(0.05)
    assert df.loc["gamma", "unit"] == "N s/m" and "ci_low" in df.columns


def test_dataframe_without_pandas_says_how_to_install(res, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r'blurtrap\[pandas\]'):
        res.to_dataframe()


@pytest.fixture(scope="module")
def batch():
    import jax

    import blurtrap as bt

    dt = 1 / 1500
    gamma = 6 * math.pi * 0.00093 * 1.53e-6
    x = bt.simulate(5e-5, gamma, dt, dt, 8192, key=jax.random.key(4), n_traces=6,
                    method="exact_frames", tracking_std=2e-9)
    return bt.calibrate_batch(np.asarray(x), frame_interval=dt, exposure=dt)


def test_batch_columns_by_name(batch):
    assert np.array_equal(batch["k"], batch.k) and batch["k"].shape == (6,)
    assert np.array_equal(batch["D"], batch.diffusion)
    assert set(batch["status"]) <= {"ok"} or batch["status"].dtype.kind in "UO"
    with pytest.raises(KeyError, match="columns"):
        batch["stiffness"]


def test_batch_summary_html_and_dataframe(batch):
    pytest.importorskip("pandas")
    text = batch.summary()
    assert text.startswith("6 items") and "pN/nm" in text
    assert batch._repr_html_().startswith("<pre>")
    df = batch.to_dataframe()
    assert len(df) == 6
    np.testing.assert_allclose(df["k_pN_per_nm"], batch.k * 1e3)
    np.testing.assert_allclose(df["D_um2_per_s"], batch.diffusion * 1e12)
