"""The design figure: made through pyplot unless `ax=` says where, axes in lab units (ms, %),
one marker per candidate the design compared (the recommended one first, as a star)."""

import io
import math

import matplotlib.pyplot as plt
import numpy as np
import pytest

pytest.importorskip("blurtrap.plotting")
import blurtrap.plotting as bp  # noqa: E402
from blurtrap.design._design import DesignResult, _acquisition  # noqa: E402

GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
K = 5e-5
DT = 1 / 1500
T_TOTAL = 10.0


def small_design(photon=False):
    """A DesignResult built from fixed candidates (no optimisation: fast), with the
    settings bt.design records."""
    common = ((K,), GAMMA, 295.0, 4e-18, DT, photon, "k")
    cands = [_acquisition("optimised series of 2 exposures",
                          [(DT, 1e-6, T_TOTAL / DT / 2), (DT, DT, T_TOTAL / DT / 2)], *common),
             _acquisition("W = dt at the fastest frame rate", [(DT, DT, T_TOTAL / DT)],
                          *common),
             _acquisition("the paper's exposure series",
                          [(DT, f * DT, T_TOTAL / DT / 4) for f in (0.15, 0.3, 0.6, 1.0)],
                          *common),
             _acquisition("your current design", [(2 * DT, DT, T_TOTAL / DT / 2)], *common)]
    cands.sort(key=lambda c: c.objective)
    settings = {"gamma_N_s_per_m": GAMMA, "temperature_K": 295.0, "max_fps_Hz": 1500.0,
                "min_exposure_s": 1e-6, "dead_time_s": 0.0, "n_frames": None,
                "total_time_s": T_TOTAL, "tracking_std_m": 2e-9, "photon_limited": photon,
                "reference_exposure_s": DT, "kT_J": 4e-21}
    return DesignResult(best=cands[0], candidates=tuple(cands), target="k", k=(K,),
                        settings=settings)


def candidate_markers(ax):
    return [ln for ln in ax.get_lines() if ln.get_gid() == "candidate"]


@pytest.mark.parametrize("photon", [False, True])
def test_design_figure_marks_every_candidate_in_lab_units(photon):
    r = small_design(photon)
    before = set(plt.get_fignums())
    fig = r.plot()
    try:
        assert set(plt.get_fignums()) - before  # made through pyplot
        ax_w, ax_dt = fig.axes[:2]
        assert "[ms]" in ax_w.get_xlabel() and "[ms]" in ax_dt.get_xlabel()
        assert "[%]" in ax_w.get_ylabel() and "[%]" in ax_dt.get_ylabel()
        marks = candidate_markers(ax_w)
        assert len(marks) == len(r.candidates)
        assert [m.get_label() for m in marks][0].startswith("recommended")
        assert marks[0].get_marker() == "*"
        # the marker of each candidate sits at its predicted SE of k, in %
        for m, c in zip(marks, r.candidates):
            np.testing.assert_allclose(m.get_ydata()[0], 100 * np.max(c.predicted_se["k"]),
                                       rtol=1e-9)
        # the W = dt single-recording curve passes through the W = dt candidate
        wdt = next(c for c in r.candidates if c.label.startswith("W = dt"))
        x, y = ax_w.get_lines()[0].get_data()
        np.testing.assert_allclose(y[-1], 100 * np.max(wdt.predicted_se["k"]), rtol=1e-6)
        assert x[-1] == pytest.approx(DT * 1e3)
    finally:
        plt.close(fig)


def test_design_figure_draws_into_given_axes():
    r = small_design()
    fig0, ax = plt.subplots()
    try:
        before = set(plt.get_fignums())
        fig = bp.design_se(r, ax=ax)
        assert fig is fig0 and set(plt.get_fignums()) == before
        assert len(candidate_markers(ax)) == len(r.candidates)
    finally:
        plt.close(fig0)


def test_design_figure_of_a_design_that_identifies_little():
    """dt >> tau (k 0.5 pN/nm at 500 fps): one W = dt recording does not separate gamma from
    eps^2 (singular information). The figure still marks every candidate, says which SE is
    not finite or above 1000 %, and draws no curve above 1000 %."""
    k, dt = 5e-4, 1 / 500
    common = ((k,), GAMMA, 295.0, 4e-18, dt, False, "k")
    cands = [_acquisition("optimised series of 2 exposures",
                          [(dt, 9.4e-6, 32768), (dt, dt, 32768)], *common),
             _acquisition("W = dt at the fastest frame rate", [(dt, dt, 65536)], *common)]
    settings = {"gamma_N_s_per_m": GAMMA, "temperature_K": 295.0, "max_fps_Hz": 500.0,
                "min_exposure_s": 1e-6, "dead_time_s": 0.0, "n_frames": None,
                "total_time_s": 65536 * dt, "tracking_std_m": 2e-9, "photon_limited": False,
                "reference_exposure_s": dt, "kT_J": 4e-21}
    r = DesignResult(best=cands[0], candidates=tuple(cands), target="k", k=(k,),
                     settings=settings)
    fig = bp.design_se(r)
    try:
        ax_w, ax_dt = fig.axes[:2]
        marks = candidate_markers(ax_w)
        assert len(marks) == 2
        assert np.isfinite(marks[0].get_ydata()[0])
        assert "not finite" in marks[1].get_label()
        for ax in (ax_w, ax_dt):
            for ln in ax.get_lines():
                if ln.get_gid() != "candidate":
                    y = np.asarray(ln.get_ydata(), dtype=float)
                    assert not (y[np.isfinite(y)] > 1e3).any()
        fig.savefig(io.BytesIO(), format="png")  # the log axes can be drawn
    finally:
        plt.close(fig)
