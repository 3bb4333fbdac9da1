"""diagnose() on data with the remaining hidden effects, each simulated the way an experiment
for it is run: photodiode sampling for ``detector_filter`` and ``hydrodynamics``, a camera
exposure series for ``exposure_kernel``, a single camera record for ``anharmonicity``.

Criteria as in test_hidden_effects.py: (1) the model is inadequate, (2) the hidden effect ranks
first and is significant, (3) after adding it the fit is adequate and k, gamma lie within 3 SE
of the truth, which they did not before. ``anharmonicity`` is not part of the Gaussian
likelihood, so (3) is replaced by: the base fit's k is biased (the effect matters).
Identification rates over many seeds are in benchmarks/study_diagnose.py.
"""

import jax
import numpy as np

import blurtrap as bt
from blurtrap.physics import BOLTZMANN
from blurtrap.physics._effects import water_viscosity
from blurtrap.simulate import (
    HydrodynamicFriction,
    PhotodiodeFilter,
    TrapezoidProfile,
    quartic_force,
)

T = 295.0
# photodiode: 1.5 um bead in water, k = 0.05 pN/nm (fc = 300 Hz), nearly instantaneous samples
R = 1.5e-6
GAMMA_PD = 6 * np.pi * float(water_viscosity(T)) * R
K_PD = 5e-5
W_PD = 1e-8
EPS_PD = 0.2e-9
# camera (as in test_hidden_effects.py)
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6
DT = 1 / 1500


def within(fit, k, gamma, n_se=3.0):
    return abs(fit.k - k) < n_se * fit.k_err and abs(fit.gamma - gamma) < n_se * fit.gamma_err


def check_hidden(d, effect, k, gamma):
    assert not d.adequate, d.summary()
    assert d.ranking[0].effect == effect, d.summary()
    assert d.ranking[0].significant
    assert not within(d.fit, k, gamma), "the effect should have biased the base fit"
    fixed = d.ranking[0].fit
    assert fixed is not None
    assert fixed.gof["p_value"] > d.threshold, fixed.summary()
    assert within(fixed, k, gamma), fixed.summary()
    return fixed


def photodiode_record(seed, dt, n, injections, method):
    x = np.asarray(bt.simulate(K_PD, GAMMA_PD, W_PD, dt, n, key=jax.random.key(seed),
                               method=method, tracking_std=EPS_PD, injections=injections))[0]
    return bt.Recording(x, frame_interval=dt, exposure=W_PD)


# both photodiode tests use one sampling rate and record length, so that the models diagnose
# compiles for one are reused by the other (test time)
DT_PD = 5e-6
N_PD = 2**15


def test_hidden_detector_filter():
    """Silicon photodiode at 1064 nm (f3dB = 8 kHz, alpha = 0.4), 200 kHz, 2^15 samples,
    simulated exactly (trap + filter state as one linear system)."""
    rec = photodiode_record(31, DT_PD, N_PD, (PhotodiodeFilter(8e3, 0.4),), "exact_frames")
    d = bt.diagnose(rec)
    fixed = check_hidden(d, "detector_filter", K_PD, GAMMA_PD)
    i = fixed.param_names.index("f3db")
    assert abs(fixed.values[i] - 8e3) < 3 * fixed.errors[i]


def test_hidden_hydrodynamics():
    """Frequency-dependent friction of a 1.5 um bead at 200 kHz, 2^15 samples (0.16 s),
    simulated from the exact discrete spectrum. The 2-parameter photodiode filter mimics most
    of the high-frequency shape; the record length is what separates them (expected
    log-likelihood gap 5.6 here, 11 at 2^16, where the study identified it in 3/3 records,
    benchmarks/RESULTS_diagnose.md)."""
    rec = photodiode_record(32, DT_PD, N_PD, (HydrodynamicFriction(R),), "spectral")
    d = bt.diagnose(rec)
    fixed = check_hidden(d, "hydrodynamics", K_PD, GAMMA_PD)
    i = fixed.param_names.index("hydro_radius")
    assert abs(fixed.values[i] - R) < 3 * fixed.errors[i]


def test_hidden_anharmonicity():
    """Quartic trap U = k x^2/2 + k4 x^4/4 with beta = k4 kT/k^2 = 0.1 (excess kurtosis -0.27),
    Euler-Maruyama with 64 substeps per frame, 16 384 camera frames: the kurtosis test flags
    it and ranks it first; the Gaussian fit's k is biased high (var = 0.82 kT/k)."""
    k = 1e-5
    k4 = 0.1 * k * k / (BOLTZMANN * T)
    x = np.asarray(bt.simulate(k, GAMMA, DT, DT, 16384, key=jax.random.key(33), method="euler",
                               force=quartic_force, force_params=(k, k4), substeps=64,
                               burn_in_frames=200, tracking_std=2e-9))[0]
    d = bt.diagnose(bt.Recording(x, frame_interval=DT, exposure=DT))
    assert not d.adequate, d.summary()
    top = d.ranking[0]
    assert top.effect == "anharmonicity" and top.significant, d.summary()
    assert "kurtosis -" in top.evidence  # stiffening quartic: flatter than Gaussian
    assert (d.fit.k - k) > 3 * d.fit.k_err  # the harmonic fit is biased


def test_hidden_exposure_kernel():
    """Camera exposure series (W = 0.25, 0.5, 0.75, 1.0 dt at 1500 fps, k = 0.05 pN/nm,
    alpha up to 1.24) with a triangular exposure profile (rise = fall = W/2), simulated with
    40 exact OU substeps per exposure weighted by the profile. A single exposure cannot show
    it (the frames stay ARMA(1,1)); the series can."""
    k = 5e-5
    recs = []
    for i, frac in enumerate((0.25, 0.5, 0.75, 1.0)):
        w = frac * DT
        x = np.asarray(bt.simulate(k, GAMMA, w, DT, 16384, key=jax.random.key(340 + i),
                                   method="exact", substeps=40,
                                   exposure_profile=TrapezoidProfile(0.5), tracking_std=2e-9))[0]
        recs.append(bt.Recording(x, frame_interval=DT, exposure=w))
    d = bt.diagnose(recs)
    fixed = check_hidden(d, "exposure_kernel", k, GAMMA)
    i = fixed.param_names.index("rise_fraction")
    assert abs(fixed.values[i] - 0.5) < 3 * fixed.errors[i]
