"""The candidate effects of :func:`diagnose`: argument checks, the default candidate list for a
model and its data, and how each candidate is tested (a screening refit with a likelihood-ratio
test, or a direct test for effects outside the Gaussian likelihood).

What a candidate is and how it is tested comes from the effect classes themselves
(:data:`blurtrap.effects.EFFECTS`): ``applies`` (does it apply to these recordings and this
model), ``diagnose_test`` (``"likelihood"``, ``"line"``, ``"kurtosis"``, ``"timestamps"``) and
``order``. Only the coupled groups, which concern pairs of effects, are listed here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..effects import EFFECTS, AbstractEffect, DataContext, make_effect
from ..inference import FitError
from ..inference.internal import chi2_sf, volts_power
from ._evidence import _evidence, _gof_change, _kurtosis_test, _line_candidate, _plausible
from ._results import Candidate
from ._screen import screen

#: Physically coupled effects tried together when the model lacks all of them: a camera both
#: blurs (exposure average) and samples (folding). From the naive model each alone makes the
#: fit worse (blur removes high-frequency power that only the folded spectrum gives back), so
#: a one-at-a-time search would never find the pair. Value: (members, place in the default
#: list, in the effects' ``order``). A real camera also has a tracking-error floor, nearly
#: degenerate with the blur at W = dt: from ``naive`` the pair alone then lands ~20 SE off the
#: other way (measured: benchmarks/RESULTS_diagnose.md section 6, eps = 2 nm), so the camera's
#: whole core (the ``standard`` model) is a group too.
COUPLED_GROUPS = {"motion_blur+aliasing": (("motion_blur", "aliasing"), 85.0),
                  "motion_blur+aliasing+tracking_noise":
                      (("motion_blur", "aliasing", "tracking_noise"), 85.5)}


def valid_candidates() -> tuple[str, ...]:
    """Every name ``candidates`` may hold: the registered effects and the coupled groups."""
    return tuple(n for n, c in EFFECTS.items() if c.diagnose_test) + tuple(COUPLED_GROUPS)


def candidate_name(c) -> str:
    """The name of a candidate (a name or an effect object)."""
    return c.name if isinstance(c, AbstractEffect) else c


def _check_alpha(alpha) -> float:
    ok = isinstance(alpha, (int, float, np.integer, np.floating)) and not isinstance(
        alpha, (bool, np.bool_))
    a = float(alpha) if ok else math.nan
    if not (math.isfinite(a) and 0.0 < a < 1.0):
        raise ValueError(f"alpha (family-wise false-alarm rate) must be a number in (0, 1), "
                         f"e.g. 0.05; got alpha = {alpha!r}")
    return a


def _check_candidates(candidates):
    """A list of unique candidates: canonical names (or coupled groups) and effect objects
    (an effect class counts as its name)."""
    if candidates is None:
        return None
    if isinstance(candidates, (str, AbstractEffect)) or (
            isinstance(candidates, type) and issubclass(candidates, AbstractEffect)):
        candidates = [candidates]
    valid = valid_candidates()
    try:
        items = list(candidates)  # pyright: ignore[reportArgumentType]  # checked here
    except TypeError:
        raise ValueError(f"candidates must be a list of effect names from {list(valid)} or "
                         f"effect objects; got {candidates!r}") from None
    items = [c.name if isinstance(c, type) and issubclass(c, AbstractEffect) else c
             for c in items]
    bad = [c for c in items if (c not in valid if isinstance(c, str)
                                else not (isinstance(c, AbstractEffect) and c.diagnose_test
                                          and c.name in valid))]
    if bad:
        raise ValueError(f"candidates: unknown effect name(s) or object(s) {bad}; valid names "
                         f"are {list(valid)}, or effect objects from blurtrap.effects")
    out: dict = {}
    for c in items:
        out.setdefault(candidate_name(c), c)
    return list(out.values())


def data_context(recs, mdl, k: str, multi_power: bool) -> DataContext:
    """What the effects' ``applies`` hooks see of the recordings and the model."""
    return DataContext(
        sampling_rate=1.0 / float(np.median([float(r.frame_interval) for r in recs])),
        n_exposures=len({float(r.exposure) for r in recs}), blurred=bool(mdl.blur), k_mode=k,
        multi_power=multi_power, has_times=any(r.times is not None for r in recs))


