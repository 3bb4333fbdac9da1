"""The maximum-likelihood methods of ``calibrate``: Whittle / blocked-PSD fits (with held
parameters and the robust refit), the exact time-domain likelihood, and the Whittle
leakage index that chooses between them."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope
from . import _noise_pooling
from ._assemble import _assemble, _interval_source, _k_mode_of
from ._fit import chi2_sf, fit_ml, fit_ml_fd_newton
from ._fixed import expand as expand_fixed
from ._fixed import held_consistency_note, reduced_objective
from ._fixed import propagate as propagate_fixed
from ._fixed import reduce as reduce_fixed
from ._innovations import innovation_gof
from ._irregular import IrregularArgs, any_irregular, frame_intervals, irregular_nll, make_irregular_args
from ._models import get_model
from ._pooling import alone_estimates, disagreements, pooling_note
from ._problems import exact_nll, make_exact_args, make_layout, spectral_nll
from ._refusals import _check_fit, _check_relaxation_resolved, _held_sentence, _unit
from ._result import FitError
from ._screen_fit import fit_nll_only
from ._spectral import _psd_jit, _spectral_args, spectral_gof, unpadded
from ._starts import _start_vector


def _fit_spectral(recs, layout, model, n_blocks, f_range, method_name, notes, start=None,
                  strict=True, fixed=None, excluded=None, robust=False):
    """Whittle (``n_blocks=1``) or blocked-PSD Gamma-likelihood fit of all recordings, with
    ``fixed`` parameters held and, with ``robust``, spikes left out; refused when the fit
    fails or the relaxation time is not resolved by the record (or block)."""
    args = _spectral_args(recs, layout, model, n_blocks, f_range, excluded)
    scale = _start_vector(recs, layout, model.noise, start)
    out, held = _fit_held(fit_ml, spectral_nll, scale, args, layout.names, fixed)
    _check_fit(out, layout.names, method_name, strict, notes, recs, fixed)
    if robust:
        out, held, args = _robust_refit(out, held, args, scale, layout, fixed, notes,
                                        method_name, strict, recs)
    psd = _psd_jit(out.value, args)
    gof = spectral_gof(args.power / psd, args.weight, len(layout.names))
    notes = [*notes, *_pooling_notes(recs, layout, model, args, psd, out.nll, gof["p_value"],
                                     fixed, f_range, excluded, fit=(out.value, out.cov))]
    if fixed:
        note = held_consistency_note(spectral_nll, args, out.value, scale, layout.names, fixed,
                                     eqx.tree_at(lambda a: a.power, args, psd),
                                     gof["p_value"])
        if note:
            notes = [*notes, note]
    extras = {"n_blocks": n_blocks, "nll": float(out.nll), "k_mode": _k_mode_of(layout),
              "f": unpadded(args, args.f), "ratio": unpadded(args, args.power / psd),
              "weight": unpadded(args, args.weight)}
    res = _assemble(recs, layout, model, method_name, out.value, out.cov, gof, notes, extras,
                    at_bound=out.at_bound, conditional=out.conditional,
                    interval_source=_interval_source(spectral_nll, args, scale, out, held))
    block = None if n_blocks <= 1 else min(r.n_frames for r in recs) // n_blocks
    return _relaxation_resolved(res, recs, method_name, fixed, block)


#: a shared stiffness is questioned when the joint fit's goodness of fit and at least two of
#: the recordings sharing it have p below this
_POOL_ALPHA = 1e-3


def shared_k_note(layout, ratio, weight, gof_p) -> str | None:
    """A note when recordings that share one k (no laser powers, or equal ones) do not fit
    it: the joint goodness of fit and two or more of the sharing recordings' own binned
    tests fail, some above the joint spectrum at low frequency and some below. Recordings of
    different stiffness (another power, bead or height) pooled
    into one k give a k between theirs with errors far too small; the note names which
    lie above the joint spectrum at low frequency (softer: S(0) ~ gamma/k^2) and which
    below."""
    if not gof_p < _POOL_ALPHA or layout.linear_power:
        return None  # k = c P: power_law_note
    idx = np.asarray(layout.k_index)
    ratio, weight = np.asarray(ratio), np.asarray(weight)
    bad = []
    for g in np.unique(idx):
        members = np.flatnonzero(idx == g)
        if members.size < 2:
            continue
        for i in members:
            p = spectral_gof(ratio[i:i + 1], weight[i:i + 1], 0)["p_value"]
            if p < _POOL_ALPHA:
                keep = np.flatnonzero(weight[i] > 0)
                low = keep[: max(8, keep.size // 20)]  # the lowest 5 % of the band
                level = float(np.average(ratio[i, low], weights=weight[i, low]))
                bad.append((int(i), p, level, layout.k_labels[g]))
    levels = [lv for _, _, lv, _ in bad]
    if len(bad) < 2 or not (min(levels) < 1.0 < max(levels)):
        return None  # all on one side: a shared misfit (the model), not a pooling
    shown = "; ".join(f"recording {i}: p = {p:.2g}, low-frequency power {lv:.2g} x the joint "
                      f"fit ({'softer' if lv > 1 else 'stiffer'} than {lab})"
                      for i, p, lv, lab in bad)
    return (f"recordings sharing one stiffness do not fit it (joint goodness of fit p = "
            f"{gof_p:.2g}; {shown}): recordings of different stiffness (another laser power, "
            "bead or height) pooled into one k give a k between theirs with errors far too "
            "small. Give each recording's laser_power, or fit k='per_recording'")


def _pooling_notes(recs, layout, model, args, psd, whittle_nll, gof_p, fixed, f_range=None,
                   excluded=None, fit=None) -> list[str]:
    """The joint fit's notes on what its recordings share, when its goodness of fit
    ``gof_p`` fails: :func:`shared_k_note`'s spectral test for k and the shared parameters
    the recordings' own fits disagree on (:mod:`._pooling`; the first dropped when the own
    k agree and another parameter does not), and with ``k = c P`` the likelihood-ratio test
    against one k per power on the Whittle objective at ``whittle_nll`` (None: not run)."""
    ratio = args.power / psd
    k_note = shared_k_note(layout, ratio, args.weight, gof_p)
    other = None
    if len(recs) >= 2 and gof_p < _POOL_ALPHA:
        found = disagreements(layout, alone_estimates(recs, layout, model, f_range, excluded,
                                                      fixed))
        if k_note and "k" not in found and set(found) - {"k"}:
            k_note = None
        other = pooling_note(found, k_note is not None, recs)
    power = None if whittle_nll is None else \
        power_law_note(recs, layout, model, args, whittle_nll, gof_p, fixed)
    # beside Cochran's note on eps^2 too: it has no refitted k and gamma (a reviewer: c 17 SE,
    # gamma 29 SE low with only that note)
    noise = None if fit is None else _noise_pooling.noise_note(layout, args, fit[0], fit[1], fixed)
    return [n for n in ("; ".join(n for n in (k_note, other) if n), power, noise) if n]


def power_law_note(recs, layout, model, args, nll_value, gof_p, fixed) -> str | None:
    """With ``k = c P`` (``k='linear_power'``) and a failing joint goodness of fit: a
    likelihood-ratio test against one k per power (the same Whittle objective on the same
    ordinates, one more fit); a note when k is not proportional to P (an offset ``k = c (P -
    P0)``, heating), naming the per-power stiffnesses."""
    if not (layout.linear_power and gof_p < _POOL_ALPHA) or (fixed and "c" in fixed):
        return None
    if any(n.startswith("power_offset") for n in layout.extra_names):
        return None  # one k per power cannot hold P0 too; the model has the offset already
    alt = make_layout(recs, "per_power", layout.noise, layout.extra_names)
    if alt.n_k < 2:
        return None
    alt_args = eqx.tree_at(lambda a: a.layout, args, alt)
    out, _ = _fit_held(fit_ml, spectral_nll, _start_vector(recs, alt, model.noise), alt_args,
                       alt.names, fixed)
    if not bool(out.converged):
        return None
    lr = 2.0 * (float(nll_value) - float(out.nll))
    dof = alt.n_k - 1
    p = float(chi2_sf(max(lr, 0.0), dof))
    if not p < _POOL_ALPHA:
        return None
    metres = _unit(recs) == "m"
    ks = ", ".join(f"{lab}: {float(v) * 1e3:.4g}" for lab, v in
                   zip(alt.k_labels, np.asarray(out.value)[: alt.n_k]))
    return (f"k = c P does not fit these recordings: one k per power fits better by a "
            f"likelihood ratio of {lr:.4g} ({dof} dof, p = {p:.2g}; joint goodness of fit p = "
            f"{gof_p:.2g})" + (f", with k [pN/nm] {ks}" if metres else "")
            + ". The stiffness is not proportional to the laser power (an offset, k = c (P - "
            "P0)), or gamma changes with it (heating), and c, gamma and their errors are "
            "biased: fit k='per_power', or diagnose the series (power_offset, laser_heating)")


#: robust spectral fit: an ordinate whose Gamma upper tail probability under the fit is below
#: this (Bonferroni over the ordinates) is a spike and gets no weight
ROBUST_ALPHA = 1e-3


def _robust_refit(out, held, args, scale, layout, fixed, notes, method, strict, recs):
    """Drop ordinates far above the fitted spectrum (spikes, lines) and refit, up to 3
    times; the count and the frequencies go into the notes."""
    from jax.scipy.special import gammaincc

    dropped = np.zeros(np.shape(args.weight), bool)
    for _ in range(3):
        w = np.asarray(args.weight)
        ratio = np.asarray(args.power / _psd_jit(out.value, args))
        n_eff = np.where(w > 0, w, 1.0)
        tail = np.asarray(gammaincc(n_eff, n_eff * ratio))
        spikes = (w > 0) & (tail < ROBUST_ALPHA / max(int(np.sum(w > 0)), 1))
        if not spikes.any():
            break
        dropped |= spikes
        args = eqx.tree_at(lambda a: a.weight, args, jnp.asarray(np.where(spikes, 0.0, w)))
        out, held = _fit_held(fit_ml, spectral_nll, scale, args, layout.names, fixed)
        _check_fit(out, layout.names, method, strict, notes, recs, fixed)
    if dropped.any():
        fr = np.asarray(args.f)[dropped]
        shown = ", ".join(f"{v:.5g}" for v in fr[:8]) + (" ..." if fr.size > 8 else "")
        notes.append(f"robust: {int(dropped.sum())} ordinate(s) far above the fitted spectrum "
                     f"(Gamma tail p < {ROBUST_ALPHA:g}/M) left out: {shown} Hz")
    else:
        notes.append("robust: no ordinate far above the fitted spectrum")
    return out, held, args


@float64_scope
def screen_model(recs, model, k, start=None, f_range=None, excluded=None):
    """Whittle fit of ``model`` without standard errors: ``(params dict, nll, gof, ok)``.
    Same ordinates and objective as ``calibrate(method='likelihood', likelihood='whittle')``
    on the recordings and band it fitted (``result.inputs``: ``f_range``, ``excluded``) so
    that log-likelihoods of nested models are comparable."""
    mdl = get_model(model)
    layout = make_layout(recs, k, mdl.noise, tuple(p.name for p in mdl.extra_params))
    args = _spectral_args(recs, layout, mdl, 1, f_range, excluded)
    scale = _start_vector(recs, layout, mdl.noise, start)
    p, nll, ok = fit_nll_only(spectral_nll, scale, args)
    psd = _psd_jit(jnp.asarray(p), args)
    gof = spectral_gof(args.power / psd, args.weight, len(layout.names))
    return dict(zip(layout.names, map(float, p))), nll, gof, ok


def _fit_held(fit, nll, scale, args, names, fixed, propagate=True):
    """``fit(nll, scale, args)`` with the parameters in ``fixed`` ({name: (value, se)}) held:
    ``(FitOutput on all parameters, held)``, the input errors propagated into the covariance
    (:mod:`._fixed`) unless ``propagate`` is False (a start value, whose errors are not
    used); ``held`` is None without fixed parameters, else what the intervals need (reduced
    objective, its start scale, args and output)."""
    if not fixed:
        return fit(nll, scale, args), None
    free, fscale, fargs = reduce_fixed(names, scale, args, fixed)
    red = reduced_objective(nll)
    out = fit(red, fscale, fargs)
    full = expand_fixed(out, free, len(names), fargs.full)
    if not propagate:
        return full, None
    cov = propagate_fixed(nll, args, full.value, full.cov, names, fixed)
    full = eqx.tree_at(lambda o: o.cov, full, jnp.asarray(cov))
    return full, (red, fscale, fargs, out, free, any(se > 0 for _, se in fixed.values()))


def _fit_exact(recs, layout, model, notes, fixed=None):
    """Exact time-domain (ARMA) likelihood fit, started from the Whittle estimate (and also
    from the closed forms where Whittle is unreliable, keeping the better optimum). Recordings
    with irregular time stamps use the exact likelihood at the recorded frame times
    (:mod:`blurtrap.inference._irregular`)."""
    if any_irregular(recs):
        args, nll = make_irregular_args(recs, layout, model), irregular_nll
    else:
        args, nll = make_exact_args(recs, layout, model), exact_nll
    # start from the (cheap, asymptotically equivalent) Whittle estimate
    sargs = _spectral_args(recs, layout, model, 1, None)
    moment = _start_vector(recs, layout, model.noise)
    wout, _ = _fit_held(_fit_start, spectral_nll, moment, sargs, layout.names, fixed, False)
    starts = [wout.value] if bool(wout.success) else []
    names = layout.names
    if not starts or ("k" in names and _leakage_index(
            recs, float(wout.value[0]), float(wout.value[names.index("gamma")]))
            > _LEAKAGE_INDEX_MAX):
        # where Whittle is unreliable (tau not << T) also start from the closed forms and
        # keep the better optimum: the exact likelihood can have a second local optimum there
        starts.append(moment)
    out = s_out = held = None
    for s0 in starts:
        cand, h0 = _fit_held(fit_ml_fd_newton, nll, s0, args, names, fixed)
        if out is None or (bool(cand.converged) and (not bool(out.converged)
                                                      or float(cand.nll) < float(out.nll))):
            out, s_out, held = cand, s0, h0
    assert out is not None  # starts is never empty
    _check_fit(out, layout.names, "likelihood (exact)", recs=recs, fixed=fixed)
    # goodness of fit on the periodogram against this fit's own spectrum
    psd = _psd_jit(out.value, sargs)
    gof = spectral_gof(sargs.power / psd, sargs.weight, len(layout.names))
    extras = {"loglik": -float(out.nll), "f": unpadded(sargs, sargs.f),  # as Whittle's:
              "ratio": unpadded(sargs, sargs.power / psd),  # data/model and its weights
              "weight": unpadded(sargs, sargs.weight)}
    if isinstance(args, IrregularArgs):  # the periodogram of irregular frames misfits
        gof, ratios = innovation_gof(out.value, args, len(layout.names),
                                     [float(np.mean(frame_intervals(r))) for r in recs])
        extras.update(ratios)
    notes = [*notes, *_pooling_notes(recs, layout, model, sargs, psd,
                                     wout.nll if bool(wout.success) else None,
                                     gof["p_value"], fixed, fit=(out.value, out.cov))]
    if fixed:
        note = held_consistency_note(nll, args, out.value, moment, names, fixed,
                                     eqx.tree_at(lambda a: a.power, sargs, psd),
                                     gof["p_value"])
        if note:
            notes = [*notes, note]
    res = _assemble(recs, layout, model, "likelihood", out.value, out.cov, gof, notes, extras,
                    at_bound=out.at_bound, conditional=out.conditional,
                    interval_source=_interval_source(nll, args, s_out, out, held,
                                                     hessian="fd"))
    return _relaxation_resolved(res, recs, "likelihood (exact)", fixed)


def _relaxation_resolved(res, recs, method, fixed, block=None):
    """:func:`_check_relaxation_resolved`, its refusal naming the held values (a wrong one
    runs k or tau off too)."""
    try:
        return _check_relaxation_resolved(res, recs, method, block)
    except FitError as e:
        if not fixed:
            raise
        raise FitError(str(e) + _held_sentence(fixed)) from None


def _fit_start(nll, scale, args):
    """A fit used only for its estimate (start values): no at-bound error computation."""
    return fit_ml(nll, scale, args, release=False)


#: Switch from Whittle to the exact likelihood above this leakage index (see below).
_LEAKAGE_INDEX_MAX = 1.0


def _leakage_index(recs, k_values, gamma):
    """``max_r sqrt(N_r) tau_r / T_r``: the Whittle likelihood's finite-record bias in units of
    the standard error scales like this. Measured (benchmarks/study_whittle_leakage.py, results
    in benchmarks/RESULTS_calibration.md; 8 seeds x 65 536 frames, W = dt, same data for both
    likelihoods): the mean Whittle-minus-exact shift of gamma is +0.35, +0.61, +0.14, +0.01 SE
    at index 8.5, 2.6, 0.85, 0.26 (with P_d instead of the exact expected periodogram it was
    -2.0, -0.7, -0.2, -0.08 SE). Above 1.0 auto uses the exact likelihood (below it the
    shift is < ~0.15 SE and Whittle is up to ~250x cheaper on long photodiode records)."""
    idx = 0.0
    for r, kk in zip(recs, np.broadcast_to(np.asarray(k_values, dtype=float), (len(recs),))):
        tau = gamma / kk
        idx = max(idx, math.sqrt(r.n_frames) * tau / (r.n_frames * float(r.frame_interval)))
    return idx

