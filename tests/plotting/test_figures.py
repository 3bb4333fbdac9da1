"""blurtrap.plotting: each figure renders to PNG with Agg and shows what it claims to show."""

import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference import CalibrationResult, drift_extrapolation

plotting = pytest.importorskip("blurtrap.plotting")
from matplotlib.collections import PolyCollection, QuadMesh  # noqa: E402
from matplotlib.container import ErrorbarContainer  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

KT = bt.BOLTZMANN * 295.0
GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
DT = 1 / 1500
EPS2 = 4e-18


def fake_result(model="standard", k=1e-5, gamma=GAMMA, eps2=EPS2, method="psd", **kw):
    """A CalibrationResult without fitting (plots compute no fits; keeps the tests fast)."""
    names = ("k", "gamma", "tracking_var") if model == "standard" else ("k", "gamma")
    vals = np.array([k, gamma, eps2][: len(names)])
    return CalibrationResult(
        method=method, model=model, param_names=names, values=vals,
        covariance=np.diag((0.01 * vals) ** 2), temperature=295.0,
        k_per_recording=np.array(kw.pop("k_per_recording", [k])),
        k_per_recording_err=np.array(kw.pop("k_err", [0.01 * k])),
        gof={"test": "binned spectral chi2", "statistic": 10.0, "dof": 9, "p_value": 0.35},
        n_recordings=1, n_frames=4096, extras={"n_blocks": 32}, **kw)


def synth(k, gamma, w, dt, n, eps2, rng):
    """Gaussian frames with exactly the standard model's discrete spectrum (circulant
    spectral synthesis in numpy: no simulator compile, keeps these plotting tests fast)."""
    from blurtrap.plotting._common import model_psd

    rec0 = bt.Recording(rng.standard_normal(8) * 1e-9, frame_interval=dt, exposure=w)
    f = np.fft.rfftfreq(n, dt)
    f[0] = 0.25 / (n * dt)
    p = model_psd({"k": k, "gamma": gamma, "tracking_var": eps2}, rec0, f)
    amp = np.sqrt(p * n / dt)
    z = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / np.sqrt(2)
    z[0] = 0.0
    if n % 2 == 0:
        z[-1] = rng.standard_normal()
    return np.fft.irfft(amp * z, n)


@pytest.fixture(scope="module")
def series():
    """2 powers x 4 exposures with the standard model's statistics, 2 nm tracking noise."""
    rng = np.random.default_rng(11)
    ks = np.array([1e-5, 3e-5])
    ws = np.array([1e-4, 4e-4, DT, 2e-3])
    dts = np.maximum(ws, DT)
    recs = [bt.Recording(synth(ks[i], GAMMA, ws[j], dts[j], 4096, EPS2, rng),
                         frame_interval=dts[j], exposure=ws[j], laser_power=0.1 * (1 + 2 * i))
            for i in range(2) for j in range(4)]
    return ks, ws, recs


def png(fig, tmp_path, name="fig.png"):
    assert isinstance(fig, Figure)
    path = tmp_path / name
    fig.savefig(path, dpi=50)
    assert path.stat().st_size > 1000
    return path


def visible_axes(fig):
    return [a for a in fig.axes if a.axison]


def test_fig1a_universal_curve(tmp_path):
    ks = np.array([5e-5, 1.25e-5])
    gammas = ks * np.array([0.537e-3, 2.148e-3])
    wins = (1e-4, 5e-4, 2e-3, 8e-3)
    # frames with the blurred variance kT/k S(W k/gamma), shaped like simulate's output with
    # ExposureWindows: (settings, windows, traces, frames)
    alpha = np.asarray(wins)[None, :] * (ks / gammas)[:, None]
    var = KT / ks[:, None] * np.asarray(bt.blur_factor(alpha))
    x = np.sqrt(var)[:, :, None, None] * np.random.default_rng(0).standard_normal((2, 4, 1, 3000))
    fig = plotting.fig1a_universal_curve(x, wins, ks, gammas, frame_interval=8e-3)
    png(fig, tmp_path)
    (ax,) = fig.axes
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    assert len(bars) == 2  # one series per setting
    assert "alpha" in ax.get_xlabel() and "dimensionless" in ax.get_xlabel()
    assert "dimensionless" in ax.get_ylabel()
    assert ax.get_xscale() == "log"
    # the points collapse on S(alpha) within a few standard errors
    for c, k, g in zip(bars, ks, gammas, strict=True):
        a, y = (np.asarray(v, dtype=float) for v in c.lines[0].get_data())
        s = np.asarray(bt.blur_factor(a))
        np.testing.assert_allclose(y, s, rtol=0.1)
        np.testing.assert_allclose(a, np.asarray(wins) * k / g)
    assert len(ax.get_legend().get_texts()) == 3