def default_candidates(recs, mdl, k: str, multi_power: bool) -> list[str]:
    """Every effect not in ``mdl`` that ``applies`` to the data (its class's hook: e.g.
    detector_filter and hydrodynamics only at photodiode rates, exposure_kernel only for a
    blurred model over several exposures, the power relations for ``k = "linear_power"`` over
    >= 3 powers, timing_jitter with time stamps), plus the coupled groups none of whose members
    is in the model, in the effects' ``order``."""
    ctx = data_context(recs, mdl, k, multi_power)
    entries = [(cls.order, name) for name, cls in EFFECTS.items()
               if cls.diagnose_test and not mdl.has(name) and cls.applies(ctx)]
    entries += [(order, g) for g, (members, order) in COUPLED_GROUPS.items()
                if not any(mdl.has(e) for e in members)]
    return [name for _, name in sorted(entries, key=lambda e: e[0])]


def _anharmonicity_candidate(recs, base) -> Candidate:
    """Tested by the frames' excess kurtosis; ``delta_loglik`` is the score-test ``z^2/2``."""
    z, p = _kurtosis_test(recs, base)
    return Candidate("anharmonicity", 0.5 * z * z, 1, p, z * z - 2.0,
                     f"frame-histogram excess kurtosis {z:+.2f} standard errors from Gaussian; "
                     "remedy: the Gaussian models cannot absorb a quartic term: refit with "
                     "bt.calibrate_anharmonic(recording) (k, k4, gamma, eps^2 from exact "
                     "moments of the blurred frames)")


def _timing_candidate(recs) -> Candidate:
    """Tested from the time stamps: irregular stamps are the evidence (p = 0)."""
    irregular = [r for r in recs if r.times is not None and not r.is_regular]
    if irregular:
        j = irregular[0].timing_jitter
        ev = (f"time stamps irregular: jitter std {j.std * 1e6:.3g} us, max "
              f"{j.max_deviation * 1e6:.3g} us ({len(irregular)} recordings); remedy: the "
              "exact likelihood at the recorded frame times, which calibrate(data) fits by "
              "default for the closed-form models (see its notes; this screen's base fit "
              "treats the frames as regular)")
        return Candidate("timing_jitter", None, 0, 0.0, None, ev)
    return Candidate("timing_jitter", None, 0, 1.0, None, "time stamps regular")


def _lr_p_value(dll: float, dof: int) -> float:
    """Likelihood-ratio p-value of a nested effect (boundary-corrected for one parameter)."""
    lr = max(2.0 * dll, 0.0)
    # Flag effects (motion_blur, aliasing) add no free parameter: they fix the strength
    # of a nested family (e.g. W_eff = beta W at beta = 1), whose free-beta likelihood is
    # at least as high, so referring the LR to the 1-parameter law is conservative.
    dof_test = max(dof, 1)
    p = float(chi2_sf(lr, dof_test))
    if dof_test == 1:
        p = 0.5 * p  # null on the boundary (parameter = 0): 1/2 chi2_0 + 1/2 chi2_1
    return p


def _screen(inputs, mdl, k, name: str, effects: tuple, warm: dict, base_nll: float):
    """Screening refit of ``mdl`` + ``effects`` (warm start; flag effects, which can move k
    and gamma far, also from the closed-form start, keeping the better optimum; so does a
    warm refit that did not converge or ended above the base fit ``base_nll``, which a
    nested model cannot: a poor start, e.g. a held friction's value on positions in volts).
    Returns the model and the optimum."""
    test_model = mdl.add(*effects)
    params, nll1, gof1, ok = screen(inputs, test_model, k, start=warm)
    stuck = not ok or nll1 > base_nll + 1e-9 * (1.0 + abs(base_nll))
    if stuck or name in COUPLED_GROUPS or EFFECTS[name].kind == "flag":
        # adding a core effect can move k and gamma far from the misspecified base
        # fit: also try the closed-form start and keep the better optimum
        cold = screen(inputs, test_model, k, start=None)
        if cold[1] < nll1:
            params, nll1, gof1, ok = cold
    return test_model, params, nll1, gof1, ok


def _candidate_effects(recs, base, name: str, effect):
    """The effect objects to add for candidate ``name`` (given as ``effect``, an object, or
    by name) and, for a ``"line"`` test, the searched line ``(frequency, p, ratio)``."""
    if name in COUPLED_GROUPS:
        return tuple(COUPLED_GROUPS[name][0]), None
    eff = effect if isinstance(effect, AbstractEffect) else make_effect(name)
    if EFFECTS[name].diagnose_test != "line":
        return (eff,), None
    f0, p_line, r_line = _line_candidate(base)
    T = float(np.median([r.n_frames * float(r.frame_interval) for r in recs]))
    return (dataclasses.replace(eff, frequency=f0, width=1.0 / T),), (f0, p_line, r_line)


