"""``blurtrap.calibrate``: every method of the paper plus exact and Whittle likelihoods.

This module holds the public entry point and the dispatcher that chooses a method. The rest
lives by idea: ``_recordings`` (input, bead metadata), ``_options`` (argument checks),
``_frames`` (what the frames show), ``_starts`` (start values), ``_spectral`` (periodogram
ordinates, goodness of fit), ``_ml_fits`` (Whittle, blocked PSD, exact likelihood),
``_variance_methods`` (variance vs exposure/power, Allan, equipartition), ``_refusals``
(refusals and their messages) and ``_assemble`` (the result)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from .._config import float64_scope
from ._detector_check import detector_mismatch_note
from ._frames import _inspect_frames, temporal_information
from ._instrument import prepare_instrument
from ._irregular import any_irregular, rounding_notes
from ._ml_fits import _LEAKAGE_INDEX_MAX, _fit_exact, _fit_spectral, _leakage_index
from ._models import TrapModel, get_model
from ._noise_pooling import without_drift_confusion
from ._options import _check_options, _default_k_mode, _flag, band_sentence
from ._problems import make_layout
from ._recordings import _bead_radii, as_recordings, misfit_note, physics_notes
from ._refusals import _check_psd_blocks, _no_temporal_information_message, known_friction_message
from ._result import CalibrationResult, FitError
from ._starts import moment_start
from ._variance_methods import _equipartition, _fit_allan, _fit_variance
from ._volts import finish_instrument

METHODS = ("auto", "likelihood", "psd", "variance_vs_exposure", "variance_vs_power",
           "equipartition", "allan")


@float64_scope
def calibrate(
    data,
    *,
    method: str = "auto",
    model=None,
    k: str | None = None,
    likelihood: str = "auto",
    n_blocks: int | None = None,
    f_range=None,
    diffusion: float | None = None,
    pade: bool = False,
    start: dict | None = None,
    strict: bool = True,
    fixed: dict | None = None,
    friction: str | None = None,
    detector: str | None = None,
    anti_aliasing: bool | None = None,
    excluded_ranges=None,
    lines: str = "auto",
    robust: bool = False,
    hydrodynamics: bool | str | None = None,
) -> CalibrationResult:
    """Calibrate k, gamma (D) and eps^2 with standard errors from one or more recordings.

    **Arguments:**

    - `data`: a ``Recording``, ``RecordingSet``, list of recordings or a manifest path.
    - `method`: ``"auto"`` (the most informative method the data allow; the choice is in
      ``result.notes``), ``"likelihood"`` (joint exact or Whittle likelihood), ``"psd"``
      (blocked power spectrum, Gamma maximum likelihood, appendix C), ``"variance_vs_exposure"``
      (section 6.2), ``"variance_vs_power"`` (section 6.3, k = c P), ``"equipartition"``
      (naive, or blur-corrected when ``diffusion`` is given).
    - `model`: ``"standard"`` (default: blur + aliasing + tracking noise), ``"blur"``,
      ``"naive"``, ``"naive_aliased"``, or a ``TrapModel``.
    - `k`: how stiffness is shared across recordings: ``"shared"``, ``"per_recording"``,
      ``"per_power"``, ``"linear_power"`` (default: per power when powers differ).
    - `likelihood`: ``"exact"`` (O(N) time-domain, REML mean), ``"whittle"`` or ``"auto"``
      (Whittle above 2^14 frames per recording, where the two agree to well within errors).
    - `n_blocks`: blocks for ``method="psd"`` (default: 128 blocks, at least 64 frames each).
    - `f_range`: ``(f_min, f_max)`` [Hz] fitted in the spectral methods.
    - `diffusion`, `pade`: for blur-corrected equipartition (D in m^2/s); ``"auto"`` uses D
      only when the frames cannot determine it, and says so in the notes otherwise.
    - `start`: optional start values by parameter name (SI), e.g. from a previous fit
      (``result.params``); missing names use the closed-form starts.
    - `strict`: raise ``FitError`` when the Fisher information is singular (default); with
      ``strict=False`` (spectral methods) the fit is returned with NaN errors and a note.
      Saturated frames (a pile-up at exactly the minimum or maximum value) and positions
      quantised in steps above their standard deviation raise ``ValueError``; with
      ``strict=False`` they give a note instead. Milder quantisation (steps above std/4)
      and a few saturated frames are noted in ``result.notes``.
    - `fixed`: parameters held at known values, ``{"gamma": 9.1e-9}`` or with a standard
      error ``{"gamma": (9.1e-9, 0.3e-9)}`` (SI), which is propagated into the others' errors.
      A value outside the quantity's plausible range is a ``ValueError`` (a unit slip); a
      held value the data disagree with (a score test, p < 0.01) gets a note. With
      ``method="equipartition"`` only ``tracking_var`` may be held: it is subtracted from
      the frame variance.
    - `friction`: ``"stokes"`` holds gamma at ``6 pi eta R`` of the bead (the recordings'
      ``bead_radius_m``, ``viscosity_Pa_s`` or water at their temperature, Faxen's factor at
      ``distance_to_surface_m``; ``bead_radius_err_m``, ``viscosity_err_Pa_s``,
      ``temperature_err_K`` propagated); ``"free"`` fits it (default: the recordings'
      ``friction`` setting, else free).
    - `detector`, `anti_aliasing`: ``"camera"`` or ``"photodiode"`` (default: the
      recordings' settings). They choose the model when `model` is not given: exposure
      average and folding for a camera or an integrating photodiode, neither for a
      photodiode with anti-aliasing (fitted below 0.4 fs unless `f_range` says otherwise);
      a ``diode_filter`` setting adds the photodiode filter (fitted, or held at given values).
    - `excluded_ranges`: ``[(f_low, f_high), ...]`` [Hz] left out of the spectral fits.
    - `lines`: ``"auto"`` (default) finds strong narrow lines (a drive, mains pick-up) and
      subtracts them before the fit, naming them in the notes; ``"keep"`` fits the trace as
      it is.
    - `robust`: spectral fits leave out ordinates far above the fitted spectrum (spikes).
    - `hydrodynamics`: the frequency-dependent friction of the known bead (Berg-Sorensen &
      Flyvbjerg 2004; near a surface Tolic-Norrelykke et al. 2006): ``True`` adds the
      ``hydrodynamics`` effect with ``hydro_radius`` held at ``bead_radius_m`` (no new
      parameter; distance, densities and viscosity from the settings, water at T where not
      given), ``False`` leaves it out, ``"auto"`` adds it when the bead radius is known and
      ignoring it would bias k or gamma by more than 1/3 of their standard error (predicted
      from the model spectra; with a stage drive in volts: Rd, gamma or k); default: the
      recordings' ``hydrodynamics`` setting, else ``"auto"``. With a stage drive the drive
      response uses the same friction and the bead's inertia (Tolic-Norrelykke et al. 2006,
      eq. D3). The notes say what was used.

    Positions in volts (``position_unit="V"``) give the displacement sensitivity Rd [m/V] and
    force sensitivity Rf = k Rd [N/V] as parameters ``displacement_sensitivity`` and
    ``force_sensitivity``, from the known friction or from a stage drive (active calibration:
    a ``drive`` setting with the recorded stage positions); k, gamma, eps^2 are then in SI.

    **Returns:** :class:`CalibrationResult` (SI units).

    **Raises:** ``FitError`` when a fit does not converge or is not identifiable;
    ``ValueError`` for bad arguments and for saturated or coarsely quantised frames.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got method = {method!r}")
    if likelihood not in ("auto", "exact", "whittle"):
        raise ValueError(f"likelihood must be 'auto', 'exact' or 'whittle'; got {likelihood!r}")
    recs = as_recordings(data)
    mdl: TrapModel = get_model(model)
    n_blocks, f_range = _check_options(recs, method, likelihood, k, n_blocks, f_range,
                                       diffusion, pade, start, strict)
    radii = _bead_radii(recs)
    data_notes = tuple(_inspect_frames(recs, bool(strict), mdl.has("drift")))
    plan = prepare_instrument(recs, mdl, model is not None, method, fixed=fixed,
                              friction=friction, detector=detector,
                              anti_aliasing=anti_aliasing, excluded_ranges=excluded_ranges,
                              lines=lines, f_range=f_range, hydrodynamics=hydrodynamics,
                              likelihood=likelihood)
    try:
        res = _calibrate(plan.recordings, method, plan.model, k, likelihood, n_blocks,
                         plan.f_range, diffusion, pade, start, strict, plan.fixed, plan.excluded,
                         _flag("robust", robust))
    except FitError as err:  # a band the caller chose is a cause the frames cannot show
        raise FitError(str(err) + band_sentence(recs, f_range, excluded_ranges)) from err
    res = finish_instrument(res, plan).with_inputs(plan.recordings, plan.model,
                                                   plan.f_range, plan.excluded)
    res = dataclasses.replace(res, extras={**res.extras, "held": sorted(plan.fixed)})
    data_notes += tuple(physics_notes(recs, radii, res, plan)) + tuple(detector_mismatch_note(res, plan))
    notes = tuple(plan.notes) + data_notes
    notes += tuple(misfit_note(res, tuple(res.notes) + notes))
    if notes:
        res = dataclasses.replace(res, notes=without_drift_confusion(tuple(res.notes) + notes))
    return res