def test_fig1b_histogram(series, tmp_path):
    ks, ws, recs = series
    rec = recs[3]  # k = 1e-5, W = 2 ms
    fig = plotting.fig1b_histogram(rec, {"k": ks[0], "gamma": GAMMA, "tracking_var": EPS2},
                                   bins=30)
    png(fig, tmp_path)
    (ax,) = fig.axes
    assert "[nm]" in ax.get_xlabel() and "[1/nm]" in ax.get_ylabel()
    assert len(ax.patches) == 30
    lines = ax.get_lines()
    assert len(lines) == 2
    assert lines[1].get_linestyle() == ":"  # blur-free normal dotted
    # blurred normal is narrower than the blur-free one
    assert lines[0].get_ydata().max() > lines[1].get_ydata().max()


def test_fig3_fractional_variance(series, tmp_path):
    ks, ws, recs = series
    params = {"k": np.repeat(ks, 4), "gamma": GAMMA, "tracking_var": EPS2}
    fig = plotting.fig3_fractional_variance(recs, params)
    png(fig, tmp_path)
    (ax,) = fig.axes
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    assert len(bars) == 2  # one per laser power
    for c in bars:
        a, y = (np.asarray(v, dtype=float) for v in c.lines[0].get_data())
        np.testing.assert_allclose(y, np.asarray(bt.blur_factor(a)), rtol=0.12)
    assert "dimensionless" in ax.get_ylabel()
    assert "mW" in ax.get_legend().get_texts()[1].get_text()


def test_fig3_rejects_result_of_other_recordings(series):
    _, _, recs = series
    with pytest.raises(ValueError, match="per-recording stiffnesses"):
        plotting.fig3_fractional_variance(recs, fake_result(k_per_recording=[1e-5, 2e-5],
                                                            k_err=[1e-7, 1e-7]))


def test_fig4_stiffness_vs_power(series, tmp_path):
    ks, ws, recs = series
    corrected = {0.1: (ks[0], 1e-7), 0.3: (ks[1], 2e-7)}
    c = 1e-4
    vvp = CalibrationResult(
        method="variance_vs_power", model="standard", param_names=("c", "gamma", "tracking_var"),
        values=np.array([c, GAMMA, EPS2]), covariance=np.eye(3) * 0, temperature=295.0,
        k_per_recording=np.array([1e-5, 3e-5]), k_per_recording_err=np.array([1e-7, 3e-7]),
        gof={}, n_recordings=2, n_frames=8192)
    fig = plotting.fig4_stiffness_vs_power(recs, corrected, naive_exposures=(DT, 2e-3),
                                           power_fits={2e-3: vvp}, truth_c=c)
    png(fig, tmp_path)
    (ax,) = fig.axes
    assert ax.get_xlabel() == "laser power P [mW]"
    assert "[pN/nm]" in ax.get_ylabel()
    bars = [b for b in ax.containers if isinstance(b, ErrorbarContainer)]
    assert len(bars) == 3  # corrected + naive at two exposures
    x, y = (np.asarray(v, dtype=float) for v in bars[0].lines[0].get_data())
    np.testing.assert_allclose(x, [100.0, 300.0])
    np.testing.assert_allclose(y, ks * 1e3)
    # naive k at 2 ms is above the truth (blur lowers the variance)
    x2, y2 = (np.asarray(v, dtype=float) for v in bars[2].lines[0].get_data())
    assert np.all(y2 > ks * 1e3)
    # fit curve through the naive points (dashed), corrected line (dash-dot), truth line
    styles = [ln.get_linestyle() for ln in ax.get_lines() if ln.get_label()[0] != "_"]
    assert styles.count("--") == 1 and styles.count("-.") == 1