def _object_start(warm: dict, effects: tuple) -> dict:
    """The warm start with the candidate objects' own positive scalar values."""
    start = dict(warm)
    for e in effects:
        if isinstance(e, AbstractEffect):
            names = {p.name for p in e.params}
            start.update({n: float(v) for n, v in e.values().items()
                          if n in names and np.ndim(v) == 0 and v > 0})
    return start


def _likelihood_candidate(recs, mdl, k, base, name: str, warm: dict, effect=None):
    """Refit with ``name`` (or the object ``effect``) added and test it by the likelihood
    ratio against ``base``. Returns the :class:`Candidate` and the screening optimum
    (``None`` when the refit failed)."""
    effects, line = _candidate_effects(recs, base, name, effect)
    try:
        test_model, params, nll1, gof1, ok = _screen(base.inputs, mdl, k, name, effects,
                                                     _object_start(warm, effects),
                                                     float(base.extras["nll"]))
    except (FitError, ValueError) as exc:
        return Candidate(name, None, 0, 1.0, None, f"refit failed: {exc}"), None
    dof = len(params) - len(base.param_names)
    dll = float(base.extras["nll"] - nll1)
    p = _lr_p_value(dll, dof)
    ev = _evidence(name, base, recs)
    if line is not None:
        # the frequency was searched over all ordinates: use the max-statistic p-value
        p = max(p, line[1])
        ev = (f"isolated spike at {line[0]:.4g} Hz, {line[2]:.3g}x the local "
              "spectrum: line noise")
    if not ok:
        ev += " (refit did not converge)"
    ev += _gof_change(base.gof, gof1)
    plausible, why = _plausible(name, params, recs)
    if not plausible:
        ev += f"; IMPLAUSIBLE: {why}"
    return Candidate(name, dll, dof, p, 2.0 * dll - 2.0 * dof, ev, model=test_model,
                     plausible=plausible), params


_DIRECT_TESTS = {"kurtosis": lambda recs, base: _anharmonicity_candidate(recs, base),
                 "timestamps": lambda recs, base: _timing_candidate(recs)}


def try_candidates(recs, mdl, k, base, candidates) -> tuple[list[Candidate], dict]:
    """Test every candidate (a name or an effect object) against the base fit, each the way
    its class says (``diagnose_test``). Returns the candidates (unranked) and each screened
    effect's optimum (the start of the full refit)."""
    out = []
    screened = {}  # candidate -> optimum of its screening fit (start of the full refit)
    # warm start from the base fit, except parameters it pinned at a bound (eps^2 -> 0 when a
    # deficit is missing): in log coordinates they could not move back, so they restart
    # from their closed-form values
    to_fit, to_si = _fit_units(base)
    warm = to_fit({n: v for n, v in base.params.items() if n not in base.at_bounds})
    for c in candidates:
        name = candidate_name(c)
        test = "likelihood" if name in COUPLED_GROUPS else EFFECTS[name].diagnose_test
        if test in _DIRECT_TESTS:
            out.append(_DIRECT_TESTS[test](recs, base))
            continue
        cand, params = _likelihood_candidate(recs, mdl, k, base, name, warm, c)
        out.append(cand)
        if params is not None:
            screened[name] = to_si(params)
    return out, screened


def _fit_units(base):
    """``(to_fit, to_si)``: a parameter dict from the base result's units (SI) into those of
    the screening fits, and back. Positions in volts are fitted in volts (k and gamma in
    N/m and N s/m per (m/V)^2, eps^2 in V^2, ...) and reported in SI through the fitted
    displacement sensitivity Rd; comparing the two (warm starts, "moves k by ... SE") mixed
    them (an independent pass: 'adding detector_filter moves k by -12 SE' on correct data).
    The screening optima are carried to SI with the base fit's Rd."""
    rd = base.params.get("displacement_sensitivity")
    if rd is None or not (np.isfinite(rd) and rd > 0):
        return dict, dict

    def scaled(p, sign):
        return {n: v * rd ** (sign * volts_power(n)) for n, v in p.items()
                if n not in ("displacement_sensitivity", "force_sensitivity")}

    return (lambda p: scaled(p, -1)), (lambda p: scaled(p, 1))