def _calibrate(recs, method, mdl, k, likelihood, n_blocks, f_range, diffusion, pade, start,
               strict, fixed=None, excluded=None, robust=False):
    """Choose the method (``'auto'``: see :func:`_auto_choice`), build the parameter layout
    and run the fit on the (instrument-prepared) recordings."""
    notes: list[str] = []
    fixed = _check_spectral_options(method, robust, fixed, excluded)
    if method == "equipartition":
        return _equipartition(recs, diffusion, pade, fixed.get("tracking_var"))
    if method == "auto":
        done, k = _auto_choice(recs, mdl, k, fixed, diffusion, pade, notes)
        if done is not None:
            return done
        method = "likelihood"
        if diffusion is not None:
            notes.append(f"auto: the given D = {diffusion * 1e12:.4g} um^2/s is not used: "
                         "the frames determine D themselves, so the joint likelihood fits "
                         "it (method='equipartition' uses a given D)")
    if k is None:
        k = "linear_power" if method == "variance_vs_power" else _default_k_mode(recs)
    layout = _checked_layout(recs, mdl, k, fixed, start)
    if mdl.extra and method in ("variance_vs_exposure", "variance_vs_power"):
        raise ValueError(f"method {method!r} fits only the core model; effects "
                         f"{[e.name for e in mdl.extra]} need method='likelihood' or 'psd'")
    if method == "likelihood":
        return _fit_likelihood(recs, layout, mdl, likelihood, f_range, excluded, robust, start,
                               strict, fixed, notes)
    if method == "psd":
        return _fit_psd(recs, layout, mdl, n_blocks, f_range, excluded, robust, start, strict,
                        fixed, notes)
    if method == "allan":
        return _fit_allan(recs, layout, mdl, notes)
    if method in ("variance_vs_exposure", "variance_vs_power"):
        if method == "variance_vs_power" and k != "linear_power":
            warnings.warn("variance_vs_power is usually run with k='linear_power'", stacklevel=2)
        return _fit_variance(recs, layout, mdl, method, notes)
    raise AssertionError(method)  # pragma: no cover


