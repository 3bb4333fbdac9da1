"""The figures of the find-the-missing-effect workflow: the ranking plot draws the Diagnosis's
own verdicts (significance, plausibility, adequacy) and every row of a real run, residuals work
for a RecordingSet on a log ratio axis, corner tick labels do not collide, and figures are made
through pyplot (so Jupyter's inline backend shows them) unless `ax=`/`fig=` says where to draw."""

import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.diagnostics import Candidate, Diagnosis
from blurtrap.inference import CalibrationResult

plotting = pytest.importorskip("blurtrap.plotting")
import matplotlib.colors as mcolors  # noqa: E402
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


# --------------------------------------------------------------------------------------------
# diagnose_ranking: the Diagnosis's verdicts, not thresholds of its own
# --------------------------------------------------------------------------------------------
RED = mcolors.to_rgba("C3")


def cand(effect, dll, p, dof=1, significant=False, plausible=True, delta_aic="auto"):
    da = (2 * dll - 2 * dof if dll is not None else None) if delta_aic == "auto" else delta_aic
    return Candidate(effect, dll, dof, p, da, "evidence", significant=significant,
                     plausible=plausible)


def diagnosis(ranking, adequate, gof_p=0.35, threshold=0.05 / 6):
    return Diagnosis(model="standard", fit=fake_fit(gof_p=gof_p), gof=fake_fit(gof_p=gof_p).gof,
                     adequate=adequate, ranking=tuple(ranking), threshold=threshold)


def rows_of(fig):
    """The axes, {effect: (bar or None, tick label)} and the effects top to bottom."""
    (ax,) = fig.axes
    labels = [t.get_text() for t in ax.get_yticklabels()]
    order = [lab.split("\n")[0] for _, lab in sorted(zip(ax.get_yticks(), labels, strict=True),
                                                       key=lambda it: -it[0])]
    rows = {}
    for y, lab in zip(ax.get_yticks(), labels, strict=True):
        # the bar of a row: centred on its tick and drawn in data coordinates
        bar = [p for p in ax.patches if abs(p.get_y() + p.get_height() / 2 - y) < 1e-9
               and "not comparable" not in (p.get_gid() or "")]
        assert len(bar) <= 1
        rows[lab.split("\n")[0]] = (bar[0] if bar else None, lab)
    return ax, rows, order


def control_diagnosis():
    """A control with nothing hidden: line_noise has dAIC 15 but its searched-frequency p-value
    is 0.09, so diagnose calls it not significant and the model adequate; hydrodynamics has the
    largest dAIC but needs a radius above the Stokes radius (implausible); timing_jitter is
    outside the likelihood (delta_aic None). Ordered as diagnose orders them."""
    return diagnosis([cand("hydrodynamics", 30.0, 1e-12, plausible=False),
                      cand("line_noise", 9.5, 0.09, dof=2),
                      cand("anharmonicity", 0.05, 0.75),
                      cand("timing_jitter", None, 1.0, dof=0)], adequate=True)


@pytest.mark.parametrize("form", ["diagnosis", "candidates", "dicts"])
def test_ranking_colours_follow_the_diagnosis_not_thresholds(form, tmp_path):
    d = control_diagnosis()
    arg = {"diagnosis": d, "candidates": d.ranking,
           "dicts": [c.to_dict() for c in d.ranking]}[form]
    fig = plotting.diagnose_ranking(arg)
    render(fig, tmp_path)
    ax, rows, order = rows_of(fig)
    bar, _ = rows["line_noise"]
    assert bar.get_width() == pytest.approx(15.0)
    # not significant in the Diagnosis: not red, whatever its dAIC
    assert mcolors.to_rgba(bar.get_facecolor()) != RED
    assert not any(mcolors.to_rgba(p.get_facecolor()) == RED for p in ax.patches)
    # the implausible candidate is flagged and not first, although its dAIC is the largest
    assert order[0] != "hydrodynamics"
    assert order.index("hydrodynamics") > order.index("line_noise")
    bar, label = rows["hydrodynamics"]
    assert "IMPLAUSIBLE" in label and bar.get_hatch()
    assert any("IMPLAUSIBLE" in t.get_text() for t in ax.texts)
    if form == "diagnosis":
        assert "adequate" in ax.get_title() and "NOT" not in ax.get_title()
        assert "0.35" in ax.get_title()  # gof p-value, as summary() gives it


