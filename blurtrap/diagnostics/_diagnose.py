"""Model criticism: is the model adequate, and which physical effect is missing?

``diagnose`` fits the model (default ``standard``), tests its goodness of fit, then tries
every applicable candidate effect (refit warm-started from the base fit, same Whittle
likelihood on the same periodogram ordinates, so log-likelihoods are comparable) and ranks
them by the improvement in AIC, each with a likelihood-ratio p-value and the residual
evidence behind it in words. Multiple testing: Bonferroni over the goodness-of-fit test and
all candidates, so a correct model is flagged in <= alpha of data sets.

Effects that are not part of the Gaussian likelihood are tested directly: anharmonicity by
the kurtosis of the frames (against its correlated-sample standard error), timing_jitter from
the time stamps. For those, ``delta_loglik`` is the score-test equivalent ``z^2/2``.

Physical plausibility: a candidate whose refit needs impossible parameters is reported but
never significant (``Candidate.plausible``): ``hydrodynamics`` with a radius above the Stokes
radius ``gamma/(6 pi eta)`` (Faxen's law only raises gamma), ``detector_filter`` with an
instantaneous fraction alpha > 1. At photodiode rates the two effects mimic each other's
high-frequency deficit closely; the radius check is what tells a photodiode filter from
hydrodynamics on short records (benchmarks/RESULTS_diagnose.md).

:func:`select_model` runs ``diagnose`` repeatedly, adding the best significant effect each
time (forward selection).

Layout: the candidates and how each is tested are in :mod:`._candidates`, the residual evidence
in words in :mod:`._evidence`, the result containers in :mod:`._results`, forward selection and
:func:`compare` in :mod:`._select`; this module holds :func:`diagnose` (base fit, ranking,
full refit of the best candidate, verdict).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._config import float64_scope
from ..inference import FitError, calibrate, get_model
from ..inference.internal import (
    as_recordings,
    chi2_sf,
    default_model,
    refuse_without_temporal_information,
)
from ..inference.internal import inspect_frames as _inspect_frames
from ._candidates import _check_alpha, _check_candidates, default_candidates, try_candidates
from ._detector import detector_note
from ._evidence import _ADDING, SENSITIVITY_SE, _gof_change, _sensitivity_notes, moved_by
from ._results import Candidate, Diagnosis


def _common_settings(recs) -> dict:
    """The first recording's instrument settings (validated for all)."""
    from ..data import instrument_settings

    return [instrument_settings(r) for r in recs][0]


def _k_mode(recs, k):
    """The stiffness sharing (default ``linear_power`` for >= 3 laser powers, ``shared`` for
    one, else ``per_power``) and whether the recordings span >= 3 powers."""
    powers = {float(r.laser_power) for r in recs if r.laser_power is not None}
    multi_power = len(powers) >= 3 and all(r.laser_power is not None for r in recs)
    if k is None:
        k = "linear_power" if multi_power else ("shared" if len(powers) <= 1 else "per_power")
    return k, multi_power


def _rank(out, threshold: float) -> list[Candidate]:
    """Mark the significant candidates (Bonferroni ``p < threshold``, ``delta_aic > 0``,
    plausible) and sort them best first: significant ones by AIC gain, then by p-value."""
    ranked = []
    for c in out:
        sig = (bool(c.p_value < threshold) and (c.delta_aic is None or c.delta_aic > 0)
               and c.plausible)
        ranked.append(dataclasses.replace(c, significant=sig))
    ranked.sort(key=lambda c: (not c.significant,
                               -(c.delta_aic if c.delta_aic is not None else
                                 (1e300 if c.significant else -1e300)),
                               c.p_value))
    return ranked


def _members(effect: str) -> set:
    return set(effect.split("+"))


