"""The results of :func:`diagnose` and :func:`select_model`: :class:`Candidate` (one tried
effect), :class:`Diagnosis` (adequacy, goodness of fit, ranking) and :class:`Selection`."""

from __future__ import annotations

import dataclasses
import math

from ..inference import CalibrationResult
from ..inference.internal import html_table

_COLUMNS = ("effect", "delta_loglik", "dof", "delta_aic", "p_value", "significant",
            "plausible", "evidence")


def _num(v, fmt):
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


@dataclasses.dataclass(frozen=True, repr=False)
class Candidate:
    """A candidate missing effect. ``delta_loglik`` = log-likelihood gain when it is added,
    ``delta_aic`` = AIC(model) - AIC(model + effect): positive means the effect improves the
    fit after paying for its parameters."""

    effect: str
    delta_loglik: float | None
    dof: int
    p_value: float
    delta_aic: float | None
    evidence: str
    significant: bool = False
    fit: CalibrationResult | None = None
    model: object = None  # the TrapModel with this effect added (likelihood effects only)
    plausible: bool = True  # False: the refit needs physically impossible parameters
    #: not significant, but part of the recording's declared detector and moving k or gamma by
    #: more than 2 SE: the model lacks it (diagnose ranks it first and is not adequate)
    required: bool = False

    def __repr__(self) -> str:
        da = "n/a" if self.delta_aic is None else f"{self.delta_aic:.2f}"
        flags = ("significant" if self.significant else "not significant") + (
            "" if self.plausible else ", IMPLAUSIBLE") + (
            ", required by the declared detector" if self.required else "")
        return (f"Candidate({self.effect!r}, dAIC = {da}, p = {self.p_value:.3g}, {flags}: "
                f"{self.evidence})")

    def __str__(self) -> str:
        return self.__repr__()

    def _repr_html_(self) -> str:
        return html_table(_COLUMNS, [self._row()])

    def _row(self):
        return (self.effect, _num(self.delta_loglik, ".2f"), self.dof,
                _num(self.delta_aic, ".2f"), _num(self.p_value, ".3g"),
                "yes" if self.significant else "no", "yes" if self.plausible else "NO",
                self.evidence)

    def to_dict(self):
        return {"effect": self.effect, "delta_loglik": self.delta_loglik, "dof": self.dof,
                "p_value": self.p_value, "delta_aic": self.delta_aic,
                "significant": self.significant, "plausible": self.plausible,
                "required": self.required, "evidence": self.evidence}


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`: adequacy, goodness of fit and ranked candidate effects."""

    model: str
    fit: CalibrationResult
    gof: dict
    adequate: bool
    ranking: tuple[Candidate, ...]
    threshold: float
    notes: tuple[str, ...] = ()

    @property
    def best(self) -> Candidate | None:
        """The first-ranked candidate when it is significant or required by the declared
        detector (then the model lacks it), else None."""
        top = self.ranking[0] if self.ranking else None
        return top if top is not None and (top.significant or top.required) else None

    def __getitem__(self, effect: str) -> Candidate:
        """The candidate of one effect by its canonical name: ``d["drift"]``."""
        for c in self.ranking:
            if c.effect == effect:
                return c
        raise KeyError(f"no candidate {effect!r} in this diagnosis; the effects tried are "
                       f"{[c.effect for c in self.ranking]}")

    def verdict(self) -> str:
        """One line: adequate, or the best missing effect (or NOT adequate without one)."""
        if self.adequate:
            return ("adequate: no candidate effect improves the fit significantly "
                    f"(Bonferroni threshold p < {self.threshold:.3g})")
        b = self.best
        return ("NOT adequate" + (f": the best missing effect is {b.effect} (dAIC = "
                                  f"{_num(b.delta_aic, '.2f')}, p = {b.p_value:.3g}"
                                  + ("; required by the declared detector: it moves k or "
                                     "gamma by > 2 SE" if b.required else "") + ")"
                                  if b is not None else ""))

    def __repr__(self) -> str:
        return (f"Diagnosis(model {self.model!r}, {self.verdict()}; "
                f"{len(self.ranking)} candidates)")

    def __str__(self) -> str:
        return self.summary()

    def _repr_html_(self) -> str:
        """The ranking table (evidence and verdict) for notebooks."""
        g = self.gof
        cap = (f"model {self.model}: goodness of fit statistic = {g['statistic']:.4g}, "
               f"dof = {g['dof']}, p = {g['p_value']:.3g}; {self.verdict()}")
        table = html_table(_COLUMNS, [c._row() for c in self.ranking], cap)
        if self.notes:
            import html

            table += "".join(f"<p>note: {html.escape(n)}</p>" for n in self.notes)
        return table

    def to_dataframe(self):
        """The ranking as a pandas DataFrame (one row per candidate effect, best first,
        indexed by effect; columns as :meth:`Candidate.to_dict`). Needs pandas
        (``pip install "blurtrap[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError('Diagnosis.to_dataframe needs pandas: pip install '
                              '"blurtrap[pandas]"') from None
        rows = [c.to_dict() for c in self.ranking]
        return pd.DataFrame(rows, columns=list(_COLUMNS)).set_index("effect")

    def to_dict(self) -> dict:
        return {"model": self.model, "adequate": self.adequate, "gof": dict(self.gof),
                "threshold": self.threshold,
                "ranking": [c.to_dict() for c in self.ranking], "notes": list(self.notes),
                "fit": self.fit.to_dict()}

    def summary(self) -> str:
        g = self.gof
        lines = [f"model: {self.model}   goodness of fit: statistic = {g['statistic']:.4g}, "
                 f"dof = {g['dof']}, p = {g['p_value']:.3g}"]
        if self.adequate:
            lines.append("The model is adequate: no candidate effect improves the fit "
                         f"significantly (Bonferroni threshold p < {self.threshold:.3g}).")
        else:
            lines.append("The model is NOT adequate.")
        for c in self.ranking:
            mark = "*" if c.significant else ("!" if c.required else " ")
            dl = "n/a" if c.delta_loglik is None else f"{c.delta_loglik:10.2f}"
            da = "n/a" if c.delta_aic is None else f"{c.delta_aic:10.2f}"
            lines.append(f" {mark} {c.effect:<16s} dlogL = {dl}  dAIC = {da}  "
                         f"p = {c.p_value:.3g}  {c.evidence}")
        if any(c.required for c in self.ranking):
            lines.append("(* significant; ! required by the declared detector: not significant "
                         "alone, but it moves k or gamma by more than 2 SE)")
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


@dataclasses.dataclass(frozen=True)
class Selection:
    """Result of :func:`select_model`: the model reached, whether it is adequate, and the
    diagnosis of every step (``steps[0]`` is the starting model)."""

    model: object
    adequate: bool
    steps: tuple[Diagnosis, ...]
    added: tuple[str, ...]
    notes: tuple[str, ...] = ()

    @property
    def fit(self) -> CalibrationResult:
        """Fit of the final model (the last diagnosis's base fit)."""
        return self.steps[-1].fit

    def to_dict(self) -> dict:
        return {"model": self.steps[-1].model, "adequate": self.adequate,
                "added": list(self.added), "notes": list(self.notes),
                "steps": [d.to_dict() for d in self.steps]}

    def summary(self) -> str:
        lines = []
        for i, d in enumerate(self.steps):
            best = d.best
            what = ("adequate" if d.adequate else
                    f"adds {best.effect} (dAIC {best.delta_aic:.1f}, p {best.p_value:.2g})"
                    if best is not None and best.delta_aic is not None else "inadequate")
            lines.append(f"step {i}: {d.model:<40s} gof p = {d.gof['p_value']:.3g}  {what}")
        lines.append(f"final model: {self.steps[-1].model} "
                     f"({'adequate' if self.adequate else 'NOT adequate'})")
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)
