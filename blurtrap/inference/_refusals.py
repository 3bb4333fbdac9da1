"""Refusals of fits the data cannot support, and the messages that say why: no temporal
information, a relaxation time not resolved by the record or the PSD blocks, a singular or
ineffective Fisher information, a fit that did not converge."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ..physics import BOLTZMANN
from ._frames import (
    _outlier_sentence,
    _robust_temporal_z,
    mean_shift_sentence,
    temporal_information,
)
from ._result import FitError
from ._variance import empirical_variance_se


def refuse_without_temporal_information(recs, noise: bool = True) -> None:
    """``FitError`` when no recording's frames carry temporal information and fewer than 3
    exposures or laser powers identify gamma otherwise, or, with the friction known from the
    bead (``friction='stokes'``), one exposure cannot separate k from eps^2 (a model with
    tracking noise, ``noise``): the refusals of ``calibrate``'s ``method="auto"``, for
    callers that fit directly (``diagnose``)."""
    info = [temporal_information(r) for r in recs]
    if any(ok for ok, _ in info):
        return
    from ..data import instrument_settings

    n_exp = len({float(r.exposure) for r in recs})
    if any(instrument_settings(r)["friction"] == "stokes" for r in recs):
        # the friction is known: k follows from the blurred variance, but one exposure
        # cannot separate it from eps^2 (calibrate's refusal; diagnose cannot hold eps^2)
        if noise and n_exp < 2:
            raise FitError(known_friction_message(max(z for _, z in info)) + "; diagnose "
                           "has no held values: calibrate with tracking_var held instead")
        return
    powers = [r.laser_power for r in recs]
    if n_exp >= 3 or (all(p is not None for p in powers) and len(set(powers)) >= 3):
        return
    raise FitError(_no_temporal_information_message(recs, info))


def known_friction_message(best: float) -> str:
    """Why frames without temporal information (lag-1 correlation ``best`` standard errors
    above 0) and a known friction still do not give k from one exposure."""
    return (f"the frames carry no temporal information (lag-1 correlation only {best:.1f} "
            "standard errors above 0: dt >> tau, W < dt): with gamma known, k follows from "
            "the blurred variance var = kT/k S(W k/gamma) + eps^2 alone, which cannot "
            "separate k from the tracking-error variance eps^2. Give it: fixed={'tracking_var':"
            " eps2} in m^2 (0 when the tracking error is negligible; CLI --fix "
            "tracking_var=NM2), or record at several exposures")


def _no_temporal_information_message(recs, info):
    """Why these recordings cannot identify gamma, what they do determine (the frame
    variance), and what to give or record instead."""
    best = max(z for _, z in info)
    v, se = empirical_variance_se(recs[0].positions)
    n = min(r.n_frames for r in recs)
    out = _outlier_sentence(recs)
    why = (out if out else f"only {n} frames" if n < 200 else
           "dt >> tau (the bead relaxes between frames), or tracking noise dominates the motion")
    return (
        f"these recordings cannot identify gamma: the lag-1 correlation of the frames is only "
        f"{best:.1f} standard errors above 0 ({why}) and there are fewer than 3 exposures or "
        f"laser powers. What they do determine is the frame variance var(X_m) = "
        f"{v * 1e18:.4g} +- {se * 1e18:.2g} nm^2 (recording 0). Give the diffusion coefficient "
        "(diffusion=D with method='auto' or 'equipartition': blur-corrected equipartition), or "
        "record an exposure series or a power series."
    )


def _slow_relaxation_hint(recs, values, names, shift):
    """A sentence when the fitted tau is not short compared with the record (else '');
    ``shift``: a callable giving :func:`mean_shift_sentence` of ``recs``."""
    if "gamma" not in names or "k" not in names:
        return ""
    tau = float(values[names.index("gamma")]) / float(values[names.index("k")])
    dur = min(r.n_frames * float(r.frame_interval) for r in recs)
    if math.isfinite(tau) and tau > dur / 30.0:
        if shift():  # named among the causes: the step/drift's doing
            return (f" The fitted relaxation time tau = gamma/k = {tau:.3g} s is the step or "
                    "drift read as a slow relaxation.")
        info = [temporal_information(r) for r in recs]
        if all(z < 0.5 * math.sqrt(r.n_frames) for r, (_, z) in zip(recs, info)):
            return f" The fit ran tau = gamma/k to {tau:.3g} s, but " + \
                _no_temporal_information_message(recs, info)
        return (f" The fitted relaxation time tau = gamma/k = {tau:.3g} s is not short compared "
                f"with the record ({dur:.3g} s): the bead diffuses almost freely, so k is not "
                "identified; record longer or use a stiffer trap.")
    return ""


def _unit(recs) -> str:
    return str(getattr(recs[0], "position_unit", "m")) if recs else "m"


def _shift_hint(recs) -> str:
    """A step or drift read as a slow relaxation: the sentence naming it ('' without)."""
    shift = mean_shift_sentence(recs, _unit(recs))
    return (f" But the frames show that {shift}; a stationary model reads that as a very "
            "slow relaxation." if shift else "")


def _check_relaxation_resolved(res, recs, method, block_frames=None):
    """Refuse a fit whose relaxation time is longer than a third of the record (or block):
    the bead then diffuses almost freely, the likelihood runs k towards 0, and the observed
    Fisher information at that edge gives a meaningless, tiny error on k. gamma (D) is still
    identified and is quoted in the message."""
    g, ge = res.gamma, res.gamma_err
    if not math.isfinite(g):
        return res
    for i, (r, kk) in enumerate(zip(recs, res.k_per_recording)):
        n = r.n_frames if block_frames is None else min(block_frames, r.n_frames)
        dur = n * float(r.frame_interval)
        tau = g / float(kk)
        if not (tau < dur / 3.0):
            informative, z = temporal_information(r)
            shift = _shift_hint(recs)
            # a freely diffusing bead has r1 ~ 1; frames with some correlation and a drift or
            # step are the drift's doing (named below), white frames lack information anyway
            if not informative or (z < 0.5 * math.sqrt(r.n_frames) and not shift):
                raise FitError(f"{method} fit ran k to {float(kk):.3g} N/m, but the frames are "
                               "far less correlated than a freely diffusing bead's: "
                               + _no_temporal_information_message([r], [(informative, z)])
                               + shift)
            what = "record" if block_frames is None else f"block ({n} frames)"
            d = BOLTZMANN * float(r.temperature) / g
            raise FitError(
                f"{method} fit: the relaxation time tau = gamma/k = {tau:.3g} s of recording {i} "
                f"is longer than a third of the {what} ({dur:.3g} s): the bead diffuses almost "
                f"freely and k is not identified (the fit ran it to {float(kk):.3g} N/m). gamma "
                f"= {g:.4g} +- {ge:.2g} N s/m (D = {d * 1e12:.4g} um^2/s) is still determined. "
                "Record longer than ~10 tau, use a stiffer trap"
                + (", or fewer, longer blocks (n_blocks)" if block_frames else "") + "."
                + shift
            )
    return res


#: a blocked-PSD fit needs blocks at least this many relaxation times long, and a leakage
#: index sqrt(M) tau/T_block (see `_leakage_index`) of at most this: a 65 536-frame record
#: fitted in one block at index 7.1 (k = 1e-5 pN/nm, dt = W = 1/1500 s, T = 32 tau) put
#: gamma 5.6 SE low, while the photodiode peer set (index 1.5, 8 blocks) is honest
_PSD_MIN_BLOCK_TAU = 20.0
_PSD_LEAKAGE_MAX = 3.0


def _check_psd_blocks(res, recs, n_blocks, explicit):
    """Blocks shorter than ~20 tau leave few, strongly correlated ordinates below the corner
    frequency; the Gamma likelihood of the block averages then treats them as independent
    and reports errors that are far too small (measured: 2048-frame records with tau = T/10
    in one block gave gamma 6-9 SE low, benchmarks/study_robustness.py), and so do long
    records in one block when the leakage index is large. With the default
    block count this is an error (the record itself is too short for a PSD fit); with a
    user's `n_blocks` a note."""
    g = res.gamma
    if not math.isfinite(g):
        return res
    for r, kk in zip(recs, res.k_per_recording):
        m = r.n_frames // n_blocks
        ratio = m * float(r.frame_interval) / (g / float(kk))
        leak = math.sqrt(m) / ratio
        if ratio >= _PSD_MIN_BLOCK_TAU and leak <= _PSD_LEAKAGE_MAX:
            continue
        msg = (f"psd: blocks of {m} frames are only {ratio:.3g} relaxation times "
               f"(tau = gamma/k = {g / float(kk):.3g} s) long (leakage index sqrt(M) tau/T = "
               f"{leak:.2g}; needed: >= {_PSD_MIN_BLOCK_TAU:g} tau and index <= "
               f"{_PSD_LEAKAGE_MAX:g}): neighbouring ordinates are correlated and the "
               "blocked-PSD estimates and errors cannot be trusted")
        if explicit:
            return dataclasses.replace(res, notes=res.notes + (
                msg + "; use fewer blocks (n_blocks) or method='likelihood'",))
        raise FitError(msg + ". The record is too short for a blocked PSD fit: use "
                       "method='likelihood' (exact for any record length)." + _shift_hint(recs))
    return res