def test_fig5_highpass(series, tmp_path):
    ks, ws, recs = series
    rec = recs[2]
    t = np.arange(rec.n_frames) * DT
    drifted = bt.Recording(rec.positions + 8e-9 * np.sin(2 * np.pi * 0.3 * t),
                           frame_interval=DT, exposure=DT)
    params = {"k": ks[0], "gamma": GAMMA, "tracking_var": EPS2}
    fig = plotting.fig5_highpass(drifted, params=params)
    png(fig, tmp_path)
    (ax,) = fig.axes
    assert "[Hz]" in ax.get_xlabel() and "nm$^2$" in ax.get_ylabel()
    fc = ks[0] / (2 * math.pi * GAMMA)
    v0, *_ = drift_extrapolation(drifted.positions, DT, corner_frequency=fc)
    star = [ln for ln in ax.get_lines() if ln.get_marker() == "*"]
    assert len(star) == 1
    np.testing.assert_allclose(star[0].get_ydata()[0], v0 * 1e18)
    cross = [ln for ln in ax.get_lines() if ln.get_marker() == "x"][0]
    assert cross.get_ydata()[0] > star[0].get_ydata()[0]  # drift inflates the raw variance
    with pytest.raises(ValueError, match="corner_frequency"):
        plotting.fig5_highpass(drifted)


