"""Frames declared to come from an anti-aliased photodiode (no exposure average, no folding)
that a camera or an integrating ADC recorded: the fit band below 0.4 fs hides the swap from
the goodness of fit (blur and folding largely cancel there), and gamma came out 8 SE high
(k 3.4 SE) in 20/20 datasets of an independent pass, with no note; ``diagnose`` compared the
two detector models, ``calibrate`` did not. Here the folded model (exposure average over the
declared W, folding at fs) is fitted by the same Whittle objective on the same ordinates,
and a log-likelihood above the anti-aliased model's by more than ``DETECTOR_DLOGL`` (both
models have k, gamma and eps^2) gets a note with its k and gamma."""

from __future__ import annotations

import math

from ._ml_fits import screen_model
from ._models import TrapModel

#: the log-likelihood difference that names the folded model over the anti-aliased one (far
#: beyond chance for non-nested models of equal size; diagnose's detector note reads it too)
DETECTOR_DLOGL = 10.0
#: below this sampling rate no comparison (cameras, whose settings are not anti-aliased; also
#: diagnose's)
MIN_RATE_HZ = 2000.0


def detector_mismatch_note(res, plan) -> list:
    """The note when an anti-aliased photodiode model, implied by the detector settings (not
    a model given: diagnose compares the two itself), fits far worse than the folded one."""
    mdl = plan.model
    recs = plan.recordings
    if plan.model_given or mdl.blur or mdl.alias or mdl.extra or not mdl.noise or res.method != "likelihood":
        return []
    if min(1.0 / float(r.frame_interval) for r in recs) < MIN_RATE_HZ:
        return []
    k_mode = res.extras.get("k_mode", "shared")
    folded = TrapModel(blur=True, alias=True, noise=True, name="standard")
    try:
        got = {}
        for m in (mdl, folded):
            p, nll, _, ok = screen_model(recs, m, k_mode, None, plan.f_range, plan.excluded)
            if not ok:
                return []
            got[m.name] = (p, float(nll))
    except (ValueError, FloatingPointError):
        return []
    d = got[mdl.name][1] - got["standard"][1]  # > 0: the folded model fits better
    if not (math.isfinite(d) and d > DETECTOR_DLOGL):
        return []
    p = got["standard"][0]
    k = p.get("k", p.get("c"))
    shown = (f" (k = {k * 1e3:.4g} pN/nm{'/W' if 'c' in p else ''}, gamma = {p['gamma'] * 1e6:.4g} "
             "pN s/um there)" if k is not None and not plan.volts else "")
    return [f"detector: the frames were fitted as an anti-aliased photodiode (no exposure average, no "
            f"folding), but a camera or integrating ADC, averaging over the declared exposure W = "
            f"{float(recs[0].exposure) * 1e3:.4g} ms and folding at fs, describes the same ordinates far "
            f"better (log-likelihood {d:.1f} higher){shown}: k and gamma are biased if the detector is "
            'declared wrong. Check the instrument: set "anti_aliasing": false (or detector="camera") '
            "unless it really oversamples and filters"]