def _prefer_complete(ranked: list, screened: dict, base) -> list[str]:
    """When a significant candidate contains the top one's effects and more (the camera core
    motion_blur+aliasing+tracking_noise over motion_blur+aliasing or tracking_noise), the data
    cannot tell them apart (their likelihood ratio is not significant) and yet k or gamma
    differs by more than SENSITIVITY_SE of the base fit's errors (:func:`moved_by`), rank the complete one first
    (as the sensitivity notes advise): otherwise the top refit is confidently wrong.
    Reorders ``ranked`` in place; returns the note."""
    if not ranked or not ranked[0].significant or ranked[0].delta_loglik is None:
        return []
    top = ranked[0]
    for i, c in enumerate(ranked[1:], start=1):
        if not (c.significant and c.delta_loglik is not None and c.dof >= top.dof
                and _members(c.effect) > _members(top.effect)):
            continue
        extra = c.dof - top.dof
        # (flag effects add no parameter, so the two need not be nested: twice the
        # log-likelihood difference is compared with chi^2 on max(extra, 1) dof both ways)
        if chi2_sf(2.0 * abs(c.delta_loglik - top.delta_loglik), max(extra, 1)) < 0.05:
            continue  # the data tell them apart: the ranking decides
        a, b = screened.get(top.effect), screened.get(c.effect)
        if a is None or b is None:
            continue
        moved = [n for n in moved_by(base, a, b) if n in ("k", "gamma")]
        if moved:
            ranked.insert(0, ranked.pop(i))
            return [f"{c.effect} is ranked above {top.effect}: the data cannot tell them apart "
                    f"(log-likelihood {c.delta_loglik - top.delta_loglik:+.2f} for {extra} more "
                    f"parameter(s)) but {' and '.join(moved)} differ by more than "
                    f"{SENSITIVITY_SE:g} SE between them, so the physically complete one is "
                    "preferred (a camera always has some tracking error)"]
    return []


#: effects the recording's declared detector implies (offered as candidates only where they
#: apply: motion blur for an exposure W > 0, aliasing for sampling without anti-aliasing) and
#: the tracking-noise floor a camera always has, which may come with them
_DETECTOR = frozenset({"motion_blur", "aliasing"})
_WITH_DETECTOR = _DETECTOR | {"tracking_noise"}


def _declared_detector(ranked: list, screened: dict, base, settings) -> list[str]:
    """When no candidate is significant but a candidate made of the detector physics the
    recording declares (its exposure's blur, its sampling's aliasing, with or without the
    tracking-noise floor) moves k or gamma by more than SENSITIVITY_SE of the base fit's errors
    (:func:`moved_by`), the model is not adequate: the data cannot tell the two apart, yet the
    model lacks what the instrument does by construction, and its answer is that many SE off
    (issue: a W = dt camera recording fitted with ``naive``). The most complete such candidate
    is marked ``required`` and ranked first (it is then refitted). Returns the note."""
    if not ranked or any(c.significant for c in ranked) or settings.get("anti_aliasing"):
        # a photodiode with anti-aliasing declares neither blur nor folding
        return []
    best = None
    for i, c in enumerate(ranked):
        members = _members(c.effect)
        params = screened.get(c.effect)
        if not (members & _DETECTOR and members <= _WITH_DETECTOR and c.plausible
                and c.model is not None and params is not None):
            continue
        moved = moved_by(base, base.params, params)
        rank = (len(members), c.delta_loglik if c.delta_loglik is not None else -np.inf)
        if moved and (best is None or rank > best[0]):
            best = (rank, i, moved)
    if best is None:
        return []
    _, i, moved = best
    c = dataclasses.replace(ranked.pop(i), required=True)
    ranked.insert(0, c)
    shifts = ", ".join(f"{n} by {z:+.1f} SE" for n, z in moved.items())
    return [f"{c.effect} is part of the declared detector (exposure, sampling) but missing from "
            f"the model: the data cannot tell the two apart (p = {c.p_value:.3g}), yet adding "
            f"it moves {shifts}, so the model is not adequate; refit with it (ranked first)"]


def _refit_best(recs, k, base, ranked: list, screened: dict) -> list[str]:
    """Full fit (with errors) of the best candidate when it is significant (or required by the
    declared detector) and part of the likelihood; replaces ``ranked[0]`` in place. Returns
    the notes (a failed refit)."""
    notes = []
    if ranked and (ranked[0].significant or ranked[0].required) \
            and ranked[0].model is not None:
        top = ranked[0]  # full fit (with errors) of the best candidate
        # from the screening optimum; if that fails (a parameter near its bound 0 cannot
        # converge in log coordinates), from the closed-form start
        for start in (screened.get(top.effect), None):
            try:
                best_fit = calibrate(recs, method="likelihood", likelihood="whittle",
                                     model=top.model, k=k, start=start, strict=False)
                # the evidence quotes the goodness of fit of the fit it carries
                ev = top.evidence.split(_ADDING)[0] + _gof_change(base.gof, best_fit.gof)
                ranked[0] = dataclasses.replace(top, fit=best_fit, evidence=ev)
                break
            except (FitError, ValueError) as exc:
                if start is None:
                    notes.append(f"full refit with {top.effect} failed: {exc}")
    return notes


