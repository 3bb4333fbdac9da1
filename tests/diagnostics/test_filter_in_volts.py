"""diagnose on a photodiode trace with an undeclared detector filter, in volts with a known
friction (a fourth independent pass: the filter candidate's refit started from the held
friction's value in metres, ended below the base fit, dlogL -21.8, and nothing was named;
its evidence said "no high-frequency low-pass deficit" beside a band at 0.71 of the model).
Data: exact AR(1) samples and a first-order filter in numpy/scipy, not blurtrap's simulator.
"""

import math

import numpy as np
from scipy.signal import lfilter

import blurtrap as bt

KT = 1.380649e-23 * 295.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
K, DT, RD = 5e-5, 1e-5, 1e-7


def _filtered(n, seed):
    rng = np.random.default_rng(seed)
    a = math.exp(-K * DT / GAMMA)
    e = rng.standard_normal(n) * math.sqrt(KT / K)
    e[1:] *= math.sqrt(1 - a * a)
    x = lfilter([1.0], [1.0, -a], e) + 2e-9 * rng.standard_normal(n)
    b = math.exp(-2 * math.pi * 5e3 * DT)  # 5 kHz pole, instantaneous fraction 0.3
    return 0.3 * x + 0.7 * lfilter([1 - b], [1, -b], x)


def test_undeclared_filter_is_named_in_volts_with_known_friction():
    meta = {"bead_radius_m": 1.53e-6, "viscosity_Pa_s": 0.00093, "detector": "photodiode",
            "hydrodynamics": False, "friction": "stokes"}
    rec = bt.Recording(_filtered(2**16, 5) / RD, frame_interval=DT, exposure=DT,
                       position_unit="V", metadata=meta)
    d = bt.diagnose(rec)
    best = d.ranking[0]
    assert best.effect == "detector_filter" and best.delta_loglik > 100
    assert all(c.delta_loglik is None or c.delta_loglik > -1e-6 * abs(d.fit.extras["nll"])
               for c in d.ranking)
    assert "no high-frequency" not in best.evidence and "detector filter" in best.evidence
