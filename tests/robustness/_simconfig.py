"""The simulate configuration shared by test_determinism.py and test_no_recompile.py, so that
both use the same compiled programs."""

import numpy as np

import blurtrap as bt
from blurtrap.simulate import RandomWalkDrift, TimingJitter

DT = 1.0 / 1500.0  # camera: frame interval = exposure [s]
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6  # 3.06 um bead in water [N s/m]


def sim(key, k=2e-5, gamma=GAMMA, exposure=DT, frame_interval=DT, tracking_std=2e-9, **kw):
    """Positions and time stamps as bytes: tracking noise, a random-walk drift and timing
    jitter, two traces of 512 frames."""
    args = dict(n_frames=512, n_traces=2, method="exact_frames", return_times=True,
                injections=(RandomWalkDrift(1e-15), TimingJitter(1e-6)))
    args.update(kw)
    pos, t = bt.simulate(k, gamma, exposure, frame_interval, key=key, tracking_std=tracking_std,
                         **args)
    return np.asarray(pos).tobytes() + np.asarray(t).tobytes()