def _verdict_notes(gof_ok: bool, adequate: bool, ranked) -> list[str]:
    notes = []
    if not gof_ok and not any(c.significant for c in ranked):
        notes.append("the goodness of fit fails but no candidate effect explains it: look at "
                     "the residuals (an effect outside the vocabulary, or a wrong exposure / "
                     "frame interval)")
    if adequate:
        notes.append("nothing is missing: the model describes the data within its errors")
    return notes


@float64_scope
def diagnose(data, model=None, *, candidates=None, alpha: float = 0.05, k: str | None = None,
             add=()) -> Diagnosis:
    """Fit ``model`` (default ``standard``), test it, and rank missing effects.

    **Arguments:**

    - `data`: Recording, RecordingSet, list of recordings or manifest path.
    - `model`: ``"naive"``, ``"blur"``, ``"standard"`` (default), a ``TrapModel`` or
      ``"standard+drift"``; `add`: effects (names or objects) added to it first.
    - `candidates`: effects to try, by canonical name or as effect objects
      (``bt.effects.Drift(drift_diffusion=2e-16)``: its values start the screening fit; the
      very object given to ``simulate(..., effects=...)``). Default: every effect of
      :data:`blurtrap.effects.EFFECTS` not in the model whose class says it ``applies`` to
      the data, tested the way it says (``diagnose_test``), plus the coupled groups.
    - `alpha`: family-wise false-alarm rate (Bonferroni over the GOF test and candidates).
    - `k`: stiffness sharing (default ``linear_power`` for >= 3 laser powers, so that
      power_offset / laser_heating are testable).

    **Returns:** :class:`Diagnosis` (``adequate``, ``gof``, ``ranking`` best first).

    **Raises:** ``ValueError`` for an ``alpha`` outside (0, 1), an unknown candidate name,
    or saturated or coarsely quantised frames (checked before any fit); ``FitError`` when
    the frames carry no temporal information and fewer than 3 exposures or laser powers
    identify gamma (as ``calibrate``).
    """
    alpha = _check_alpha(alpha)
    candidates = _check_candidates(candidates)
    recs = as_recordings(data)
    # saturated or coarsely quantised frames: refused here as by calibrate (the base fit
    # runs with strict=False, which would only note them)
    _inspect_frames(recs, strict=True)
    settings = _common_settings(recs)
    mdl = get_model(model) if model is not None else default_model(settings)
    if add:
        mdl = mdl.add(*add)
    # frames without temporal information (white noise, dt >> tau) cannot identify gamma
    # from one exposure, nor with a known friction k apart from eps^2: refused here as by
    # calibrate (the base fit would call the unidentifiable model adequate)
    refuse_without_temporal_information(recs, noise=bool(mdl.noise))
    k, multi_power = _k_mode(recs, k)
    notes = []
    base = calibrate(recs, method="likelihood", likelihood="whittle", model=mdl, k=k,
                     strict=False, lines="keep")
    if not all(np.isfinite(e) for n, e in zip(base.param_names, base.errors)
               if n not in base.at_bounds):
        notes.append("the base model's Fisher information is singular (a parameter is pinned "
                     "at its bound): its standard errors are undefined, a sign of misfit")
    if candidates is None:
        candidates = default_candidates(recs, mdl, k, multi_power)
    m = len(candidates) + 1
    threshold = alpha / m
    out, screened = try_candidates(recs, mdl, k, base, candidates)
    ranked = _rank(out, threshold)
    notes += _prefer_complete(ranked, screened, base)
    notes += _declared_detector(ranked, screened, base, settings)
    notes += _refit_best(recs, k, base, ranked, screened)
    notes += _sensitivity_notes(base, ranked, screened)
    gof_ok = base.gof["p_value"] >= threshold
    adequate = gof_ok and not any(c.significant or c.required for c in ranked)
    notes += _verdict_notes(gof_ok, adequate, ranked)
    notes += detector_note(recs, settings, ranked)
    return Diagnosis(model=mdl.name, fit=base, gof=base.gof, adequate=adequate,
                     ranking=tuple(ranked), threshold=threshold, notes=tuple(notes))
