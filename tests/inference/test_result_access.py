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


def test_repr_is_short_without_arrays(res):
    import dataclasses

    big = dataclasses.replace(res, extras={"f": np.linspace(1, 750, 5000)})
    r = repr(big)
    assert "array" not in r and len(r) < 300
    assert "k = 0.05 +- 0.001 pN/nm" in r and "gamma = 0.0274 +- 0.001 pN s/um" in r
    assert "tracking_var = 4 +- 1 nm^2" in r and "65536 frames" in r


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


# ---- Posterior: the same access by name, an HTML table and a DataFrame ---------------------
@pytest.fixture(scope="module")
def post():
    from blurtrap.inference._posterior_result import Posterior

    rng = np.random.default_rng(7)
    n_kept, n_walkers = 100, 40
    k = rng.normal(5e-5, 1e-6, n_kept * n_walkers)
    g = rng.normal(2.74e-8, 4e-10, k.size)
    e2 = np.abs(rng.normal(4e-18, 5e-19, k.size))
    samples = {"k": k, "gamma": g, "tracking_var": e2, "diffusion": KB * 295.0 / g,
               "tau": g / k, "corner_frequency": k / (2 * np.pi * g), "force_per_nm": k * 1e-9}
    chain = np.stack([k, g, e2], axis=-1).reshape(n_kept, n_walkers, 3)
    ml = CalibrationResult(
        method="likelihood", model="standard", param_names=("k", "gamma", "tracking_var"),
        values=np.array([5e-5, 2.74e-8, 4e-18]), covariance=np.diag([1e-12, 1e-18, 1e-36]),
        temperature=295.0, k_per_recording=np.array([5e-5]),
        k_per_recording_err=np.array([1e-6]), gof={}, n_recordings=1, n_frames=65536)
    return Posterior(
        samples=samples, param_names=("k", "gamma", "tracking_var"), chain=chain,
        log_prob=rng.normal(size=(n_kept, n_walkers)),
        acceptance_fraction=np.full(n_walkers, 0.41), autocorr_time={"k": 31.0, "gamma": 29.5,
                                                                      "tracking_var": 40.2},
        ess={"k": 1290.0, "gamma": 1356.0, "tracking_var": 995.0}, burn_in=200, n_steps=300,
        n_walkers=n_walkers, likelihood="whittle", model="standard", k_mode="shared",
        temperature=295.0, seed=3, ml=ml)


def test_posterior_parameter_by_name(post):
    s = post.samples["k"]
    p = post["k"]
    assert p.value == pytest.approx(np.percentile(s, 50), rel=1e-12)
    assert p.error == pytest.approx(0.5 * (np.percentile(s, 84) - np.percentile(s, 16)),
                                    rel=1e-12)
    assert p.error == pytest.approx(1e-6, rel=0.1)  # the samples' SD (4000 draws)
    assert (p.unit, p.lab_unit, p.description) == ("N/m", "pN/nm", "trap stiffness")
    assert p.lab_value == pytest.approx(p.value * 1e3) and p.lab_error == pytest.approx(
        p.error * 1e3)
    assert p.interval == (pytest.approx(np.percentile(s, 2.5), rel=1e-12),
                          pytest.approx(np.percentile(s, 97.5), rel=1e-12))
    d = post["D"]
    assert d.name == "diffusion" and d.lab_unit == "um^2/s"
    assert d.lab_value == pytest.approx(np.median(KB * 295.0 / post.samples["gamma"]) * 1e12)
    assert post["tau"].lab_unit == "ms" and post["tau"].unit == "s"
    with pytest.raises(KeyError, match=r"no quantity 'kappa'.*'k', 'gamma'"):
        post["kappa"]
    assert "array" not in repr(post) and len(repr(post)) < 300


def _html_rows(html):
    import re

    return {cells[0]: cells for cells in (re.findall(r"<td>(.*?)</td>", row)
                                          for row in re.findall(r"<tr>(.*?)</tr>", html))
            if cells}


