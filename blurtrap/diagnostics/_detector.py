"""Is the detector model right? Folded (camera, integrating ADC) against not folded
(photodiode with anti-aliasing), compared on the same ordinates.

Both models have the same parameters (k, gamma, eps^2) and are fitted by the Whittle
likelihood over the band below 0.4 fs, where an instrument's anti-alias filter is flat. A
difference of log-likelihoods above :data:`DETECTOR_DLOGL` (~e^-10: far beyond chance for
non-nested models of equal size) names the better one; when the recordings' settings say
otherwise (or say nothing) the note says which key to set.
"""

from __future__ import annotations

from ..inference import FitError, TrapModel, calibrate
from ..inference.internal import DETECTOR_DLOGL, MIN_RATE_HZ  # calibrate's own check uses them too

_FOLDED = TrapModel(blur=True, alias=True, noise=True, name="standard")
_UNFOLDED = TrapModel(blur=False, alias=False, noise=True, name="photodiode_aa")


#: significant effects that reshape the spectrum's high-frequency end, which neither detector
#: model has: the comparison would credit their deficit to "no folding"
_HIGH_F_EFFECTS = ("detector_filter", "hydrodynamics", "exposure_kernel")


def detector_note(recs, settings, ranked=()) -> list[str]:
    """A note when the data prefer the other detector model (or name one that was not set).
    Not compared when a significant candidate in ``ranked`` reshapes the high frequencies."""
    fs = min(1.0 / float(r.frame_interval) for r in recs)
    if fs < MIN_RATE_HZ:
        return []
    if any(c.significant and c.effect in _HIGH_F_EFFECTS for c in ranked):
        return []
    band = (0.0, 0.4 * fs)
    nll = {}
    for mdl in (_FOLDED, _UNFOLDED):
        try:
            res = calibrate(recs, method="likelihood", likelihood="whittle", model=mdl,
                            f_range=band, strict=False, lines="keep")
        except (FitError, ValueError):
            return []
        nll[mdl.name] = float(res.extras.get("nll", float("nan")))
    d = nll["standard"] - nll["photodiode_aa"]  # > 0: the unfolded model fits better
    if not abs(d) > DETECTOR_DLOGL:
        return []
    aa_set = bool(settings.get("anti_aliasing"))
    if d > 0 and not aa_set:
        return [f"detector: below 0.4 fs the spectrum is that of an anti-aliased photodiode "
                f"(no exposure average, no folding): log-likelihood {d:.1f} above the folded "
                "camera/integrating-ADC model. If the instrument oversamples and filters, set "
                '"detector": "photodiode", "anti_aliasing": true (calibrate would otherwise fold '
                "a spectrum that is not folded and bias f_c)"]
    if d < 0 and aa_set:
        return [f"detector: the spectrum is folded and averaged over the exposure (log-likelihood "
                f"{-d:.1f} above the anti-aliased photodiode model), but the settings say "
                'anti_aliasing: true; check the instrument and set "anti_aliasing": false']
    return []
