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
from ..inference._calibrate import _inspect_frames, as_recordings, calibrate, screen_model
from ..inference._fit import chi2_sf
from ..inference._models import get_model
from ..inference._result import CalibrationResult, FitError
from ..physics._effects import water_viscosity

SPECTRAL_CANDIDATES = ("motion_blur", "aliasing", "tracking_noise", "drift", "line_noise",
                       "exposure_kernel", "detector_filter", "hydrodynamics")
RELATION_CANDIDATES = ("power_offset", "laser_heating")
_CORE_FLAGS = ("motion_blur", "aliasing", "tracking_noise")
#: Physically coupled effects tried together when the model lacks all of them: a camera both
#: blurs (exposure average) and samples (folding). From the naive model each alone makes the
#: fit worse (blur removes high-frequency power that only the folded spectrum gives back), so
#: a one-at-a-time search would never find the pair.
COUPLED_GROUPS = {"motion_blur+aliasing": ("motion_blur", "aliasing")}


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

    def __repr__(self) -> str:
        da = "n/a" if self.delta_aic is None else f"{self.delta_aic:.2f}"
        flags = ("significant" if self.significant else "not significant") + (
            "" if self.plausible else ", IMPLAUSIBLE")
        return (f"Candidate({self.effect!r}, dAIC = {da}, p = {self.p_value:.3g}, {flags}: "
                f"{self.evidence})")

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


def _signature(ratio: float, n: int, excess: bool) -> bool:
    """Does a band's data/model ratio show an excess (or deficit) beyond its noise? Each
    ordinate's ratio has SD ~1 under the model, so a band mean of n ordinates has SD
    ~1/sqrt(n); 2 SD is the bar for naming an effect in words."""
    if not np.isfinite(ratio) or n == 0:
        return False
    dev = ratio - 1.0 if excess else 1.0 - ratio
    return dev > 2.0 / math.sqrt(n)


# effect -> (what its signature is, True for an excess / False for a deficit near Nyquist)
_HIGH_F = {"motion_blur": ("deficit rising toward fs/2 (motion blur)", False),
           "aliasing": ("excess near Nyquist (aliasing)", True),
           "motion_blur+aliasing": ("high-frequency shape of a camera's blur and folding", None),
           "tracking_noise": ("flat excess floor (tracking noise)", True),
           "exposure_kernel": ("high-frequency shape unlike sinc^2 (exposure kernel)", None),
           "detector_filter": ("high-frequency low-pass deficit (detector filter)", False),
           "hydrodynamics": ("high-frequency shape of frequency-dependent friction", None)}


def _evidence(effect: str, fit: CalibrationResult, recs) -> str:
    """The residual evidence for ``effect`` in words. The effect is named as the cause only
    when the band ratio deviates in its direction by more than 2 SD; otherwise the words say
    that its signature is absent (the likelihood test may still favour it)."""
    f, ratio, w = _bands(fit)
    fs = 1.0 / float(recs[0].frame_interval)
    fmin = float(np.min(f[w > 0])) if np.any(w > 0) else 0.0
    fc = fit.k / (2 * math.pi * fit.gamma) if np.isfinite(fit.gamma) else fs / 10
    if effect == "drift":
        hi = max(5 * fmin, min(0.05 * fc, 0.01 * fs))
        r, n = _band_ratio(f, ratio, w, 0, hi)
        verdict = ("excess at the lowest frequencies: drift" if _signature(r, n, True)
                   else "no low-frequency excess (not the signature of drift)")
        return f"power below {hi:.3g} Hz is {r:.3g}x the model ({n} ordinates): {verdict}"
    if effect in _HIGH_F:
        r_hi, n_hi = _band_ratio(f, ratio, w, 0.7 * fs / 2, fs / 2)
        r_mid, n_mid = _band_ratio(f, ratio, w, 0.2 * fs / 2, 0.5 * fs / 2)
        what, excess = _HIGH_F[effect]
        if excess is None:  # a shape: any significant high- or mid-band misfit
            seen = (_signature(r_hi, n_hi, True) or _signature(r_hi, n_hi, False)
                    or _signature(r_mid, n_mid, True) or _signature(r_mid, n_mid, False))
        else:
            seen = _signature(r_hi, n_hi, excess)
        verdict = what if seen else f"within noise of the model (no {what.split(' (')[0]})"
        return (f"data/model near Nyquist {r_hi:.3g} ({n_hi} ordinates), at 0.1-0.25 fs "
                f"{r_mid:.3g}: {verdict}")
    if effect == "line_noise":
        j = int(np.argmax(np.where(w > 0, ratio, 0)))
        return f"isolated spike at {f[j]:.4g} Hz, {ratio[j]:.3g}x the model: line noise"
    if effect == "power_offset":
        return "k-vs-power line does not pass through the origin (k = c (P - P0))"
    if effect == "laser_heating":
        return "gamma falls with laser power (viscosity of heated water)"
    return ""


