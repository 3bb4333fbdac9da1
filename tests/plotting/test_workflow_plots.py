"""Residuals work for a RecordingSet on a log ratio axis, corner tick labels do not collide,
and figures are made through pyplot (so Jupyter's inline backend shows them) unless
`ax=`/`fig=` says where to draw."""

import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference import CalibrationResult

plotting = pytest.importorskip("blurtrap.plotting")
import matplotlib.pyplot as plt  # noqa: E402

GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
DT = 1 / 1500
EPS2 = 4e-18
DRIFT = [{"effect": "drift", "delta_aic": 1.0}]


def fake_fit(model="standard", k=1e-5, gof_p=0.35, n_rec=1):
    names = ("k", "gamma", "tracking_var")
    vals = np.array([k, GAMMA, EPS2])
    return CalibrationResult(
        method="likelihood", model=model, param_names=names, values=vals,
        covariance=np.diag((0.01 * vals) ** 2), temperature=295.0,
        k_per_recording=np.full(n_rec, k), k_per_recording_err=np.full(n_rec, 0.01 * k),
        gof={"test": "binned spectral chi2", "statistic": 130.0, "dof": 125, "p_value": gof_p},
        n_recordings=n_rec, n_frames=4096 * n_rec, extras={"n_blocks": 1})


def noise_recording(seed, n=4096, drift=0.0):
    rng = np.random.default_rng(seed)
    from blurtrap.plotting._common import model_psd

    rec0 = bt.Recording(rng.standard_normal(8) * 1e-9, frame_interval=DT, exposure=DT)
    f = np.fft.rfftfreq(n, DT)
    f[0] = 0.25 / (n * DT)
    amp = np.sqrt(model_psd({"k": 1e-5, "gamma": GAMMA, "tracking_var": EPS2}, rec0, f) * n / DT)
    z = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / np.sqrt(2)
    z[0] = 0.0
    x = np.fft.irfft(amp * z, n) + drift * np.cumsum(rng.standard_normal(n))
    return bt.Recording(x, frame_interval=DT, exposure=DT)


def render(fig, tmp_path, name="fig.png"):
    path = tmp_path / name
    fig.savefig(path, dpi=50)
    assert path.stat().st_size > 1000


# --------------------------------------------------------------------------------------------
# pyplot figures (shown by Jupyter's inline backend), ax=/fig= draw where told
# --------------------------------------------------------------------------------------------
def test_figures_are_made_through_pyplot():
    before = set(plt.get_fignums())
    fig = plotting.diagnose_ranking(DRIFT)
    assert fig.number in set(plt.get_fignums()) - before
    plotting.close(fig)
    assert fig.number not in plt.get_fignums()


def test_ax_and_fig_draw_where_told_without_new_pyplot_figures(tmp_path):
    from matplotlib.figure import Figure

    rec = noise_recording(5, n=1024)
    before = len(plt.get_fignums())
    host = Figure()
    ax = host.subplots()
    assert plotting.diagnose_ranking(DRIFT, ax=ax) is host
    for make in (lambda f: plotting.residuals_before_after(fake_fit(), fake_fit(), rec, fig=f),
                 lambda f: plotting.fig7_deviation(rec, fake_fit(), n_blocks=4, fig=f),
                 lambda f: plotting.corner({"k": np.linspace(1, 2, 50) * 1e-5,
                                            "gamma": np.linspace(1, 2, 50) * GAMMA}, fig=f)):
        f = Figure()
        assert make(f) is f and f.axes
    assert len(plt.get_fignums()) == before
    with pytest.raises(ValueError, match="empty figure"):
        plotting.residuals_before_after(fake_fit(), fake_fit(), rec, fig=host)


def test_save_closes_the_figure(tmp_path):
    fig = plotting.diagnose_ranking(DRIFT)
    plotting.save(fig, tmp_path / "r.png", dpi=40)
    assert (tmp_path / "r.png").stat().st_size > 1000
    assert fig.number not in plt.get_fignums()


# --------------------------------------------------------------------------------------------
# corner: readable ticks
# --------------------------------------------------------------------------------------------
def label_boxes(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    return [(t.get_text(), t.get_window_extent(renderer)) for ax in fig.axes if ax.axison
            for t in ax.get_xticklabels() + ax.get_yticklabels()
            if t.get_visible() and t.get_text()]


@pytest.mark.parametrize("seed", range(4))
def test_corner_tick_labels_do_not_overlap(seed, tmp_path):
    """Posterior widths of 0.2-5 % (as in notebook 04): no two tick labels of the figure
    touch (the old corner plot had colliding labels for all of these)."""
    rng = np.random.default_rng(seed)
    rel = rng.uniform(0.002, 0.05, 3)
    samples = {"k": 2e-5 * (1 + rel[0] * rng.standard_normal(2000)),
               "gamma": 2.68e-8 * (1 + rel[1] * rng.standard_normal(2000)),
               "tracking_var": 4.1e-18 * (1 + rel[2] * rng.standard_normal(2000))}
    fig = plotting.corner(samples)
    render(fig, tmp_path)
    boxes = label_boxes(fig)
    assert len(boxes) >= 8
    for i, (ta, a) in enumerate(boxes):
        for tb, b in boxes[i + 1:]:
            assert not a.overlaps(b), (ta, tb)
    for ax in fig.axes:
        if ax.axison:
            assert len([t for t in ax.get_xticklabels() if t.get_text()]) <= 4


# --------------------------------------------------------------------------------------------
# residuals_before_after
# --------------------------------------------------------------------------------------------
def test_residuals_for_a_recording_set(tmp_path):
    recs = bt.RecordingSet([noise_recording(1), noise_recording(2, n=2048)])
    fit = fake_fit(n_rec=2)
    fig = plotting.residuals_before_after(fit, fit, recs, labels=("base", "with drift"))
    render(fig, tmp_path)
    a1, a2 = fig.axes
    assert "2 recordings pooled" in a1.get_title()
    pts = a1.get_lines()[0]
    assert pts.get_xdata().size == 2048 + 1024  # every ordinate of both recordings
    fig = plotting.residuals_before_after(fit, fit, list(recs), per_recording=True)
    render(fig, tmp_path, "per.png")
    assert len(fig.axes) == 4
    assert [a.get_lines()[0].get_xdata().size for a in fig.axes] == [2048, 1024, 2048, 1024]


def test_residuals_ratio_axis_is_logarithmic_and_shows_a_large_drift(tmp_path):
    rec = noise_recording(4, drift=2e-9)
    fit = fake_fit()
    fig = plotting.residuals_before_after(fit, fit, rec)
    render(fig, tmp_path)
    for ax in fig.axes:
        assert ax.get_yscale() == "log"
        ratio = ax.get_lines()[0].get_ydata()
        assert ratio.max() > 100  # the drift's low-frequency excess ...
        assert ax.get_ylim()[1] >= ratio.max()  # ... is on the axis
