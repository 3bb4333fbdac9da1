"""diagnose from the naive model on a camera recording: the detector the recording declares
(exposure W = dt: blur; sampled frames: aliasing) is required when adding it moves k or gamma
by more than 2 SE, even where the data alone cannot tell the models apart (issue: 2 of 10
such records were called adequate with a naive k 5-13 SE off). Frames by circulant embedding
of the exact frame autocovariance (numpy, not blurtrap's simulator)."""

import math

from _circulant import circulant_frames

import blurtrap as bt
import blurtrap.plotting as bp

T = 295.0
K = 5e-5
GAMMA = 6 * math.pi * 0.00095 * 1.5e-6


def test_naive_camera_record_the_data_cannot_reject_is_not_adequate():
    """W = dt = 1/1500 s, k = 0.05 pN/nm, 1.5 um bead, eps = 2 nm, 16 384 frames; a seed whose
    naive fit passes the goodness of fit and has no significant candidate (adequate before)."""
    dt = 1 / 1500
    rec = bt.Recording(circulant_frames(K, GAMMA, dt, dt, 4e-18, 16384, seed=1), frame_interval=dt,
                       exposure=dt, temperature=T)
    d = bt.diagnose(rec, model="naive")
    assert (d.fit.k - K) / d.fit.k_err > 3  # the naive answer is confidently wrong
    assert not any(c.significant for c in d.ranking)
    assert not d.adequate
    top = d.ranking[0]
    assert top.required and d.best is top
    assert top.effect == "motion_blur+aliasing+tracking_noise"
    assert abs(top.fit.k - K) < 2 * top.fit.k_err
    assert abs(top.fit.gamma - GAMMA) < 2 * top.fit.gamma_err
    assert abs(top.fit.k - K) < abs(d.fit.k - K)  # the error falls
    assert "required by the declared detector" in d.verdict()
    assert any("part of the declared detector" in n for n in d.notes)
    assert d.to_dict()["ranking"][0]["required"] is True
    assert "! motion_blur+aliasing+tracking_noise" in d.summary()
    fig = bp.diagnose_ranking(d)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert any("required by the declared detector" in t for t in texts)
    assert "missing effect: motion_blur+aliasing+tracking_noise" in fig.axes[0].get_title()


def test_no_requirement_where_the_detector_does_not_move_k():
    """A fast camera (dt = tau / 20) with a 1 us exposure and no tracking noise: blur and
    aliasing change k by far less than 2 SE, so nothing is required and naive is adequate."""
    tau = GAMMA / K
    dt = tau / 20
    rec = bt.Recording(circulant_frames(K, GAMMA, 1e-6, dt, 0.0, 16384, seed=3), frame_interval=dt,
                       exposure=1e-6, temperature=T)
    d = bt.diagnose(rec, model="naive")
    assert not any(c.required for c in d.ranking)
    assert not any("part of the declared detector" in n for n in d.notes)
    assert d.adequate == (d.gof["p_value"] >= d.threshold
                          and not any(c.significant for c in d.ranking))