def _singular_fisher_causes(recs, values, names, shift=None) -> str:
    """What the data say about why a fit failed: dt >> tau only when the frames (outliers
    clipped) really carry no temporal information; otherwise the outliers, steps or record
    length seen in the data, or a neutral list of possible causes."""
    if not recs:
        return ("possible causes: outliers or steps in the trace, a parameter at its bound, "
                "a wrong exposure or frame interval, or too short a record")
    causes = []
    zr = max(_robust_temporal_z(r) for r in recs)
    dt = min(float(r.frame_interval) for r in recs)
    tau = math.nan
    if "gamma" in names and "k" in names:
        tau = float(values[names.index("gamma")]) / float(values[names.index("k")])
    out = _outlier_sentence(recs)
    if zr < 5.0:
        causes.append(f"dt >> tau: the lag-1 correlation of the frames is only {zr:.1f} "
                      "standard errors above 0" + (f" (the fit ran tau = gamma/k to {tau:.3g} "
                      f"s; dt = {dt:.3g} s)" if math.isfinite(tau) else "")
                      + ", so there is little temporal information (use recordings at "
                      "several exposures or powers)")
    elif math.isfinite(tau) and tau < dt / 3.0 and not out:
        # (with outliers present and the clipped frames resolving the relaxation, the fitted
        # tau is the outliers' doing: the outlier sentence below names the cause)
        causes.append(f"dt >> tau: the fit puts the relaxation time tau = gamma/k at {tau:.3g} s, "
                      f"shorter than the frame interval {dt:.3g} s, where one recording carries "
                      "too little temporal information for gamma; give the friction "
                      "(friction='stokes' with the bead radius, or fixed={'gamma': ...}) or "
                      "record at several exposures")
    if out:
        causes.append(out)
    # the caller's once-computed mean_shift_sentence of recs (``shift``), else computed here
    shift = shift() if shift is not None else mean_shift_sentence(recs, _unit(recs))
    if shift:
        causes.append(shift)
    for i, r in enumerate(recs if not shift else ()):
        seg = np.array_split(np.asarray(r.positions, dtype=float), 8)
        if len(seg[-1]) < 8:
            continue
        meds = np.array([np.median(v) for v in seg])
        # spread within the segments: a step does not inflate it
        mad = 1.4826 * float(np.median([np.median(np.abs(v - m)) for v, m in zip(seg, meds)]))
        jump = float(meds.max() - meds.min())
        if mad > 0 and jump > 4.0 * mad:
            causes.append(f"a step or drift: the median position of recording {i} moves by "
                          f"{jump:.3g} m ({jump / mad:.2g} robust SDs) across the record")
    n = min(r.n_frames for r in recs)
    if n < 1000:
        causes.append(f"a short record ({n} frames)")
    if not causes:
        return ("nothing in the frames points to one cause; possible causes: outliers or "
                "steps in the trace, a parameter at its bound (e.g. eps^2 -> 0), a wrong "
                "exposure or frame interval, or too short a record")
    return "what the frames show: " + "; ".join(causes)


