r"""Posterior sampling of trap parameters with emcee's affine-invariant ensemble sampler.

The log-posterior is **one** jitted, vmapped JAX function over walkers,

``log post(theta) = log L(p) + sum_i log prior_i(p_i) + sum_i theta_i``,  ``p = exp(theta)``,

evaluated in ``theta = log p`` (log k, log gamma, log eps^2, ...; the last term is the Jacobian
of the log transform, so a prior written as a density in ``p`` means exactly that: the
default log-uniform prior is uniform in ``theta``). The likelihood is the Whittle likelihood
of the periodogram (``likelihood="whittle"``, the default) or the exact O(N) ARMA likelihood
(``"exact"``) of :mod:`blurtrap.inference._problems`; parameters follow the recordings'
:class:`Layout` (``layout.names``), so joint sets with shared gamma / eps^2 and k per power
or ``k = c P`` work unchanged, and so do models with extra effects.

For closed-form models the Whittle likelihood is evaluated without a pass over the
periodogram (:class:`_RationalWhittleArgs`: exact closed-form log sums and a 64-lag sum of
data statistics computed once), ~10-30x faster per walker than the per-ordinate form; models
with additive or transfer effects, an ``f_range``, or records that are short compared with
tau (where ``calibrate``'s expected-periodogram Whittle differs from P_d by more than a few %
of a standard error) use the per-ordinate form of ``calibrate``.

NaN is mapped to ``-inf`` inside JAX and the host receives a float64 NumPy vector (emcee's
``vectorize=True``). emcee's red-blue stretch move evaluates half ensembles, so exactly two
batch shapes are compiled (``n_walkers`` and ``n_walkers / 2``); both are compiled before
sampling.

emcee is imported inside :func:`sample_posterior` only (``import blurtrap`` stays light).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .._config import float64_scope
from ._calibrate import calibrate
from ._log_posterior import _compiled_log_posterior, _PostArgs
from ._models import get_model
from ._options import _default_k_mode
from ._pointwise import Pointwise, exact_pointwise, spectral_pointwise
from ._posterior_chain import ShortChainWarning as ShortChainWarning
from ._posterior_chain import burn_in_and_tau, run_emcee
from ._posterior_priors import _check_user_priors, _resolve_priors, check_prior_units, prior_conflict_notes
from ._posterior_result import Posterior, _derived
from ._priors import LogUniform, Uniform
from ._problems import make_exact_args, make_layout
from ._recordings import as_recordings
from ._result import CalibrationResult
from ._spectral import _spectral_args
from ._whittle_closed import (
    LEAKAGE_MAX,
    _leakage,
    _rational_args,
    _rational_ok,
    _RationalWhittleArgs,
)


# ------------------------------------------------------------------------------------------
# set-up: the walkers' start, the ML fit and the compiled log-posterior
# ------------------------------------------------------------------------------------------
def _start_point(p_ml, cov, priors):
    """Centre (log parameters) and covariance (of log parameters) of the walkers' start.

    A parameter whose ML value is 0 starts just above it; one outside a (Log)Uniform
    prior's bounds but within 3 SE of them starts one e-fold inside them; each log
    parameter's start SD is capped at 1 (an eps^2 ~ 0 has SE/p >> 1)."""
    p = np.array(p_ml, dtype=float)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    for i, pr in enumerate(priors):
        if not p[i] > 0:
            p[i] = 1e-3 * np.abs(p).max() + 1e-30
        if isinstance(pr, (LogUniform, Uniform)):
            lo, hi = float(pr.low), float(pr.high)
            # only where the data are consistent with the bound (within 3 SE): a prior far
            # from the ML point is left to fail with a clear error (units, typos)
            mid = math.sqrt(lo * hi) if lo > 0 else 0.5 * hi
            if lo > 0 and p[i] < lo and lo - p[i] < 3.0 * se[i]:
                p[i] = lo * math.e if lo * math.e < hi else mid
            elif p[i] > hi and p[i] - hi < 3.0 * se[i]:
                p[i] = hi / math.e if hi / math.e > lo else mid
    cov_theta = cov / np.outer(p, p)
    sd = np.sqrt(np.clip(np.diag(cov_theta), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        cap = np.where(sd > 1.0, 1.0 / sd, 1.0)
    return np.log(p), cov_theta * np.outer(cap, cap)


def _initial_ball(rng, theta_ml, cov_theta, n_walkers, init_scale):
    d = theta_ml.size
    chol = None
    if np.all(np.isfinite(cov_theta)):
        try:
            chol = np.linalg.cholesky(0.5 * (cov_theta + cov_theta.T))
        except np.linalg.LinAlgError:
            chol = None
    if chol is None:
        chol = np.eye(d) * 1e-2
    z = rng.standard_normal((n_walkers, d))
    return theta_ml[None, :] + init_scale * z @ chol.T, chol


@dataclasses.dataclass(frozen=True)
class _Setup:
    recs: list
    model: Any
    layout: Any
    k_mode: str
    ml: CalibrationResult
    theta_start: np.ndarray  # log parameters where the walkers start
    cov_theta: np.ndarray  # covariance of the log parameters for the initial ball
    args: _PostArgs
    lik: Any
    log_prob: Callable  # thetas (n, d) -> float64 numpy (n,)
    pointwise: Pointwise  # per-observation log-likelihood of natural parameters


def _setup(data, model, priors, n_walkers, likelihood, k, f_range) -> _Setup:
    """Everything before sampling: recordings, layout, priors, the ML start and the compiled
    batched log-posterior (also used by the tests to check the sampler against independent
    evaluations of the same density)."""
    recs = as_recordings(data)
    mdl = get_model(model)
    k_mode = k if k is not None else _default_k_mode(recs)
    layout = make_layout(recs, k_mode, mdl.noise, tuple(p.name for p in mdl.extra_params))
    ndim = len(layout.names)
    if n_walkers % 2 or n_walkers < 2 * ndim:
        raise ValueError(
            f"n_walkers must be even and >= 2 x {ndim} parameters {list(layout.names)}; "
            f"got n_walkers = {n_walkers}"
        )
    prior_objs, user_fns = _resolve_priors(layout, priors)
    check_prior_units(layout.names, prior_objs,
                      any(str(getattr(r, "position_unit", "m")) == "V" for r in recs))
    _check_user_priors(user_fns, layout.names)

    # ---- maximum-likelihood start ------------------------------------------------------
    ml = calibrate(recs, method="likelihood", likelihood=likelihood, model=mdl, k=k_mode,
                   f_range=f_range)
    if tuple(ml.param_names) != tuple(layout.names):  # pragma: no cover - defensive
        raise AssertionError((ml.param_names, layout.names))
    conflicts = prior_conflict_notes(layout.names, prior_objs, ml.values, list(ml.errors))
    if conflicts:  # shown with the ML start's notes (Posterior.notes)
        ml = dataclasses.replace(ml, notes=tuple(ml.notes) + tuple(conflicts))
    # the likelihood sees what the fit saw: lines subtracted, the band and the ranges it
    # left out (the raw recordings gave gamma 23 SE high with a 50 Hz line that calibrate
    # had removed: an independent pass)
    excluded: tuple = ()
    if ml.inputs is not None:
        recs, f_range, excluded = list(ml.inputs.recordings), ml.inputs.f_range, \
            tuple(ml.inputs.excluded)
    p_ml = np.asarray(ml.values, dtype=float)
    theta_ml, cov_theta = _start_point(p_ml, np.asarray(ml.covariance, dtype=float),
                                       prior_objs)

    # ---- likelihood arguments and the batched log-posterior ----------------------------
    if likelihood == "whittle":
        lik = spec = _spectral_args(recs, layout, mdl, 1, f_range, excluded)
        if _rational_ok(mdl, f_range) and not excluded:  # lag sums need every ordinate
            rat = _rational_args(recs, lik)
            if lik.block_len is None or _leakage(np.exp(theta_ml), rat) <= LEAKAGE_MAX:
                lik = rat  # the discrete PSD P_d: per ordinate, spec without block_len
                spec = dataclasses.replace(spec, block_len=None)
        pointwise = spectral_pointwise(spec)
    else:
        lik = make_exact_args(recs, layout, mdl)
        pointwise = exact_pointwise(lik)
    args = _PostArgs(lik=lik, priors=prior_objs, names=tuple(layout.names),
                     user_log_prior=user_fns, chunk=None if likelihood == "exact" else 1)

    log_prob = _compiled_log_posterior(args)
    return _Setup(recs=recs, model=mdl, layout=layout, k_mode=k_mode, ml=ml,
                  theta_start=theta_ml, cov_theta=cov_theta, args=args, lik=lik,
                  log_prob=log_prob, pointwise=pointwise)


# ------------------------------------------------------------------------------------------
# the emcee run
# ------------------------------------------------------------------------------------------
def _check_run_args(likelihood, n_walkers, n_steps, init_scale) -> tuple[int, int | str, float]:
    """Validate the sampler arguments (before any fit); return them as int, int, float."""
    if likelihood not in ("whittle", "exact"):
        raise ValueError(f"likelihood must be 'whittle' or 'exact'; got {likelihood!r}")
    if n_steps != "auto":
        if isinstance(n_steps, (str, bool)) or int(n_steps) != n_steps:
            raise ValueError(f"n_steps must be 'auto' or an integer >= 10; got n_steps = {n_steps!r}")
        n_steps = int(n_steps)
        if n_steps < 10:
            raise ValueError(f"n_steps must be >= 10; got {n_steps}")
    n_walkers = int(n_walkers)
    ok = isinstance(init_scale, (int, float, np.integer, np.floating)) and not isinstance(
        init_scale, (bool, np.bool_))
    if not (ok and math.isfinite(float(init_scale)) and 0.0 < float(init_scale) <= 1.0):
        raise ValueError(
            f"init_scale must be a finite number in (0, 1]: the walkers start within "
            "init_scale maximum-likelihood standard errors of the ML point, in log "
            "parameters (default 0.1); larger balls start walkers where the posterior is "
            f"negligible or zero; got init_scale = {init_scale!r}")
    return n_walkers, n_steps, float(init_scale)


def _compile_both_shapes(log_prob, theta_ml, n_walkers: int) -> float:
    """Compile both batch shapes (full and half ensemble) before sampling; return the time."""
    ndim = theta_ml.size
    t0 = time.perf_counter()
    log_prob(np.broadcast_to(theta_ml, (n_walkers, ndim)))
    log_prob(np.broadcast_to(theta_ml, (n_walkers // 2, ndim)))
    return time.perf_counter() - t0


def _start_walkers(rng, su: _Setup, n_walkers: int, init_scale: float):
    """The initial ball around the ML point; walkers where the posterior is zero are redrawn
    (up to 100 times). Returns the positions and their log-posteriors."""
    theta_ml, log_prob = su.theta_start, su.log_prob
    ndim = theta_ml.size
    theta0, chol = _initial_ball(rng, theta_ml, su.cov_theta, n_walkers, init_scale)
    lp0 = log_prob(theta0)
    for _ in range(100):
        bad = ~np.isfinite(lp0)
        if not bad.any():
            break
        z = rng.standard_normal((int(bad.sum()), ndim))
        theta0[bad] = theta_ml[None, :] + init_scale * z @ chol.T
        lp0 = log_prob(theta0)  # whole ensemble: no third batch shape is compiled
    if not np.all(np.isfinite(lp0)):
        p_ml = np.asarray(su.ml.values, dtype=float)
        at = dict(zip(su.layout.names, map(float, p_ml), strict=True))
        raise ValueError(
            f"the posterior is zero around the maximum-likelihood point {at}: check that the "
            "priors' support contains it (e.g. LogUniform bounds, units in SI)"
        )
    return theta0, lp0


# ------------------------------------------------------------------------------------------
# entry point
# ------------------------------------------------------------------------------------------
@float64_scope
def sample_posterior(
    data,
    *,
    model=None,
    priors=None,
    n_walkers: int = 32,
    n_steps: int | str = "auto",
    seed: int = 0,
    progress: bool = False,
    likelihood: str = "whittle",
    k: str | None = None,
    f_range=None,
    init_scale: float = 0.1,
    burn_in: int | None = None,
) -> Posterior:
    r"""Sample the posterior of (k or c, gamma, eps^2) with emcee's ensemble sampler.

    **Arguments:**

    - `data`: a ``Recording``, ``RecordingSet``, list of recordings or manifest path.
    - `model`: ``"standard"`` (default), ``"blur"``, ``"naive"``, ``"naive_aliased"`` or a
      ``TrapModel``.
    - `priors`: dict ``{name: Prior}`` over ``layout.names`` (``"k"`` applies to every
      ``k[...]``), e.g. ``{"gamma": stokes_gamma_prior(...), "tracking_var":
      stuck_bead_prior(s2, n)}``; parameters without an entry get a log-uniform prior on wide
      physical bounds (``DEFAULT_BOUNDS``), except ``tracking_var``: uniform on
      ``[0, 1e-10]`` m^2 (eps^2 is often consistent with 0, where a log-uniform prior would
      depend on its arbitrary lower cut-off). User log-prior functions ``f(params) -> scalar``
      (JAX-traceable; ``params`` maps ``layout.names`` to SI values; density in the natural
      parameters) are given as ``priors=f``, a list of functions, or under the key
      ``"log_prior"``; they add to the per-parameter priors.
    - `n_walkers`: even, >= 2 x the number of parameters. `n_steps`: steps per walker, or
      ``"auto"`` (default): 2000, extended until the chain holds 50 integrated
      autocorrelation times (at most 20 000).
    - `seed`: seeds ``np.random.default_rng(seed)``, which draws the initial ball and seeds the
      ``RandomState`` handed to emcee (no global RNG state is used or changed).
    - `progress`: emcee's progress bar.
    - `likelihood`: ``"whittle"`` (periodogram, O(N log N) once, then O(1) per evaluation
      for closed-form models, O(N) otherwise; see the module docstring) or ``"exact"`` (O(N)
      ARMA likelihood with REML mean).
    - `k`: ``"shared"``, ``"per_recording"``, ``"per_power"`` or ``"linear_power"`` (``k = c
      P``); default: per power when the recordings' powers differ.
    - `f_range`: ``(f_min, f_max)`` [Hz] for the Whittle likelihood.
    - `init_scale`: walkers start at ``theta_ML + init_scale * L z`` (``L L^T`` the ML
      covariance of log parameters from :func:`calibrate`, each SD capped at 1; ``z``
      standard normal); a number in (0, 1]. An ML value within 3 SE outside a (Log)Uniform prior's bounds (eps^2
      ~ 0) starts just inside them.
    - `burn_in`: steps discarded; default ``max(3 tau_max, n_steps / 10)`` (at most half).

    **Returns:** :class:`Posterior`.

    **Warns:** :class:`ShortChainWarning` when ``n_steps < 50 tau_max`` (with ``"auto"``:
    after 20 000 steps).

    **Raises:** ``ValueError`` for bad arguments or a start outside the prior's support;
    ``TypeError`` for a user log-prior that is not JAX-traceable (checked before any fit);
    ``FitError`` when the maximum-likelihood start cannot be found.
    """
    import emcee

    n_walkers, n_steps, init_scale = _check_run_args(likelihood, n_walkers, n_steps, init_scale)
    su = _setup(data, model, priors, n_walkers, likelihood, k, f_range)
    t_compile = _compile_both_shapes(su.log_prob, su.theta_start, n_walkers)
    rng = np.random.default_rng(seed)
    theta0, lp0 = _start_walkers(rng, su, n_walkers, init_scale)
    sampler, n_steps, t_sample = run_emcee(emcee, su.log_prob, theta0, lp0, rng, n_steps, progress)

    # ---- diagnostics -------------------------------------------------------------------
    chain = np.asarray(sampler.get_chain())  # (n_steps, n_walkers, ndim) in theta
    lps = np.asarray(sampler.get_log_prob())
    burn, tau = burn_in_and_tau(emcee, chain, n_steps, burn_in)
    kept = chain[burn:]
    ess = n_walkers * kept.shape[0] / tau
    chain_nat = np.exp(kept)
    temps = {float(r.temperature) for r in su.recs}
    temperature = float(np.mean(list(temps)))
    names = su.layout.names
    return Posterior(
        samples=_derived(su.layout, chain_nat, temperature),
        param_names=tuple(names),
        chain=chain_nat,
        log_prob=lps[burn:],
        acceptance_fraction=np.asarray(sampler.acceptance_fraction, dtype=float),
        autocorr_time=dict(zip(names, map(float, tau), strict=True)),
        ess=dict(zip(names, map(float, ess), strict=True)),
        burn_in=burn,
        n_steps=n_steps,
        n_walkers=n_walkers,
        likelihood=likelihood,
        model=su.model.name,
        k_mode=su.k_mode,
        temperature=temperature,
        seed=int(seed),
        ml=su.ml,
        timing={"compile_s": t_compile, "sampling_s": t_sample},
        evaluation=("exact" if likelihood == "exact" else "whittle_closed_form"
                    if isinstance(su.lik, _RationalWhittleArgs) else "whittle_ordinates"),
        pointwise=su.pointwise,
    )