_ADDING = "; adding it: gof p "


def _gof_change(before: dict, after: dict) -> str:
    return f"{_ADDING}{before['p_value']:.2g} -> {after['p_value']:.2g}"


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


#: A candidate that is not significant but moves k or gamma by more than this many of the base
#: fit's standard errors makes the base fit's errors dishonest: the data cannot tell the two
#: models apart, yet the answer depends on the choice (e.g. tracking noise on a W = dt camera
#: recording: blur + aliasing without noise fits as well, with k 14 SE low).
SENSITIVITY_SE = 2.0


def _sensitivity_notes(base: CalibrationResult, ranked, screened) -> list[str]:
    out = []
    errs = dict(zip(base.param_names, base.errors))
    for c in ranked:
        params = screened.get(c.effect)
        if c.significant or params is None or not c.plausible:
            continue
        shifts = []
        for name, v0 in base.params.items():
            if not (name == "gamma" or name == "k" or name.startswith("k[")) or name not in params:
                continue
            e = errs[name]
            if np.isfinite(e) and e > 0 and abs(params[name] - v0) > SENSITIVITY_SE * e:
                shifts.append(f"{name} by {(params[name] - v0) / e:+.1f} SE")
        if shifts:
            out.append(f"{c.effect} is not significant, but adding it moves {', '.join(shifts)}: "
                       "the data cannot tell the two models apart and the result depends on the "
                       f"choice; prefer the physically complete model (add {c.effect} if the "
                       "instrument has it) and quote its larger errors")
    return out


#: every name ``candidates`` may hold
VALID_CANDIDATES = SPECTRAL_CANDIDATES + RELATION_CANDIDATES + ("anharmonicity",
                                                                 "timing_jitter") + tuple(COUPLED_GROUPS)


def _check_alpha(alpha) -> float:
    ok = isinstance(alpha, (int, float, np.integer, np.floating)) and not isinstance(
        alpha, (bool, np.bool_))
    a = float(alpha) if ok else math.nan
    if not (math.isfinite(a) and 0.0 < a < 1.0):
        raise ValueError(f"alpha (family-wise false-alarm rate) must be a number in (0, 1), "
                         f"e.g. 0.05; got alpha = {alpha!r}")
    return a


def _check_candidates(candidates):
    if candidates is None:
        return None
    if isinstance(candidates, str):
        candidates = [candidates]
    try:
        names = list(candidates)
    except TypeError:
        raise ValueError(f"candidates must be a list of effect names from "
                         f"{list(VALID_CANDIDATES)}; got {candidates!r}") from None
    bad = [c for c in names if c not in VALID_CANDIDATES]
    if bad:
        raise ValueError(f"candidates: unknown effect name(s) {bad}; valid names are "
                         f"{list(VALID_CANDIDATES)}")
    return list(dict.fromkeys(names))


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

    **Raises:** ``ValueError`` for an ``alpha`` outside (0, 1), an unknown candidate name,
    or saturated or coarsely quantised frames (checked before any fit).
    """
    alpha = _check_alpha(alpha)
    candidates = _check_candidates(candidates)
    recs = as_recordings(data)
    # saturated or coarsely quantised frames: refused here as by calibrate (the base fit
    # runs with strict=False, which would only note them)
    _inspect_frames(recs, strict=True)
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
        candidates += [g for g, members in COUPLED_GROUPS.items()
                       if not any(mdl.has(e) for e in members)]
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
            test_model = mdl.add(*COUPLED_GROUPS.get(name, (name,)), **config)
            params, nll1, gof1, ok = screen_model(recs, test_model, k, start=warm)
            if name in _CORE_FLAGS or name in COUPLED_GROUPS:
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
        ev += _gof_change(base.gof, gof1)
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
                # the evidence quotes the goodness of fit of the fit it carries
                ev = top.evidence.split(_ADDING)[0] + _gof_change(base.gof, best_fit.gof)
                ranked[0] = dataclasses.replace(top, fit=best_fit, evidence=ev)
                break
            except (FitError, ValueError) as exc:
                if start is None:
                    notes.append(f"full refit with {top.effect} failed: {exc}")
    notes += _sensitivity_notes(base, ranked, screened)
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
            candidates = [c for c in candidates if c != best.effect]
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