def test_fig6_psd_and_fig7(series, tmp_path):
    ks, ws, recs = series
    rec = recs[2]  # W = dt
    fits = [fake_result(m, k=ks[0]) for m in ("standard", "naive", "naive_aliased")]
    fig = plotting.fig6_psd(rec, fits)
    png(fig, tmp_path, "f6.png")
    (ax,) = fig.axes
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    assert "[Hz]" in ax.get_xlabel() and "[nm$^2$/Hz]" in ax.get_ylabel()
    lines = ax.get_lines()
    assert len(lines) == 4  # data + 3 models
    assert [ln.get_linestyle() for ln in lines[1:]] == ["-", "--", ":"]
    assert len(lines[0].get_xdata()) == (rec.n_frames // 32) // 2  # 32 blocks from extras
    # the blur-corrected aliased model lies below the naive aliased one near Nyquist
    assert lines[1].get_ydata()[-1] < lines[3].get_ydata()[-1]

    # 8 blocks of 512 frames: the finite-block (leakage) bias of the periodogram is ~1 %
    fig = plotting.fig7_deviation(rec, fits[0], n_blocks=8)
    png(fig, tmp_path, "f7.png")
    a1, a2 = fig.axes
    assert "[Hz]" in a1.get_xlabel() and "dimensionless" in a1.get_ylabel()
    band = [ln for ln in a1.get_lines() if ln.get_linestyle() == "--"]
    assert len(band) == 2
    np.testing.assert_allclose(sorted(b.get_ydata()[0] for b in band),
                               [1 - 1 / math.sqrt(8), 1 + 1 / math.sqrt(8)])
    assert len(a2.patches) == 25 and len(a2.get_lines()) == 2
    ratio = a1.get_lines()[0].get_ydata()
    assert ratio.size == 256
    # truth as the "fit": mean data/model is 1 within 3 standard errors (1/sqrt(8 * 256))
    assert abs(np.mean(ratio) - 1) < 3 / math.sqrt(8 * 256) + 0.01


def test_residuals_before_after(series, tmp_path):
    ks, _, recs = series
    fig = plotting.residuals_before_after(fake_result("naive", k=ks[0]),
                                          fake_result("standard", k=ks[0]), recs[2])
    png(fig, tmp_path)
    a1, a2 = fig.axes
    assert "naive" in a1.get_title() and "standard" in a2.get_title()
    assert "[Hz]" in a2.get_xlabel()
    for a in (a1, a2):
        assert len(a.get_lines()) == 3  # points, binned mean, unity
        assert any(isinstance(c, PolyCollection) for c in a.collections)  # expected band


def test_corner(tmp_path):
    rng = np.random.default_rng(0)
    samples = {"k": 1e-5 * (1 + 0.02 * rng.standard_normal(500)),
               "gamma": GAMMA * (1 + 0.03 * rng.standard_normal(500)),
               "tracking_var": EPS2 * (1 + 0.1 * rng.standard_normal(500))}
    fig = plotting.corner(samples, truths={"k": 1e-5, "gamma": GAMMA, "tracking_var": EPS2})
    png(fig, tmp_path)
    assert len(fig.axes) == 9
    assert len(visible_axes(fig)) == 6
    axes = np.array(fig.axes).reshape(3, 3)
    assert axes[2, 0].get_xlabel() == "k [pN/nm]"
    assert axes[2, 1].get_xlabel() == "gamma [pN s/um]"
    assert axes[1, 0].get_ylabel() == "gamma [pN s/um]"
    assert axes[2, 2].get_xlabel() == "eps^2 [nm^2]"
    # marginals in lab units: k near 0.01 pN/nm, with the truth line drawn
    lo, hi = axes[0, 0].get_xlim()
    assert lo < 0.01 < hi
    assert any(isinstance(c, QuadMesh) for c in axes[1, 0].collections)
    with pytest.raises(ValueError, match="mapping"):
        plotting.corner([1, 2, 3])


def test_naive_error_map(tmp_path):
    k = np.geomspace(5e-6, 2e-4, 12)
    w = np.geomspace(5e-5, 5e-3, 10)
    kk, ww = np.meshgrid(k, w, indexing="ij")
    err = 1 / np.asarray(bt.blur_factor(ww * kk / GAMMA)) - 1
    fig = plotting.naive_error_map(k, w, err)
    png(fig, tmp_path)
    assert len(fig.axes) == 2  # map + colorbar
    ax, cb = fig.axes
    assert "[ms]" in ax.get_xlabel() and "[pN/nm]" in ax.get_ylabel()
    assert "[%]" in cb.get_ylabel()
    mesh = [c for c in ax.collections if isinstance(c, QuadMesh)]
    assert len(mesh) == 1
    np.testing.assert_allclose(np.asarray(mesh[0].get_array()).reshape(12, 10), 100 * err)
    with pytest.raises(ValueError, match="shape"):
        plotting.naive_error_map(k, w, err.T)


def test_naive_error_map_into_axes(tmp_path):
    from matplotlib.figure import Figure

    fig = Figure(layout="constrained")
    axes = fig.subplots(1, 2)
    k, w = np.array([1e-5, 2e-5]), np.array([1e-4, 1e-3])
    for ax in axes:
        out = plotting.naive_error_map(k, w, np.array([[0.1, 0.3], [0.2, 0.5]]), ax=ax)
        assert out is fig
    png(fig, tmp_path)
    assert len(fig.axes) == 4


def test_diagnose_ranking(tmp_path):
    ranking = [{"effect": "tracking_noise", "delta_aic": 3.0},
               {"effect": "motion_blur", "delta_aic": 250.0, "p_value": 1e-9},
               {"effect": "drift", "delta_aic": -1.5}]
    fig = plotting.diagnose_ranking(ranking)
    png(fig, tmp_path)
    (ax,) = fig.axes
    assert len(ax.patches) == 3
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels[0] == "motion_blur"  # best at the top (highest y)
    widths = sorted(p.get_width() for p in ax.patches)
    assert widths == [-1.5, 3.0, 250.0]
    assert "AIC" in ax.get_xlabel()
    empty = plotting.diagnose_ranking([])
    png(empty, tmp_path, "empty.png")
    assert "nothing is missing" in empty.axes[0].texts[0].get_text()
    with pytest.raises(ValueError, match="delta_aic"):
        plotting.diagnose_ranking([{"effect": "drift"}])


def test_plotting_imports_pyplot_only_to_make_a_figure():
    """Importing blurtrap.plotting selects no backend; a figure made without ax=/fig= is a
    pyplot figure (so that Jupyter's inline backend displays it)."""
    import os
    import subprocess
    import sys

    code = ("import blurtrap.plotting, sys, numpy as np; "
            "assert 'matplotlib.pyplot' not in sys.modules; "
            "fig = blurtrap.plotting.diagnose_ranking([{'effect': 'drift', 'delta_aic': 1.0}]); "
            "import matplotlib.pyplot as plt; "
            "sys.exit(0 if plt.get_fignums() == [fig.number] else 1)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "MPLBACKEND": "Agg"})
    assert out.returncode == 0, out.stderr


def test_sample_variance_se_np_matches_physics():
    from blurtrap.plotting._common import sample_variance_se_np

    w = np.array([1e-4, 1e-3, 5e-3])
    ref = np.asarray(bt.sample_variance_se(20000, 2e-5, GAMMA, w, 5e-3, 295.0, EPS2))
    got = sample_variance_se_np(20000, 2e-5, GAMMA, w, 5e-3, 295.0, EPS2)
    np.testing.assert_allclose(got, ref, rtol=2e-3)