def _check_spectral_options(method, robust, fixed, excluded) -> dict:
    """robust, fixed and excluded ranges apply to the likelihood and psd methods only;
    returns ``fixed`` as a dict."""
    if robust and method not in ("auto", "likelihood", "psd"):
        raise ValueError(f"robust=True applies to the spectral methods (Whittle likelihood, "
                         f"psd); got method = {method!r}")
    fixed = fixed or {}
    if method == "equipartition" and set(fixed) <= {"tracking_var"}:
        return fixed  # the known tracking-error variance is subtracted from the variance
    if fixed and method not in ("auto", "likelihood", "psd"):
        raise ValueError(f"fixed = {sorted(fixed)} applies to the likelihood and psd methods; "
                         f"got method = {method!r}")
    if excluded and method not in ("auto", "likelihood", "psd"):
        raise ValueError(f"excluded ranges apply to the spectral methods (Whittle likelihood, "
                         f"psd); got method = {method!r}")
    return fixed


def _auto_choice(recs, mdl, k, fixed, diffusion, pade, notes):
    """What ``method='auto'`` does: ``(result, k)``, the result of blur-corrected
    equipartition when only that is possible, else ``None`` (the joint likelihood follows,
    with ``k`` possibly set to ``'linear_power'``). The reason goes into ``notes``.

    The joint likelihood of all frames contains the variance-vs-exposure and
    variance-vs-power information too, so it is the most informative choice whenever the
    parameters are identifiable at all."""
    info = [temporal_information(r) for r in recs]
    n_exp = len({float(r.exposure) for r in recs})
    powers = {float(r.laser_power) for r in recs if r.laser_power is not None}
    best = max(z for _, z in info)
    if any(ok for ok, _ in info):
        notes.append("auto: frames resolve the trap relaxation (lag-1 correlation "
                     f"{best:.1f} standard errors above 0); joint likelihood")
    elif "gamma" in fixed:
        if mdl.noise and "tracking_var" not in fixed and n_exp < 2:
            raise FitError(known_friction_message(best))
        notes.append(f"auto: frames carry little temporal information (lag-1 correlation "
                     f"{best:.1f} standard errors above 0: dt >> tau); gamma is held at the "
                     "given friction, so the joint likelihood gives k from the "
                     "blur-corrected variance"
                     + (f" (the {n_exp} exposures blur it differently, which separates k "
                        "from eps^2)" if mdl.noise and "tracking_var" not in fixed else ""))
    elif n_exp >= 3:
        notes.append(f"auto: frames are nearly independent (dt >> tau); gamma is "
                     f"identified by the {n_exp} exposures (variance-vs-exposure "
                     "information) in the joint likelihood")
    elif len(powers) >= 3 and all(r.laser_power is not None for r in recs):
        notes.append("auto: dt >> tau; k = c P across the laser powers (variance-vs-power "
                     "information) in the joint likelihood")
        if k is None:
            k = "linear_power"
    elif diffusion is not None:
        res = _equipartition(recs, diffusion, pade, fixed.get("tracking_var"))
        return dataclasses.replace(res, notes=(
            f"auto: frames carry no temporal information (lag-1 correlation only {best:.1f} "
            "standard errors above 0: dt >> tau, or tracking noise dominates) and there are "
            "fewer than 3 exposures or powers; k from blur-corrected equipartition with the "
            "given D",) + res.notes), k
    else:
        raise FitError(_no_temporal_information_message(recs, info))
    return None, k


