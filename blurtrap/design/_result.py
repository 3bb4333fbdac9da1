"""The results of :func:`blurtrap.design.design`: a candidate acquisition and the design."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Acquisition:
    """One candidate: recordings as (frame_interval [s], exposure [s], n_frames), the predicted
    relative SEs of k, gamma, eps^2 at each stiffness of the range, and the objective. A power
    series also has ``laser_powers``: each recording's laser power as a multiple of the one k
    is given at (its ``predicted_se["k"]`` is then that of c in k = c P).

    ``predicted_se`` is the expected scatter of the fit's estimates with eps^2 >= 0 enforced
    (below the Cramer-Rao bound where eps^2 often lands on its bound 0, see
    :func:`blurtrap.design.bounded_covariance`); ``unconstrained_se`` is the Cramer-Rao bound
    itself (what calibrate reports as the SE of a fit whose eps^2 sits at the bound), and
    ``bound_probability`` the predicted fraction of fits with eps^2 at 0 per stiffness."""

    label: str
    recordings: tuple
    predicted_se: dict  # name -> relative SE (fraction) at each k of the range
    objective: float
    laser_powers: tuple | None = None
    unconstrained_se: dict = dataclasses.field(default_factory=dict)
    bound_probability: np.ndarray | None = None

    def to_dict(self) -> dict:
        recs = [{"frame_interval_s": r[0], "exposure_s": r[1], "n_frames": r[2]}
                for r in self.recordings]
        for rec, p in zip(recs, self.laser_powers or ()):
            rec["laser_power_relative"] = p
        return {"label": self.label, "objective": self.objective,
                "recordings": recs,
                "predicted_relative_se": {n: [float(x) for x in v]
                                          for n, v in self.predicted_se.items()},
                "cramer_rao_relative_se": {n: [float(x) for x in v]
                                           for n, v in self.unconstrained_se.items()},
                "eps2_at_bound_probability": (None if self.bound_probability is None else
                                              [float(x) for x in self.bound_probability])}


@dataclasses.dataclass(frozen=True)
class DesignResult:
    """Result of :func:`design`: the recommended acquisition (``best``), every candidate
    compared (``candidates``, best first) and the settings used (SI)."""

    best: Acquisition
    candidates: tuple
    target: str
    k: tuple
    settings: dict

    @property
    def predicted_se(self) -> dict:
        """Relative SE of each parameter for the recommended design (worst over the k range)."""
        return {n: float(np.max(v)) for n, v in self.best.predicted_se.items()}

    def plot(self, ax=None):
        """Predicted SE against exposure and frame interval, candidates marked
        (:func:`blurtrap.plotting.design_se`; imports matplotlib). Returns the figure."""
        from ..plotting import design_se

        return design_se(self, ax=ax)

    def to_dict(self) -> dict:
        return {"target": self.target, "k_N_per_m": list(self.k), "settings": self.settings,
                "notes": list(self.notes),
                "best": self.best.to_dict(),
                "candidates": [c.to_dict() for c in self.candidates]}

    @property
    def notes(self) -> tuple[str, ...]:
        """What the predicted SEs assume that ``calibrate`` does not do (photon-limited
        noise across exposures)."""
        exposures = {round(float(r[1]), 15) for r in self.best.recordings}
        if not (self.settings.get("photon_limited") and len(exposures) > 1):
            return ()
        return ("photon-limited: the SEs assume a fit that knows eps^2 = eps_ref^2 W_ref/W across "
                "the recordings (one noise parameter for the whole series). calibrate fits one eps^2 "
                "shared by all recordings, which a photon-limited series violates: its joint fit of "
                "the recommended series is biased, its note refits one eps^2 per recording with "
                "larger errors, and neither reaches these SEs (benchmarks/study_design.py reached "
                "them with a joint likelihood of eps^2 ~ 1/W written there)",)

    def summary(self) -> str:
        extra = self.target not in ("k", "gamma")
        lines = [f"experiment design: minimise the SE of {self.target} (worst case over k = "
                 + ", ".join(f"{k * 1e3:.3g}" for k in self.k) + " pN/nm)",
                 f"  {'candidate':<34s} {'recordings (dt ms / W ms / frames [@ P])':<44s}"
                 f" {'SE k %':>8s} {'SE gamma %':>11s}"
                 + (f" {'SE ' + self.target + ' %':>12s}" if extra else "")]
        for c in self.candidates:
            ps = c.laser_powers or (None,) * len(c.recordings)
            recs = "; ".join(f"{r[0] * 1e3:.3g}/{r[1] * 1e3:.3g}/{int(r[2])}"
                             + ("" if p is None else f"@{p:g}P")
                             for r, p in zip(c.recordings, ps))
            full = recs if len(recs) > 44 and c.laser_powers else ""
            if len(recs) > 44:
                recs = recs[:41] + "..."
            mark = "*" if c is self.best else " "
            sg = np.max(c.predicted_se["gamma"])
            lines.append(f"{mark} {c.label:<34s} {recs:<44s} "
                         f"{100 * np.max(c.predicted_se['k']):8.3g} "
                         + (f"{100 * sg:11.3g}" if sg != 0 else f"{'known':>11s}")
                         + (f" {100 * c.objective:12.3g}" if extra else ""))
            if full:  # a power series: every recording with its power, on its own line
                lines.append(f"      {full}")
        p_bound = float(np.max(self.best.bound_probability)) \
            if self.best.bound_probability is not None else 0.0
        if p_bound > 0.01:
            crb = self.best.unconstrained_se
            lines.append(f"  eps^2 is predicted at its bound 0 in {100 * p_bound:.2g} % of fits "
                         "of the recommended design; the SEs above are the scatter with that "
                         "bound (Cramer-Rao bound without it: k "
                         f"{100 * np.max(crb['k']):.3g} %, gamma "
                         f"{100 * np.max(crb['gamma']):.3g} %)")
        known = self.settings.get("friction_error")
        lines.append("(* recommended; SEs from the Whittle Fisher information with the bound "
                     "eps^2 >= 0, relative, worst over the k range"
                     + ("" if known is None else
                        f"; friction known to {100 * known:.3g} % (SE gamma is that prior)")
                     + ("" if self.settings.get("laser_powers") is None else
                        "; @pP: at p times the laser power k is given at, SE k of a power "
                        "series = SE of c in k = c P, calibrate(k='linear_power')")
                     + ")")
        return "\n".join(lines + [f"note: {n}" for n in self.notes])
