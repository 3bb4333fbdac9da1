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
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._config import float64_scope
from ..inference._calibrate import as_recordings, calibrate, screen_model
from ..inference._fit import chi2_sf
from ..inference._models import get_model
from ..inference._result import CalibrationResult, FitError
from ..physics._effects import water_viscosity

SPECTRAL_CANDIDATES = ("motion_blur", "aliasing", "tracking_noise", "drift", "line_noise",
                       "exposure_kernel", "detector_filter", "hydrodynamics")
RELATION_CANDIDATES = ("power_offset", "laser_heating")
_CORE_FLAGS = ("motion_blur", "aliasing", "tracking_noise")


@dataclasses.dataclass(frozen=True)
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

    def to_dict(self):
        return {"effect": self.effect, "delta_loglik": self.delta_loglik, "dof": self.dof,
                "p_value": self.p_value, "delta_aic": self.delta_aic,
                "significant": self.significant, "plausible": self.plausible,
                "evidence": self.evidence}


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
        return self.ranking[0] if self.ranking and self.ranking[0].significant else None

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
            mark = "*" if c.significant else " "
            dl = "n/a" if c.delta_loglik is None else f"{c.delta_loglik:10.2f}"
            da = "n/a" if c.delta_aic is None else f"{c.delta_aic:10.2f}"
            lines.append(f" {mark} {c.effect:<16s} dlogL = {dl}  dAIC = {da}  "
                         f"p = {c.p_value:.3g}  {c.evidence}")
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------
# residual evidence
# ---------------------------------------------------------------------------------------
def _bands(fit: CalibrationResult):
    f = np.asarray(fit.extras["f"]).ravel()
    ratio = np.asarray(fit.extras["ratio"]).ravel()
    w = np.asarray(fit.extras["weight"]).ravel()
    return f, ratio, w


def _band_ratio(f, ratio, w, lo, hi):
    sel = (f >= lo) & (f <= hi) & (w > 0)
    if not np.any(sel):
        return float("nan"), 0
    return float(np.sum(ratio[sel] * w[sel]) / np.sum(w[sel])), int(np.sum(sel))


def _evidence(effect: str, fit: CalibrationResult, recs) -> str:
    f, ratio, w = _bands(fit)
    fs = 1.0 / float(recs[0].frame_interval)
    fmin = float(np.min(f[w > 0])) if np.any(w > 0) else 0.0
    fc = fit.k / (2 * math.pi * fit.gamma) if np.isfinite(fit.gamma) else fs / 10
    if effect == "drift":
        hi = max(5 * fmin, min(0.05 * fc, 0.01 * fs))
        r, n = _band_ratio(f, ratio, w, 0, hi)
        return f"power below {hi:.3g} Hz is {r:.3g}x the model ({n} ordinates): drift"
    if effect in ("motion_blur", "aliasing", "tracking_noise", "exposure_kernel",
                  "detector_filter", "hydrodynamics"):
        r_hi, n_hi = _band_ratio(f, ratio, w, 0.7 * fs / 2, fs / 2)
        r_mid, _ = _band_ratio(f, ratio, w, 0.2 * fs / 2, 0.5 * fs / 2)
        what = {"motion_blur": "deficit rising toward fs/2 (motion blur)",
                "aliasing": "excess near Nyquist (aliasing)",
                "tracking_noise": "flat excess floor (tracking noise)",
                "exposure_kernel": "high-frequency shape unlike sinc^2 (exposure kernel)",
                "detector_filter": "high-frequency low-pass deficit (detector filter)",
                "hydrodynamics": "high-frequency shape of frequency-dependent friction"}[effect]
        return (f"data/model near Nyquist {r_hi:.3g} ({n_hi} ordinates), at 0.1-0.25 fs "
                f"{r_mid:.3g}: {what}")
    if effect == "line_noise":
        j = int(np.argmax(np.where(w > 0, ratio, 0)))
        return f"isolated spike at {f[j]:.4g} Hz, {ratio[j]:.3g}x the model: line noise"
    if effect == "power_offset":
        return "k-vs-power line does not pass through the origin (k = c (P - P0))"
    if effect == "laser_heating":
        return "gamma falls with laser power (viscosity of heated water)"
    return ""