def test_ranking_does_not_colour_by_aic_thresholds():
    """dAIC 15 with the searched-frequency p = 0.09: diagnose says not significant, and so does
    the bar (it used to be red: dAIC >= 10, 'strong')."""
    rows = [c.to_dict() for c in control_diagnosis().ranking if c.delta_aic is not None]
    ax, bars, _ = rows_of(plotting.diagnose_ranking(rows))
    assert bars["line_noise"][0].get_width() == pytest.approx(15.0)
    assert mcolors.to_rgba(bars["line_noise"][0].get_facecolor()) != RED


def test_ranking_marks_the_significant_effect_and_says_not_adequate(tmp_path):
    d = diagnosis([cand("drift", 570.0, 1e-250, significant=True),
                   cand("line_noise", 9.0, 0.27, dof=2),
                   cand("anharmonicity", 0.05, 0.76)], adequate=False, gof_p=7e-58)
    assert "NOT adequate" in d.summary()
    fig = plotting.diagnose_ranking(d)
    render(fig, tmp_path)
    ax, rows, order = rows_of(fig)
    assert order[0] == "drift"
    assert mcolors.to_rgba(rows["drift"][0].get_facecolor()) == RED
    assert mcolors.to_rgba(rows["line_noise"][0].get_facecolor()) != RED
    assert "NOT adequate" in ax.get_title() and "drift" in ax.get_title()


def test_ranking_draws_rows_not_comparable_by_aic(tmp_path):
    """timing_jitter on irregular time stamps: significant (p = 0) with delta_aic None, first
    in diagnose's ranking. It used to raise (float(None))."""
    d = diagnosis([cand("timing_jitter", None, 0.0, dof=0, significant=True),
                   cand("line_noise", 3.3, 0.33, dof=2),
                   cand("drift", 0.8, 0.1)], adequate=False, gof_p=0.56)
    for arg in (d, [c.to_dict() for c in d.ranking]):
        fig = plotting.diagnose_ranking(arg)
        render(fig, tmp_path)
        ax, rows, order = rows_of(fig)
        assert order == ["timing_jitter", "line_noise", "drift"]
        assert rows["timing_jitter"][0] is None  # no bar: no AIC value to draw
        assert any("not comparable by AIC" in t.get_text() for t in ax.texts)
        assert [p.get_gid() for p in ax.patches if "not comparable" in (p.get_gid() or "")] \
            == ["not comparable: timing_jitter"]


def test_ranking_labels_the_aic_sign_convention():
    fig = plotting.diagnose_ranking(control_diagnosis())
    xlabel = fig.axes[0].get_xlabel()
    assert "AIC_old - AIC_new" in xlabel and "> 0" in xlabel


def test_ranking_of_a_real_diagnosis(tmp_path):
    """A real diagnose run on jittered time stamps, the case that crashed on every real run."""
    n = 4096
    x = noise_recording(3, n=n).positions
    t = np.arange(n) * DT + np.random.default_rng(3).normal(0.0, 2e-6, n)
    rec = bt.Recording(x, frame_interval=DT, exposure=DT, times=t, allow_irregular=True)
    d = bt.diagnose(rec, candidates=["drift", "line_noise", "anharmonicity", "timing_jitter"])
    assert any(c.delta_aic is None for c in d.ranking)
    fig = plotting.diagnose_ranking(d)
    render(fig, tmp_path)
    ax, rows, order = rows_of(fig)
    assert order == [c.effect for c in d.ranking]  # all plausible: diagnose's order
    for c in d.ranking:
        bar = rows[c.effect][0]
        if c.delta_aic is not None:
            assert bar.get_width() == pytest.approx(c.delta_aic)
            assert (mcolors.to_rgba(bar.get_facecolor()) == RED) == c.significant
    assert ("NOT adequate" in ax.get_title()) == (not d.adequate)