def _checked_layout(recs, mdl, k, fixed, start):
    """The parameter layout for stiffness mode ``k``, with ``fixed`` and ``start`` checked
    against its parameter names."""
    if mdl.has("power_offset") and k != "linear_power":
        raise ValueError("the power_offset effect needs k='linear_power' (k = c (P - P0))")
    layout = make_layout(recs, k, mdl.noise, tuple(p.name for p in mdl.extra_params))
    unknown = sorted(set(fixed) - set(layout.names))
    if unknown:
        raise ValueError(f"fixed names {unknown}, which this model does not have; its "
                         f"parameters are {list(layout.names)}")
    if len(fixed) == len(layout.names):
        raise ValueError(f"fixed holds every parameter {list(layout.names)}: nothing to fit")
    if start:
        unknown = sorted(set(start) - set(layout.names))
        if unknown:
            raise ValueError(f"start has parameter names {unknown} that this model does not "
                             f"have; its parameters are {list(layout.names)}")
    return layout


def _choose_likelihood(recs, mdl, likelihood, f_range, excluded, robust, notes):
    """``(use, exact_ok)``: the likelihood to fit first (``'exact'`` or ``'whittle'``) and
    whether the exact one may still replace a Whittle fit whose relaxation time turns out
    long. Raises for an explicit ``likelihood='exact'`` that the model or options exclude."""
    use = likelihood
    if any_irregular(recs):
        return _irregular_choice(recs, mdl, likelihood, f_range, excluded, robust, notes), False
    if use == "auto":
        use = "whittle" if min(r.n_frames for r in recs) > 2**14 else "exact"
        if (f_range is not None or excluded or robust) and use == "exact":
            use = "whittle"
            notes.append(("f_range" if f_range is not None else "excluded ranges"
                          if excluded else "robust") + " given: the Whittle likelihood over "
                         "that band (the exact likelihood uses every frequency)")
    if use == "exact" and not mdl.alias:
        if likelihood == "exact":
            raise ValueError(f"model {mdl.name!r} is not aliased (an anti-aliased "
                             "photodiode): its frames are not the sampled trap process of "
                             "the exact likelihood; use likelihood='whittle'")
        use = "whittle"
    if use == "exact" and mdl.extra:
        if likelihood == "exact":
            raise ValueError("the exact time-domain likelihood covers the closed-form "
                             "model only; use likelihood='whittle' with effects "
                             f"{[e.name for e in mdl.extra]}")
        use = "whittle"
    exact_ok = (not mdl.extra and f_range is None and not excluded and not robust
                and mdl.alias and mdl.closed_form)
    if use == "whittle" and likelihood == "auto" and exact_ok:
        ks, gs = zip(*[moment_start(r)[:2] for r in recs])
        if _leakage_index(recs, ks, float(np.median(gs))) > _LEAKAGE_INDEX_MAX:
            use = "exact"
            notes.append("likelihood: exact (the relaxation time is not short compared with "
                         "the record, where the Whittle approximation is biased)")
    return use, exact_ok


