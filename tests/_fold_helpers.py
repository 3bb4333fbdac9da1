"""Shared by tests/inference/test_fold_nodes.py and tests/diagnostics/test_screen.py: a
simulated record of the folded-spectrum cases (k = 0.05 pN/nm, a 0.75 um bead in water at
295 K, 2 nm tracking noise) and the periodogram arguments of a model on recordings."""

import jax
import numpy as np

import blurtrap as bt
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import make_layout
from blurtrap.inference._spectral import _spectral_args
from blurtrap.physics._effects import water_viscosity

K = 5e-5
GAMMA = 6 * np.pi * float(water_viscosity(295.0)) * 0.75e-6


def record(dt, w, n, seed=0, injections=()):
    """One exact-frame recording (frame interval `dt`, exposure `w`, `n` frames)."""
    x = np.asarray(bt.simulate(K, GAMMA, w, dt, n, key=jax.random.key(seed),
                               method="exact_frames", tracking_std=2e-9,
                               injections=injections))[0]
    return bt.Recording(x, frame_interval=dt, exposure=w)


def spec(recs, model):
    """Whittle arguments (one block, all ordinates) of `model` on `recs`, k shared."""
    mdl = get_model(model)
    layout = make_layout(recs, "shared", True, tuple(p.name for p in mdl.extra_params))
    return _spectral_args(recs, layout, mdl, 1, None)
