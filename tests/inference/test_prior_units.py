"""Priors in lab units instead of SI (a fifth independent pass): ``Normal(0.0268, 5e-4)`` for
gamma (its value in pN s/um) or ``Normal(0.05, 0.001)`` for k (pN/nm) put all their mass
outside any trapped bead's range; the posterior equalled the flat-prior one, with no word.
Such a prior is now a ValueError naming the unit; plausible priors pass. k's 0.05 "N/m" is
a plausible (very stiff) trap: that prior gets a note, as every prior that conflicts with the
data's maximum-likelihood value (frames from tests/_circulant.py, not blurtrap's simulator)."""

import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference import LogNormal
from blurtrap.inference._posterior_priors import check_prior_units

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
NAMES = ("k", "gamma", "tracking_var")


@pytest.mark.parametrize("priors, name", [
    ({"gamma": bt.Normal(0.0268, 5e-4)}, "gamma"),  # pN s/um as N s/m
    ({"k": bt.LogUniform(10.0, 100.0)}, "k"),
    ({"gamma": LogNormal(GAMMA * 1e6, 0.1)}, "gamma"),
])
def test_a_prior_in_lab_units_is_refused_before_any_fit(priors, name):
    rec = bt.Recording(np.random.default_rng(0).normal(size=4096) * 1e-8,
                       frame_interval=1 / 1500, exposure=1 / 1500)
    with pytest.raises(ValueError, match=rf"priors\['{name}'\].*unit slip; priors take SI"):
        bt.sample_posterior(rec, priors=priors, n_steps=10)


def test_plausible_priors_and_volts_pass():
    ok = (bt.Normal(5e-5, 1e-6), LogNormal(GAMMA, 0.05), bt.Uniform(0.0, 1e-17))
    check_prior_units(NAMES, ok)
    wide = (bt.Normal(0.05, 0.001), bt.Normal(0.0268, 5e-4), bt.Uniform(0.0, 1e-17))
    check_prior_units(NAMES, wide, volts=True)  # in volts k and gamma scale with Rd^2


@pytest.mark.filterwarnings("ignore:the chain")  # 20 steps: only the notes are tested
def test_a_prior_that_conflicts_with_the_data_is_named():
    from _circulant import circulant_frames

    x = circulant_frames(5e-5, GAMMA, 1 / 1500, 1 / 1500, 4e-18, 16384, 7, reps=1,
                         temperature=295.0)[0]
    rec = bt.Recording(x, frame_interval=1 / 1500, exposure=1 / 1500, temperature=295.0)
    post = bt.sample_posterior(rec, priors={"k": bt.Normal(0.05, 0.001)}, n_steps=20,
                               burn_in=0, seed=1)
    (note,) = [n for n in post.notes if n.startswith("prior on k")]
    assert "conflicts with the data" in note and "1 pN/nm = 1e-3 N/m" in note
    fine = bt.sample_posterior(rec, priors={"k": bt.Normal(5e-5, 5e-6)}, n_steps=20,
                               burn_in=0, seed=1)
    assert not [n for n in fine.notes if n.startswith("prior on")]