def _irregular_choice(recs, mdl, likelihood, f_range, excluded, robust, notes) -> str:
    """Irregular time stamps: the exact likelihood at the recorded times where the model and
    options allow it (closed-form, aliased, every frequency); otherwise the Whittle fit on the
    nominal grid, with a note that the jitter is ignored (an explicit ``'exact'`` raises)."""
    why = ("the model adds effects" if mdl.extra else "the model is not aliased"
           if not mdl.alias else "f_range / excluded / robust select frequencies"
           if (f_range is not None or excluded or robust) else "")
    if likelihood == "whittle" or why:
        if likelihood == "exact":
            raise ValueError(f"the exact likelihood at irregular frame times is not available: "
                             f"{why}; use likelihood='whittle' (frames treated as regular)")
        notes.append("time stamps irregular: this fit treats the frames as regular (the "
                     "Whittle likelihood needs a regular grid"
                     + (f"; the exact likelihood at the recorded times is unavailable: {why}"
                        if why else "; likelihood='exact' fits the recorded times") + ")")
        return "whittle"
    notes.append("likelihood: exact, at the recorded (irregular) frame times")
    notes.extend(rounding_notes(mdl, recs))
    return "exact"


def _fit_likelihood(recs, layout, mdl, likelihood, f_range, excluded, robust, start, strict,
                    fixed, notes):
    """``method='likelihood'``: the exact or the Whittle likelihood (see
    :func:`_choose_likelihood`); a Whittle fit whose leakage index is large is replaced by
    the exact fit (``likelihood='auto'``) or gets a note."""
    use, exact_ok = _choose_likelihood(recs, mdl, likelihood, f_range, excluded, robust, notes)
    if use == "exact":
        if not any(n.startswith("likelihood: exact") for n in notes):
            notes.append("likelihood: exact")
        return _fit_exact(recs, layout, mdl, notes, fixed)
    res = _fit_spectral(recs, layout, mdl, 1, f_range, "likelihood", list(notes), start,
                        strict, fixed, excluded, robust)
    p = res.params
    if "gamma" in p and "c" not in p:
        kvals = res.k_per_recording
        leak = _leakage_index(recs, kvals, p["gamma"])
        if leak > _LEAKAGE_INDEX_MAX:
            if likelihood == "auto" and exact_ok:
                notes.append("likelihood: exact (the fitted relaxation time is not short "
                             "compared with the record, where the Whittle approximation "
                             "is biased)")
                return _fit_exact(recs, layout, mdl, notes, fixed)
            res = dataclasses.replace(res, notes=res.notes + (
                f"Whittle leakage index sqrt(N) tau/T = {leak:.2g} > {_LEAKAGE_INDEX_MAX}: "
                "the relaxation time is not short compared with the record and the "
                "Whittle approximation may bias gamma by a fraction of its SE or more; "
                "likelihood='exact' is exact",))
    return dataclasses.replace(res, notes=(*notes, "likelihood: whittle",
                                           *res.notes[len(notes):]))


def _fit_psd(recs, layout, mdl, n_blocks, f_range, excluded, robust, start, strict, fixed,
             notes):
    """``method='psd'``: blocked periodogram, ``n_blocks`` or a default block count (a note
    says which); refused (or noted, with a user's ``n_blocks``) when blocks are too short."""
    nb = n_blocks
    if nb is None:
        # blocks long compared with tau (>= 100 tau from the closed-form start): shorter
        # blocks correlate neighbouring ordinates and the Gamma likelihood then
        # understates the errors (SE/SD 0.33 measured with 7-tau blocks)
        taus = [st[1] / st[0] for st in (moment_start(r) for r in recs)]
        n_min = min(r.n_frames for r in recs)
        t_min = min(r.n_frames * float(r.frame_interval) for r in recs)
        nb = max(1, min(128, n_min // 64, int(t_min / (100.0 * max(taus)))))
        # a power of two: the block length (an array shape) then takes few values across
        # records, so new recordings rarely recompile the fit
        nb = 1 << (nb.bit_length() - 1)
        notes.append(f"psd: {nb} blocks of {n_min // nb} frames (>= 100 tau each where "
                     "the record allows)")
    res = _fit_spectral(recs, layout, mdl, int(nb), f_range, "psd", notes, start, strict,
                        fixed, excluded, robust)
    return _check_psd_blocks(res, recs, int(nb), explicit=n_blocks is not None)