def _effect_parameters_hint(out, names, fixed) -> str:
    """Names the free parameters of effects in a fit that did not converge, with their
    values at the stop: an effect the data do not show (a detector filter on a trace without
    one) leaves its parameters undetermined, and the fit wanders along them."""
    core = ("k", "c", "gamma", "tracking_var")
    value = np.asarray(out.value, dtype=float)
    extra = [(n, v) for n, v in zip(names, value)
             if n.split("[")[0] not in core and n not in (fixed or {})]
    if not extra:
        return ""
    shown = ", ".join(f"{n} = {v:.4g}" for n, v in extra)
    return (f" The model's effect parameters ended at {shown}: if the data do not show one of "
            "these effects (e.g. a detector filter on a trace without one, diode_filter='fit'), "
            "its parameters are undetermined and the fit wanders along them; fit without it "
            "(diagnose says which effects the data need) or hold its parameters (fixed=...).")


def _held_sentence(fixed) -> str:
    """Names the held values in a refusal: a wrong one (value or unit) makes fits fail too."""
    if not fixed:
        return ""
    from ..effects import QUANTITIES

    shown = []
    for name, (v, _) in fixed.items():
        q = QUANTITIES.get(name.split("[")[0])
        shown.append(f"{name} = {v:.4g}" + (f" {q.unit} ({v * q.lab_factor:.4g} {q.lab_unit})"
                                            if q is not None else " (SI)"))
    return (f" Held in this fit: {', '.join(shown)}; a held value that disagrees with the "
            "data (a wrong value or unit: SI in Python, lab units on the CLI's --fix) also "
            "makes the fit fail: check it, or fit without it.")


