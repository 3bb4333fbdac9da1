"""Data/model of a blocked periodogram in the figures has mean 1 also when the blocks are only
a few relaxation times long: the figures divide by the exact expected block periodogram (as
the spectral fits do), not by P_d(f)."""

import numpy as np
from _xy_gen import principal_frames

import blurtrap as bt
from blurtrap.plotting._common import blocked_psd, model_psd
from blurtrap.plotting._psd_figs import _residuals


def test_blocked_ratio_has_mean_one_for_a_slow_trap():
    dt, w, temp = 1e-3, 0.5e-3, 295.0
    k, gamma = 1e-6, 1e-8  # tau = 10 ms = 10 frames; blocks of 256 frames are 25.6 tau
    rng = np.random.default_rng(7)
    x, _ = principal_frames(2**16, k, k, gamma, w, dt, rng, temperature=temp)
    rec = bt.Recording(x, frame_interval=dt, exposure=w, temperature=temp)
    params = {"k": k, "gamma": gamma, "tracking_var": 0.0, "temperature": temp,
              "model": "blur"}
    nb = 256
    f, p, nb = blocked_psd(rec, nb)
    band = f > 0.1 / dt  # where P_d alone is biased by the blocks' leakage
    exact = p / model_psd(params, rec, f, block_len=rec.n_frames // nb)
    plain = p / model_psd(params, rec, f)
    se = 1.0 / np.sqrt(nb * band.sum())  # ratios ~ Gamma(nb)/nb, independent across f
    assert abs(exact[band].mean() - 1.0) < 4 * se
    assert plain[band].mean() - 1.0 > 5 * se  # what the figures showed before (+6 %)
    # the figures' residual helper uses the exact expectation
    (_, ratio, _), = _residuals(params, [rec], nb, None)
    np.testing.assert_allclose(ratio, exact, rtol=1e-12)
