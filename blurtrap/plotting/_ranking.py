"""The ranking of candidate missing effects of a :func:`blurtrap.diagnose` run as a bar chart
that states the Diagnosis's own verdicts."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ._common import new_axes

_SIG_COLOR, _NOT_SIG_COLOR, _NO_VERDICT_COLOR, _IMPLAUSIBLE_COLOR = "C3", "0.6", "C0", "0.85"
AIC_LABEL = ("AIC improvement = AIC_old - AIC_new = AIC(model) - AIC(model + effect)\n"
             "(> 0: adding the effect helps; dimensionless)")


def _ranking_rows(ranking):
    """Rows ``{effect, delta_aic, p_value, significant, plausible}`` and the Diagnosis (or
    None) from a Diagnosis, a sequence of Candidates or a sequence of mappings."""
    diag = ranking if hasattr(ranking, "ranking") and hasattr(ranking, "adequate") else None
    items = diag.ranking if diag is not None else ranking
    rows = []
    for r in items:
        if isinstance(r, Mapping):
            r = dict(r)
            if "effect" not in r or "delta_aic" not in r:
                raise ValueError(f"each ranking entry needs 'effect' and 'delta_aic'; got {r!r}")
        elif hasattr(r, "effect") and hasattr(r, "delta_aic"):
            r = {k: getattr(r, k) for k in ("effect", "delta_aic", "p_value", "significant",
                                               "plausible", "required", "evidence")
                 if hasattr(r, k)}
        else:
            raise ValueError("ranking must be a Diagnosis, a sequence of Candidates or of "
                             f"mappings with 'effect' and 'delta_aic'; got an item {r!r}")
        dA = r["delta_aic"]
        rows.append({"effect": str(r["effect"]),
                     "delta_aic": None if dA is None else float(dA),
                     "p_value": None if r.get("p_value") is None else float(r["p_value"]),
                     "significant": None if r.get("significant") is None
                     else bool(r["significant"]),
                     "plausible": bool(r.get("plausible", True)),
                     "required": bool(r.get("required", False))})
    return rows, diag


def _ranking_key(item):
    i, r = item
    sig = r["significant"] is True or r["required"]  # diagnose's first (the missing effect)
    d = r["delta_aic"]
    if d is None:  # not comparable by AIC: a significant one leads (as in diagnose), else last
        d = math.inf if sig else -math.inf
    return (not sig, not r["plausible"], -d, i)


def _verdict_title(diag, rows):
    if diag is None:
        if any(r["significant"] is not None for r in rows):
            return "missing-effect ranking"
        return ("missing-effect ranking (no verdicts given: pass the Diagnosis for "
                "significance and adequacy)")
    g = diag.gof or {}
    p = g.get("p_value", math.nan)
    head = (f"model {diag.model}: " + ("adequate" if diag.adequate else "NOT adequate")
            + f" (gof p = {p:.3g}; significant: p < {diag.threshold:.3g}, Bonferroni)")
    best = getattr(diag, "best", None)
    if not diag.adequate:
        head += (f"\nmissing effect: {best.effect}" if best is not None else
                 "\nno candidate effect explains the misfit")
    return head


def diagnose_ranking(ranking, *, ax=None, thresholds=None):
    r"""Bar chart of the candidate missing effects of a :func:`blurtrap.diagnose` run.

    The picture states the Diagnosis's own verdicts, computed nowhere else: a bar is red
    when ``diagnose`` found the effect significant (likelihood-ratio p below the Bonferroni
    threshold, AIC improved, physically plausible), grey when not; a physically implausible
    candidate is hatched, labelled ``IMPLAUSIBLE`` and drawn after the plausible ones,
    whatever its AIC; a candidate that is not part of the likelihood (``timing_jitter``:
    ``delta_aic`` is None) is drawn as a hatched band labelled "not comparable by AIC" with
    its p-value. The title gives the adequacy verdict, the goodness-of-fit p-value and the
    threshold, as :meth:`Diagnosis.summary` words them.

    - `ranking`: the :class:`~blurtrap.diagnostics.Diagnosis` (preferred), its ``ranking``
      (Candidates), or a list of dicts (``Candidate.to_dict()``) with keys ``effect`` and
      ``delta_aic`` (``AIC(model) - AIC(model + effect)``, > 0: the effect improves the
      fit; None: not comparable by AIC) and optionally ``p_value``, ``significant`` and
      ``plausible``. Dicts without ``significant`` are drawn blue: no verdict.
    - `thresholds`: optional AIC-improvement levels drawn as dotted guides (they do not
      change the colours).
    - `ax`: draw into an existing axes.

    **Returns:** Figure with one axes (one bar per effect, the Diagnosis's best at the top).
    An empty ranking gives a figure that says that nothing is missing.
    """
    from matplotlib.patches import Patch, Rectangle
    from matplotlib.transforms import blended_transform_factory

    rows, diag = _ranking_rows(ranking)
    rows = [r for _, r in sorted(enumerate(rows), key=_ranking_key)]
    fig, ax = new_axes(figsize=(9.0, 0.45 * max(len(rows), 2) + 1.7), ax=ax)
    ax.set_xlabel(AIC_LABEL, fontsize=8)
    ax.set_title(_verdict_title(diag, rows), fontsize=9)
    if not rows:
        msg = "no candidate effect improves the fit: nothing is missing"
        if diag is not None and not diag.adequate:
            msg = "no candidate effects were tried, and the model is NOT adequate"
        ax.text(0.5, 0.5, msg, ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
        return fig
    n = len(rows)
    ypos = np.arange(n)[::-1]
    band = blended_transform_factory(ax.transAxes, ax.transData)
    kinds = set()
    for y, r in zip(ypos, rows, strict=True):
        sig, v, p = r["significant"], r["delta_aic"], r["p_value"]
        color = (_NO_VERDICT_COLOR if sig is None else _SIG_COLOR if sig else _NOT_SIG_COLOR)
        ptxt = "" if p is None else f"p = {p:.2g}"
        if r["required"]:
            kinds.add("req")
            color = _SIG_COLOR
        elif not r["plausible"]:
            kinds.add("implausible")
            color = _IMPLAUSIBLE_COLOR
        else:
            kinds.add({None: "none", True: "sig", False: "not"}[sig])
        if v is None:
            kinds.add("n/a")
            ax.add_patch(Rectangle((0.0, y - 0.4), 1.0, 0.8, transform=band, facecolor="none",
                                   edgecolor=color if sig else "0.45", hatch="//", lw=1.0,
                                   gid=f"not comparable: {r['effect']}"))
            ax.text(0.5, y, f"not comparable by AIC{', ' + ptxt if ptxt else ''}"
                    + (" (significant)" if sig else ""),
                    transform=band, ha="center", va="center", fontsize=8,
                    bbox=dict(facecolor="white", edgecolor="none", pad=1.0))
            continue
        hatch = ".." if r["required"] else (None if r["plausible"] else "xx")
        ax.barh([y], [v], color=color, hatch=hatch,
                edgecolor="0.3" if not r["plausible"] else color, gid=f"bar: {r['effect']}")
        note = f" {v:.3g}" + (f", {ptxt}" if ptxt else "")
        if not r["plausible"]:
            note += ", IMPLAUSIBLE"
        if r["required"]:
            note += ", required by the declared detector"
        ax.text(max(v, 0.0), y, note, va="center", ha="left", fontsize=8)
    labels = [r["effect"] + ("\n(IMPLAUSIBLE)" if not r["plausible"] else "") for r in rows]
    ax.set_yticks(ypos, labels)
    ax.set_ylim(-0.6, n - 0.4)
    ax.axvline(0.0, color="k", lw=0.8)
    for t in thresholds or ():
        ax.axvline(float(t), color="k", ls=":", lw=0.8)
    vals = [r["delta_aic"] for r in rows if r["delta_aic"] is not None]
    lo, hi = (min(vals + [0.0]), max(vals + [0.0])) if vals else (-1.0, 1.0)
    span = max(hi - lo, 1.0)
    # room for the value labels, written right of each bar's end (of 0 for a negative bar)
    ax.set_xlim(lo - 0.05 * span, hi + 0.4 * span)
    legend = {
        "sig": Patch(facecolor=_SIG_COLOR, label="significant (diagnose's verdict)"),
        "not": Patch(facecolor=_NOT_SIG_COLOR, label="not significant"),
        "req": Patch(facecolor=_SIG_COLOR, hatch="..", edgecolor="0.3",
                     label="required by the declared detector (moves k or gamma > 2 SE)"),
        "none": Patch(facecolor=_NO_VERDICT_COLOR, label="no verdict given"),
        "implausible": Patch(facecolor=_IMPLAUSIBLE_COLOR, hatch="xx", edgecolor="0.3",
                             label="physically implausible: never significant"),
        "n/a": Patch(facecolor="none", hatch="//", edgecolor="0.45",
                     label="not comparable by AIC (outside the likelihood)"),
    }
    ax.legend(handles=[legend[k] for k in ("sig", "req", "not", "none", "implausible", "n/a")
                       if k in kinds], fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              borderaxespad=0.0)
    return fig


__all__ = ["diagnose_ranking"]