def _check_fit(out, names, method, strict=True, notes=None, recs=None, fixed=None):
    """Refuse (``FitError``) a fit that did not converge or whose Fisher information is
    singular, in effect too (see :func:`_unidentified`), with the causes the frames show
    (and the held values, ``fixed``); with ``strict=False`` a singular information only
    adds a note."""
    # the step/drift sentence (segment FFTs of every record) once, and only where needed
    shift = functools.cache(lambda: mean_shift_sentence(recs, _unit(recs)) if recs else "")
    hint = _slow_relaxation_hint(recs, np.asarray(out.value), names, shift) if recs else ""
    hint += _held_sentence(fixed)
    if not bool(out.converged):
        seen = _outlier_sentence(recs) if recs else ""
        effects = _effect_parameters_hint(out, names, fixed)
        raise FitError(
            f"{method} fit did not converge after {int(out.n_steps)} steps "
            f"(max |grad| = {float(out.grad_norm):.3g}); parameters {names}. "
            + (f"The frames show {seen}." if seen else "Try another method or check the data "
               "(outliers, drift, wrong exposure/frame interval).")
            + effects + hint
        )
    if not bool(out.hessian_pd):
        if not strict:
            if notes is not None:
                notes.append(f"{method}: the Fisher information is singular (a parameter at "
                             "its bound or unidentifiable): standard errors are NaN" + hint)
            return
        why = _singular_fisher_causes(recs, np.asarray(out.value), names, shift)
        raise FitError(
            f"{method} fit: the Fisher information is singular - the parameters {names} are "
            f"not all identifiable from these data; {why}." + hint
        )
    lost = _unidentified(out, names)
    if lost and strict:
        # with a nuisance parameter at its bound the information of the others is finite,
        # but an SE above the value itself carries no information (white frames, dt >> tau:
        # k 4.4 +- 86 pN/nm): refuse as for a singular information, naming the cause
        why = _singular_fisher_causes(recs, np.asarray(out.value), names, shift)
        raise FitError(
            f"{method} fit: the Fisher information is singular in effect - {lost} have "
            f"standard errors above their values (or sit at their bound 0) and are not "
            f"identifiable from these data; "
            f"{why}." + hint
        )


#: k (or c) or gamma with a relative SE above this is not identified by the data
MAX_RELATIVE_SE = 1.0


def _unidentified(out, names) -> list[str]:
    """The stiffness and friction parameters whose standard error exceeds
    ``MAX_RELATIVE_SE`` times their value, or that sit at their lower bound 0 (setting them
    to 0 changes the likelihood by < 1e-6: tracking noise 10x the thermal motion gave k and
    gamma 'at the bound' with NaN errors and no refusal)."""
    value = np.asarray(out.value, dtype=float)
    se = np.sqrt(np.abs(np.diag(np.asarray(out.cov, dtype=float))))
    bound = np.zeros(value.size, bool) if out.at_bound is None else \
        np.asarray(out.at_bound, bool)
    core = [i for i, n in enumerate(names) if n in ("k", "c", "gamma") or n.startswith("k[")]
    return [names[i] for i in core
            if bound[i] or (np.isfinite(se[i]) and se[i] > MAX_RELATIVE_SE * abs(value[i]))]

