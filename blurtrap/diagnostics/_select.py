"""Forward model selection (:func:`select_model`: diagnose, add the best significant effect,
repeat) and the comparison of two fits of the same data (:func:`compare`)."""

from __future__ import annotations

from ..inference import CalibrationResult, get_model
from ..inference.internal import as_recordings
from ._candidates import _check_alpha, _check_candidates, candidate_name
from ._diagnose import diagnose
from ._results import Selection


def select_model(data, model=None, *, max_steps: int = 3, alpha: float = 0.05,
                 k: str | None = None, candidates=None) -> Selection:
    """Forward selection: diagnose, add the best significant effect, diagnose again, until the
    model is adequate, nothing significant is left, or `max_steps` effects were added.

    Each step is one :func:`diagnose` call (Bonferroni over its candidates at family-wise
    `alpha`), so the chance of adding a spurious effect at a given step is <= `alpha`; the
    steps are not jointly corrected. Effects outside the Gaussian likelihood
    (``anharmonicity``, ``timing_jitter``) cannot be added: when one ranks first the
    selection stops and says so.

    **Arguments:** `data`, `model`, `alpha`, `k`, `candidates` as in :func:`diagnose`;
    `max_steps`: most effects to add (int >= 1).

    **Returns:** :class:`Selection` (``model``, ``adequate``, ``added``, ``steps``).
    """
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"max_steps must be an integer >= 1; got max_steps = {max_steps!r}")
    alpha = _check_alpha(alpha)
    candidates = _check_candidates(candidates)
    recs = as_recordings(data)
    mdl = get_model(model)
    steps, added, notes = [], [], []
    while True:
        d = diagnose(recs, mdl, candidates=candidates, alpha=alpha, k=k)
        steps.append(d)
        best = d.best
        if d.adequate or best is None:
            break
        if best.model is None:
            notes.append(f"{best.effect} ranks first but is not part of the Gaussian likelihood "
                         "(it cannot be added to the model): stopped")
            break
        if len(added) >= max_steps:
            notes.append(f"stopped after max_steps = {max_steps} added effects; {best.effect} "
                         "is still significant")
            break
        mdl = best.model
        added.append(best.effect)
        if candidates is not None:
            candidates = [c for c in candidates if candidate_name(c) != best.effect]
    notes += [n for n in steps[-1].notes if "is not significant, but adding it moves" in n]
    return Selection(model=mdl, adequate=steps[-1].adequate, steps=tuple(steps),
                     added=tuple(added), notes=tuple(notes))


def compare(fit_a: CalibrationResult, fit_b: CalibrationResult) -> dict:
    """Compare two fits of the same data (same method): goodness of fit, the log-likelihood
    gain and ``delta_aic = AIC(a) - AIC(b)`` (> 0: b is better), and the shift of each shared
    parameter in units of fit_a's standard error."""
    out: dict = {"gof_a": dict(fit_a.gof), "gof_b": dict(fit_b.gof)}
    if "nll" in fit_a.extras and "nll" in fit_b.extras:
        dll = float(fit_a.extras["nll"] - fit_b.extras["nll"])
        ddof = len(fit_b.param_names) - len(fit_a.param_names)
        out.update(delta_loglik=dll, delta_aic=2.0 * dll - 2.0 * ddof)
    shifts = {}
    for name in fit_a.param_names:
        if name in fit_b.param_names:
            a = fit_a.params[name]
            b = fit_b.params[name]
            e = fit_a.errors[fit_a.param_names.index(name)]
            shifts[name] = {"a": a, "b": b, "shift_in_se": (b - a) / e if e > 0 else float("nan")}
    out["shifts"] = shifts
    return out
