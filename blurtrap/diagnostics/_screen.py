"""Screening fits of candidate models, folded ones included.

``diagnose`` refits the model once per candidate effect with the Whittle likelihood over every
periodogram ordinate. For the closed-form models (the core trap plus additive effects) that is
cheap. The others (``hydrodynamics``, ``detector_filter``, ``exposure_kernel``) fold a
continuous spectrum; for long records the model itself evaluates the folded part on
log-spaced nodes and interpolates it to the ordinates (``blurtrap.inference._nodes``, relative
error of the PSD <= 2.7e-8), so the screening fit is the plain Whittle fit that ``calibrate``
runs, with the same ordinates and objective: log-likelihoods stay comparable with the base fit
and the final refit of a significant candidate evaluates the same spectrum.
"""

from __future__ import annotations

from .._config import float64_scope
from ..inference.internal import screen_model


@float64_scope
def screen(inputs, model, k, start=None):
    """Screening Whittle fit of ``model`` without standard errors: ``(params dict, nll, gof,
    ok)`` (:func:`blurtrap.inference._ml_fits.screen_model`) on the base fit's ``inputs``
    (:class:`blurtrap.inference.FitInputs`: the recordings as the instrument prepared them and
    the band it fitted, so that the log-likelihoods compare with the base fit's: a photodiode
    with anti-aliasing is fitted below 0.4 fs; screened over every ordinate, each candidate
    gained ~2e4 in log-likelihood on correct data)."""
    excluded = list(inputs.excluded) or None
    return screen_model(list(inputs.recordings), model, k, start=start,
                        f_range=inputs.f_range, excluded=excluded)