def _line_candidate(fit: CalibrationResult, half_window: int = 500, guard: int = 2,
                    lowest: int = 10):
    """Most significant isolated spike: periodogram/model ratio divided by its local mean
    over +-``half_window`` ordinates (excluding +-``guard`` around the candidate), so broadband
    misfit (drift, blur) is not mistaken for a line. The ``lowest`` Fourier frequencies
    (f < 10/T) are not searched: a "line" there cannot be told from drift. Under the model each
    ratio is Exp(1); the p-value accounts for the search over all M ordinates:
    1 - (1 - e^-r)^M."""
    f, ratio, w = _bands(fit)
    keep = w > 0
    f, q = f[keep], ratio[keep]
    if q.size > 4 * lowest:
        f, q = f[lowest:], q[lowest:]
    m = q.size
    hw = min(half_window, max(m // 4, 1))
    c = np.concatenate([[0.0], np.cumsum(np.pad(q, hw, mode="reflect"))])
    idx = np.arange(m) + hw
    total = c[idx + hw + 1] - c[idx - hw]
    inner = c[idx + guard + 1] - c[idx - guard]
    local = (total - inner) / (2 * hw - 2 * guard)
    r = q / local
    j = int(np.argmax(r))
    p = float(-np.expm1(m * np.log1p(-math.exp(-min(float(r[j]), 700.0)))))
    return float(f[j]), p, float(r[j])


def _kurtosis_test(recs, fit: CalibrationResult):
    zs = []
    for r in recs:
        y = np.asarray(r.positions, dtype=float)
        y = y - y.mean()
        m2 = float(np.mean(y * y))
        g2 = float(np.mean(y**4)) / m2**2 - 3.0
        # correlated frames: var(g2) ~ (24/N) sum_n r(n)^4 with the empirical autocorrelation
        n = y.size
        spec = np.fft.rfft(y, 2 * n)
        ac = np.fft.irfft(np.abs(spec) ** 2)[: min(n, 2000)] / n / m2
        stop = int(np.argmax(ac <= 0)) if np.any(ac <= 0) else len(ac)
        s4 = 1.0 + 2.0 * float(np.sum(ac[1:max(stop, 1)] ** 4))
        zs.append(g2 / math.sqrt(24.0 * s4 / n))
    z = float(np.sum(zs) / math.sqrt(len(zs)))
    p = float(math.erfc(abs(z) / math.sqrt(2.0)))
    return z, p


# Largest fitted hydrodynamic radius accepted, relative to the Stokes radius gamma/(6 pi eta):
# Faxen's law only raises gamma above 6 pi eta R, so R <= gamma/(6 pi eta); the margin covers
# the scatter of R in a weakly informative fit.
HYDRO_RADIUS_MARGIN = 1.5
DIODE_ALPHA_MAX = 1.05


def _plausible(name: str, params: dict, recs) -> tuple[bool, str]:
    """Physical consistency of a candidate's refit. ``hydrodynamics``: the fitted radius must
    not exceed the Stokes radius implied by the fitted gamma (near a wall gamma only grows,
    Faxen), else the high-frequency shape it absorbs is something else (on photodiode-filter
    data the hydrodynamic fit wants R ~ 3 x the Stokes radius). ``detector_filter``: the
    instantaneous fraction alpha cannot exceed 1 (no gain above the DC response)."""
    if name == "hydrodynamics":
        temp = float(np.median([float(r.temperature) for r in recs]))
        r_stokes = params["gamma"] / (6.0 * math.pi * float(water_viscosity(temp)))
        r_fit = params["hydro_radius"]
        if r_fit > HYDRO_RADIUS_MARGIN * r_stokes:
            return False, (f"fitted radius {r_fit * 1e6:.3g} um exceeds the Stokes radius "
                           f"{r_stokes * 1e6:.3g} um implied by gamma (gamma >= 6 pi eta R)")
    if name == "detector_filter" and params["diode_alpha"] > DIODE_ALPHA_MAX:
        return False, f"instantaneous fraction alpha = {params['diode_alpha']:.3g} > 1"
    return True, ""


@float64_scope
def diagnose(data, model=None, *, candidates=None, alpha: float = 0.05, k: str | None = None,
             add=()) -> Diagnosis:
    """Fit ``model`` (default ``standard``), test it, and rank missing effects.

    **Arguments:**

    - `data`: Recording, RecordingSet, list of recordings or manifest path.
    - `model`: ``"naive"``, ``"blur"``, ``"standard"`` (default), a ``TrapModel`` or
      ``"standard+drift"``; `add`: effect names added to it first.
    - `candidates`: effect names to try (default: every applicable one not in the model).
    - `alpha`: family-wise false-alarm rate (Bonferroni over the GOF test and candidates).
    - `k`: stiffness sharing (default ``linear_power`` for >= 3 laser powers, so that
      power_offset / laser_heating are testable).

    **Returns:** :class:`Diagnosis` (``adequate``, ``gof``, ``ranking`` best first).
    """
    recs = as_recordings(data)
    mdl = get_model(model)
    if add:
        mdl = mdl.add(*add)
    powers = {float(r.laser_power) for r in recs if r.laser_power is not None}
    multi_power = len(powers) >= 3 and all(r.laser_power is not None for r in recs)
    if k is None:
        k = "linear_power" if multi_power else ("shared" if len(powers) <= 1 else "per_power")
    notes = []
    base = calibrate(recs, method="likelihood", likelihood="whittle", model=mdl, k=k,
                     strict=False)
    if not all(np.isfinite(e) for n, e in zip(base.param_names, base.errors)
               if n not in base.at_bounds):
        notes.append("the base model's Fisher information is singular (a parameter is pinned "
                     "at its bound): its standard errors are undefined, a sign of misfit")
    fs = 1.0 / float(np.median([float(r.frame_interval) for r in recs]))
    fast = fs >= 10_000.0
    if candidates is None:
        candidates = [c for c in SPECTRAL_CANDIDATES if not mdl.has(c)]
        if not fast:
            candidates = [c for c in candidates if c not in ("detector_filter", "hydrodynamics")]
        if not mdl.blur or len({float(r.exposure) for r in recs}) < 2:
            # one exposure: the kernel shape is absorbed by k, gamma, eps^2 (exact ARMA(1,1))
            candidates = [c for c in candidates if c != "exposure_kernel"]
        if multi_power and k == "linear_power":
            candidates += [c for c in RELATION_CANDIDATES if not mdl.has(c)]
        candidates += ["anharmonicity"]
        if any(r.times is not None for r in recs):
            candidates += ["timing_jitter"]
    m = len(candidates) + 1
    threshold = alpha / m
    out = []
    screened = {}  # candidate -> optimum of its screening fit (start of the full refit)
    # warm start from the base fit, except parameters it pinned at a bound (eps^2 -> 0 when a
    # deficit is missing): in log coordinates they could not move back, so they restart
    # from their closed-form values
    warm = {n: v for n, v in base.params.items() if n not in base.at_bounds}
    nll0 = base.extras["nll"]
    for name in candidates:
        if name == "anharmonicity":
            z, p = _kurtosis_test(recs, base)
            out.append(Candidate(name, 0.5 * z * z, 1, p, z * z - 2.0,
                                 f"frame-histogram excess kurtosis {z:+.2f} standard errors "
                                 "from Gaussian"))
            continue
        if name == "timing_jitter":
            irregular = [r for r in recs if r.times is not None and not r.is_regular]
            if irregular:
                j = irregular[0].timing_jitter
                ev = (f"time stamps irregular: jitter std {j.std * 1e6:.3g} us, max "
                      f"{j.max_deviation * 1e6:.3g} us ({len(irregular)} recordings)")
                out.append(Candidate(name, None, 0, 0.0, None, ev))
            else:
                out.append(Candidate(name, None, 0, 1.0, None, "time stamps regular"))
            continue
        config = {}
        p_line = None
        if name == "line_noise":
            f0, p_line, r_line = _line_candidate(base)
            T = float(np.median([r.n_frames * float(r.frame_interval) for r in recs]))
            config = {"frequency": f0, "width": 1.0 / T}
        try:
            test_model = mdl.add(name, **config)
            params, nll1, gof1, ok = screen_model(recs, test_model, k, start=warm)
            if name in _CORE_FLAGS:
                # adding a core effect can move k and gamma far from the misspecified base
                # fit: also try the closed-form start and keep the better optimum
                cold = screen_model(recs, test_model, k, start=None)
                if cold[1] < nll1:
                    params, nll1, gof1, ok = cold
        except (FitError, ValueError) as exc:
            out.append(Candidate(name, None, 0, 1.0, None, f"refit failed: {exc}"))
            continue
        screened[name] = params
        dof = len(params) - len(base.param_names)
        dll = float(nll0 - nll1)
        lr = max(2.0 * dll, 0.0)
        # Flag effects (motion_blur, aliasing) add no free parameter: they fix the strength
        # of a nested family (e.g. W_eff = beta W at beta = 1), whose free-beta likelihood is
        # at least as high, so referring the LR to the 1-parameter law is conservative.
        dof_test = max(dof, 1)
        p = float(chi2_sf(lr, dof_test))
        if dof_test == 1:
            p = 0.5 * p  # null on the boundary (parameter = 0): 1/2 chi2_0 + 1/2 chi2_1
        ev = _evidence(name, base, recs)
        if p_line is not None:
            # the frequency was searched over all ordinates: use the max-statistic p-value
            p = max(p, p_line)
            ev = (f"isolated spike at {config['frequency']:.4g} Hz, {r_line:.3g}x the local "
                  "spectrum: line noise")
        if not ok:
            ev += " (refit did not converge)"
        ev += f"; adding it: gof p {base.gof['p_value']:.2g} -> {gof1['p_value']:.2g}"
        plausible, why = _plausible(name, params, recs)
        if not plausible:
            ev += f"; IMPLAUSIBLE: {why}"
        out.append(Candidate(name, dll, dof, p, 2.0 * dll - 2.0 * dof, ev, model=test_model,
                             plausible=plausible))
    ranked = []
    for c in out:
        sig = (bool(c.p_value < threshold) and (c.delta_aic is None or c.delta_aic > 0)
               and c.plausible)
        ranked.append(dataclasses.replace(c, significant=sig))
    ranked.sort(key=lambda c: (not c.significant,
                               -(c.delta_aic if c.delta_aic is not None else
                                 (1e300 if c.significant else -1e300)),
                               c.p_value))
    if ranked and ranked[0].significant and ranked[0].model is not None:
        top = ranked[0]  # full fit (with errors) of the best candidate
        # from the screening optimum; if that fails (a parameter near its bound 0 cannot
        # converge in log coordinates), from the closed-form start
        for start in (screened.get(top.effect), None):
            try:
                best_fit = calibrate(recs, method="likelihood", likelihood="whittle",
                                     model=top.model, k=k, start=start, strict=False)
                ranked[0] = dataclasses.replace(top, fit=best_fit)
                break
            except (FitError, ValueError) as exc:
                if start is None:
                    notes.append(f"full refit with {top.effect} failed: {exc}")
    gof_ok = base.gof["p_value"] >= threshold
    adequate = gof_ok and not any(c.significant for c in ranked)
    if not gof_ok and not any(c.significant for c in ranked):
        notes.append("the goodness of fit fails but no candidate effect explains it: look at "
                     "the residuals (an effect outside the vocabulary, or a wrong exposure / "
                     "frame interval)")
    if adequate:
        notes.append("nothing is missing: the model describes the data within its errors")
    return Diagnosis(model=mdl.name, fit=base, gof=base.gof, adequate=adequate,
                     ranking=tuple(ranked), threshold=threshold, notes=tuple(notes))


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
            candidates = [c for c in candidates if c != best.effect]
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