def test_posterior_html_table_in_lab_units(post):
    html = post._repr_html_()
    assert html.startswith("<table>") and "acceptance 0.410" in html
    rows = _html_rows(html)
    assert set(rows) == set(post.samples)
    s = post.samples["k"] * 1e3  # pN/nm
    name, med, i68, i95, unit, ess, tau = rows["k"]
    assert float(med) == pytest.approx(np.median(s), rel=1e-4) and unit == "pN/nm"
    lo, hi = (float(v) for v in i68.strip("[]").split(","))
    assert (lo, hi) == (pytest.approx(np.percentile(s, 16), rel=1e-4),
                        pytest.approx(np.percentile(s, 84), rel=1e-4))
    lo, hi = (float(v) for v in i95.strip("[]").split(","))
    assert (lo, hi) == (pytest.approx(np.percentile(s, 2.5), rel=1e-4),
                        pytest.approx(np.percentile(s, 97.5), rel=1e-4))
    assert (ess, tau) == ("1290", "31")
    g = rows["gamma"]
    assert float(g[1]) == pytest.approx(np.median(post.samples["gamma"]) * 1e6, rel=1e-4)
    assert g[4] == "pN s/um" and rows["diffusion"][5] == ""  # derived: no ESS of its own


def test_posterior_dataframe(post, monkeypatch):
    pd = pytest.importorskip("pandas")
    df = post.to_dataframe()
    assert isinstance(df, pd.DataFrame) and list(df.index) == list(post.samples)
    s = post.samples["tracking_var"]
    assert df.loc["tracking_var", "lab_value"] == pytest.approx(np.median(s) * 1e18)
    assert df.loc["tracking_var", "lab_unit"] == "nm^2"
    assert df.loc["k", "q84"] == pytest.approx(np.percentile(post.samples["k"], 84))
    assert df.loc["k", "ess"] == 1290.0 and np.isnan(df.loc["tau", "ess"])
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r'Posterior.to_dataframe needs pandas.*blurtrap\[pandas\]'):
        post.to_dataframe()


# ---- Diagnosis: ranking by name, HTML, DataFrame, no array dumps ---------------------------
@pytest.fixture
def diag(res):
    from blurtrap.diagnostics import Candidate, Diagnosis

    big = dict(res.extras, f=np.linspace(1.0, 750.0, 5000), ratio=np.ones(5000))
    fit = CalibrationResult(**{**{f: getattr(res, f) for f in (
        "method", "model", "param_names", "values", "covariance", "temperature",
        "k_per_recording", "k_per_recording_err", "gof", "n_recordings", "n_frames")},
        "extras": big})
    ranking = (
        Candidate("drift", 25.0, 1, 1e-12, 48.0, "excess power < 2 Hz: 30x", significant=True,
                  fit=fit),
        Candidate("line_noise", 1.5, 2, 0.22, -1.0, "no peak above the Bonferroni level",
                  fit=fit),
        Candidate("timing_jitter", None, 0, 1.0, None, "time stamps regular"),
    )
    return Diagnosis(model="standard", fit=fit, gof={"test": "spectral", "statistic": 812.0,
                                                     "dof": 700, "p_value": 2e-3},
                     adequate=False, ranking=ranking, threshold=0.01 / 3,
                     notes=("a note & more",))


def test_diagnosis_candidate_by_name(diag):
    assert diag["drift"] is diag.ranking[0] and diag["line_noise"].delta_aic == -1.0
    with pytest.raises(KeyError, match=r"no candidate 'hydro'.*\['drift', 'line_noise', "
                                       r"'timing_jitter'\]"):
        diag["hydro"]


def test_diagnosis_prints_without_arrays(diag):
    best = str(diag.best)
    assert best.startswith("Candidate('drift'") and "array" not in best and len(best) < 200
    r = repr(diag)
    assert "array" not in r and len(r) < 300 and "best missing effect is drift" in r
    assert str(diag) == diag.summary() and "array" not in str(diag)


def test_diagnosis_html_ranking(diag):
    html = diag._repr_html_()
    assert html.startswith("<table>") and "NOT adequate" in html and "drift" in html
    rows = _html_rows(html)
    assert list(rows) == ["drift", "line_noise", "timing_jitter"]
    assert rows["drift"][1:6] == ["25.00", "1", "48.00", "1e-12", "yes"]
    assert rows["drift"][7] == "excess power &lt; 2 Hz: 30x"  # escaped
    assert rows["timing_jitter"][1] == "n/a" and rows["line_noise"][5] == "no"
    assert "note: a note &amp; more" in html
    assert diag["drift"]._repr_html_().count("<tr>") == 2


def test_diagnosis_dataframe(diag, monkeypatch):
    pytest.importorskip("pandas")
    df = diag.to_dataframe()
    assert list(df.index) == ["drift", "line_noise", "timing_jitter"]
    assert df.loc["drift", "delta_aic"] == 48.0 and bool(df.loc["drift", "significant"])
    assert np.isnan(float(df.loc["timing_jitter", "delta_loglik"]))
    assert df.loc["line_noise", "evidence"].startswith("no peak")
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r'blurtrap\[pandas\]'):
        diag.to_dataframe()
