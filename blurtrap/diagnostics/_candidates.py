"""The candidate effects of :func:`diagnose`: the vocabulary, argument checks, the default
candidate list for a model and its data, and how each candidate is tested (a screening refit
with a likelihood-ratio test, or a direct test for effects outside the Gaussian likelihood)."""

from __future__ import annotations

import math

import numpy as np

from ..inference._fit import chi2_sf
from ..inference._result import FitError
from ._evidence import _evidence, _gof_change, _kurtosis_test, _line_candidate, _plausible
from ._results import Candidate
from ._screen import screen

SPECTRAL_CANDIDATES = ("motion_blur", "aliasing", "tracking_noise", "drift", "line_noise",
                       "exposure_kernel", "detector_filter", "hydrodynamics")
RELATION_CANDIDATES = ("power_offset", "laser_heating")
_CORE_FLAGS = ("motion_blur", "aliasing", "tracking_noise")
#: Physically coupled effects tried together when the model lacks all of them: a camera both
#: blurs (exposure average) and samples (folding). From the naive model each alone makes the
#: fit worse (blur removes high-frequency power that only the folded spectrum gives back), so
#: a one-at-a-time search would never find the pair.
COUPLED_GROUPS = {"motion_blur+aliasing": ("motion_blur", "aliasing")}


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


def default_candidates(recs, mdl, k: str, multi_power: bool) -> list[str]:
    """Every applicable effect not in ``mdl``: the spectral ones (detector_filter and
    hydrodynamics only at photodiode rates, >= 10 kHz; exposure_kernel only for a blurred
    model over several exposures), the coupled groups, the power relations (``k =
    "linear_power"`` over >= 3 powers), anharmonicity, and timing_jitter when there are time
    stamps."""
    fs = 1.0 / float(np.median([float(r.frame_interval) for r in recs]))
    fast = fs >= 10_000.0
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
    return candidates


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
              f"{j.max_deviation * 1e6:.3g} us ({len(irregular)} recordings); remedy: "
              "calibrate fits the exact likelihood at the recorded frame times (closed-form "
              "models; see the fit's notes)")
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


def _screen(recs, mdl, k, name: str, config: dict, warm: dict):
    """Screening refit of ``mdl`` + ``name`` (warm start; core effects also from the
    closed-form start, keeping the better optimum). Returns the model and the optimum."""
    test_model = mdl.add(*COUPLED_GROUPS.get(name, (name,)), **config)
    params, nll1, gof1, ok = screen(recs, test_model, k, start=warm)
    if name in _CORE_FLAGS or name in COUPLED_GROUPS:
        # adding a core effect can move k and gamma far from the misspecified base
        # fit: also try the closed-form start and keep the better optimum
        cold = screen(recs, test_model, k, start=None)
        if cold[1] < nll1:
            params, nll1, gof1, ok = cold
    return test_model, params, nll1, gof1, ok


def _likelihood_candidate(recs, mdl, k, base, name: str, warm: dict):
    """Refit with ``name`` added and test it by the likelihood ratio against ``base``.
    Returns the :class:`Candidate` and the screening optimum (``None`` when the refit
    failed)."""
    config = {}
    p_line = None
    if name == "line_noise":
        f0, p_line, r_line = _line_candidate(base)
        T = float(np.median([r.n_frames * float(r.frame_interval) for r in recs]))
        config = {"frequency": f0, "width": 1.0 / T}
    try:
        test_model, params, nll1, gof1, ok = _screen(recs, mdl, k, name, config, warm)
    except (FitError, ValueError) as exc:
        return Candidate(name, None, 0, 1.0, None, f"refit failed: {exc}"), None
    dof = len(params) - len(base.param_names)
    dll = float(base.extras["nll"] - nll1)
    p = _lr_p_value(dll, dof)
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
    return Candidate(name, dll, dof, p, 2.0 * dll - 2.0 * dof, ev, model=test_model,
                     plausible=plausible), params


def try_candidates(recs, mdl, k, base, candidates) -> tuple[list[Candidate], dict]:
    """Test every candidate against the base fit. Returns the candidates (unranked) and each
    screened effect's optimum (the start of the full refit)."""
    out = []
    screened = {}  # candidate -> optimum of its screening fit (start of the full refit)
    # warm start from the base fit, except parameters it pinned at a bound (eps^2 -> 0 when a
    # deficit is missing): in log coordinates they could not move back, so they restart
    # from their closed-form values
    warm = {n: v for n, v in base.params.items() if n not in base.at_bounds}
    for name in candidates:
        if name == "anharmonicity":
            out.append(_anharmonicity_candidate(recs, base))
            continue
        if name == "timing_jitter":
            out.append(_timing_candidate(recs))
            continue
        cand, params = _likelihood_candidate(recs, mdl, k, base, name, warm)
        out.append(cand)
        if params is not None:
            screened[name] = params
    return out, screened
