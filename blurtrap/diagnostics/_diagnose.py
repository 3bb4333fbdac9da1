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

    def to_dict(self):
        return {"effect": self.effect, "delta_loglik": self.delta_loglik, "dof": self.dof,
                "p_value": self.p_value, "delta_aic": self.delta_aic,
                "significant": self.significant, "evidence": self.evidence}


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
    if not np.all(np.isfinite(base.errors)):
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
            params, nll1, gof1, ok = screen_model(recs, test_model, k, start=base.params)
            if name in _CORE_FLAGS:
                # adding a core effect can move k and gamma far from the misspecified base
                # fit: also try the closed-form start and keep the better optimum
                cold = screen_model(recs, test_model, k, start=None)
                if cold[1] < nll1:
                    params, nll1, gof1, ok = cold
        except (FitError, ValueError) as exc:
            out.append(Candidate(name, None, 0, 1.0, None, f"refit failed: {exc}"))
            continue
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
        out.append(Candidate(name, dll, dof, p, 2.0 * dll - 2.0 * dof, ev))
    ranked = []
    for c in out:
        sig = bool(c.p_value < threshold) and (c.delta_aic is None or c.delta_aic > 0)
        ranked.append(dataclasses.replace(c, significant=sig))
    ranked.sort(key=lambda c: (not c.significant,
                               -(c.delta_aic if c.delta_aic is not None else
                                 (1e300 if c.significant else -1e300)),
                               c.p_value))
    if ranked and ranked[0].significant:  # full fit (with errors) of the best candidate
        top = ranked[0]
        cfg = {}
        if top.effect == "line_noise":
            f0, _, _ = _line_candidate(base)
            T = float(np.median([r.n_frames * float(r.frame_interval) for r in recs]))
            cfg = {"frequency": f0, "width": 1.0 / T}
        try:
            start = None if top.effect in _CORE_FLAGS else base.params
            best_fit = calibrate(recs, method="likelihood", likelihood="whittle",
                                 model=mdl.add(top.effect, **cfg), k=k, start=start,
                                 strict=False)
            ranked[0] = dataclasses.replace(top, fit=best_fit)
        except (FitError, ValueError) as exc:
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


def compare(fit_a: CalibrationResult, fit_b: CalibrationResult) -> dict:
    """Compare two fits of the same data (same method): goodness of fit, the log-likelihood
    gain and ``delta_aic = AIC(a) - AIC(b)`` (> 0: b is better), and the shift of each shared
    parameter in units of fit_a's standard error."""
    out = {"gof_a": dict(fit_a.gof), "gof_b": dict(fit_b.gof)}
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
