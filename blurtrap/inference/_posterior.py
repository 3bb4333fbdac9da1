r"""Posterior sampling of trap parameters with emcee's affine-invariant ensemble sampler.

The log-posterior is **one** jitted, vmapped JAX function over walkers,

``log post(theta) = log L(p) + sum_i log prior_i(p_i) + sum_i theta_i``,  ``p = exp(theta)``,

evaluated in ``theta = log p`` (log k, log gamma, log eps^2, ...; the last term is the Jacobian
of the log transform, so a prior written as a density in ``p`` means exactly that: the
default log-uniform prior is uniform in ``theta``). The likelihood is the Whittle likelihood
of the periodogram (``likelihood="whittle"``, the default) or the exact O(N) ARMA likelihood
(``"exact"``) of :mod:`blurtrap.inference._problems`; parameters follow the recordings'
:class:`Layout` (``layout.names``), so joint sets with shared gamma / eps^2 and k per power
or ``k = c P`` work unchanged. NaN is mapped to ``-inf`` inside JAX and the host receives a
float64 NumPy vector (emcee's ``vectorize=True``). emcee's red-blue stretch move evaluates
half ensembles, so exactly two batch shapes are compiled (``n_walkers`` and
``n_walkers / 2``); both are compiled before sampling.

emcee is imported inside :func:`sample_posterior` only (``import blurtrap`` stays light).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import warnings
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope
from ..physics._constants import BOLTZMANN
from ._calibrate import _default_k_mode, _spectral_args, as_recordings, calibrate
from ._models import get_model
from ._priors import DEFAULT_BOUNDS, LogUniform, Prior
from ._problems import exact_nll, make_exact_args, make_layout, spectral_nll
from ._result import LAB, CalibrationResult


class ShortChainWarning(UserWarning):
    """The chain is shorter than ~50 integrated autocorrelation times: the interval
    estimates are noisy; run more steps."""


# lab units for summaries: name -> (factor from SI, unit)
LAB_UNITS = LAB

_TRACE_COUNT = [0]  # incremented each time the batched log-posterior is traced


def trace_count() -> int:
    """How many times the batched log-posterior has been traced (compiled) so far."""
    return _TRACE_COUNT[0]


# ------------------------------------------------------------------------------------------
# the log-posterior (pure JAX)
# ------------------------------------------------------------------------------------------
class _PostArgs(eqx.Module):
    lik: Any  # SpectralArgs or ExactArgs
    priors: tuple  # one Prior per parameter, in layout.names order
    names: tuple = eqx.field(static=True)
    exact: bool = eqx.field(static=True)
    user_log_prior: tuple = eqx.field(static=True)  # JAX-traceable f(dict) -> scalar
    chunk: int | None = eqx.field(static=True, default=None)  # walkers per vmap chunk


def _log_posterior(theta, a: _PostArgs):
    p = jnp.exp(theta)
    lp = jnp.sum(theta)  # log |dp/dtheta|
    for i, prior in enumerate(a.priors):
        lp = lp + prior.log_prob(p[i])
    if a.user_log_prior:
        d = {name: p[i] for i, name in enumerate(a.names)}
        for fn in a.user_log_prior:
            lp = lp + jnp.asarray(fn(d), dtype=p.dtype)
    nll = exact_nll(p, a.lik) if a.exact else spectral_nll(p, a.lik)
    out = lp - nll
    return jnp.where(jnp.isnan(out), -jnp.inf, out)


def _batched_impl(thetas, a: _PostArgs):
    """Log-posterior of a batch of walkers ``thetas`` (n, d) -> (n,). The walker axis is
    vectorised (``vmap``) in chunks of ``a.chunk`` walkers, looped with ``lax.map``: for the
    Whittle likelihood a chunk of 1 keeps each walker's (R, M) intermediates in cache and is
    ~4x faster on CPU than one (n, R, M) vmap; the exact likelihood's sequential scan is
    vectorised over the whole batch."""
    _TRACE_COUNT[0] += 1  # Python side effect: runs only while tracing
    chunk = thetas.shape[0] if a.chunk is None else min(a.chunk, thetas.shape[0])
    if chunk >= thetas.shape[0]:
        return jax.vmap(_log_posterior, in_axes=(0, None))(thetas, a)
    one = lambda t: _log_posterior(t, a)
    if chunk == 1:
        return jax.lax.map(one, thetas)
    return jax.lax.map(one, thetas, batch_size=chunk)


_batched_log_posterior = eqx.filter_jit(_batched_impl)

# One jitted function per static configuration (model flags, layout names, prior kinds,
# user prior functions): data and prior values are its array arguments, so new data of the
# same shapes reuse the compiled code. Array leaves are flattened once per
# ``sample_posterior`` call and passed positionally, so each of emcee's calls takes JAX's C++
# dispatch path (no per-call pytree flattening of the arguments).
_JIT_CACHE: dict = {}


def _compiled_log_posterior(args: _PostArgs):
    """Return ``f(thetas) -> np.ndarray[float64]`` for emcee (``vectorize=True``)."""
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    key = (treedef, static)
    fn = _JIT_CACHE.get(key)
    if fn is None:

        def impl(thetas, *lv):
            a = eqx.combine(jax.tree_util.tree_unflatten(treedef, lv), static)
            return _batched_impl(thetas, a)

        fn = _JIT_CACHE[key] = jax.jit(impl)

    def log_prob(thetas):
        return np.asarray(fn(np.asarray(thetas, dtype=np.float64), *leaves), dtype=np.float64)

    return log_prob


# ------------------------------------------------------------------------------------------
# results
# ------------------------------------------------------------------------------------------
def _base(name: str) -> str:
    return name.split("[")[0]


@dataclasses.dataclass(frozen=True)
class Posterior:
    """Posterior samples of trap parameters (SI units) with MCMC diagnostics.

    - ``samples``: dict of 1-D arrays (all walkers and kept steps, burn-in removed) keyed like
      :meth:`CalibrationResult.to_dict`: ``k`` (or ``k[...]`` per stiffness parameter, or
      ``c`` and the implied ``k[P=... mW]``), ``gamma``, ``tracking_var`` (models with
      tracking noise) and the derived ``diffusion`` (kT/gamma), ``tau`` (gamma/k),
      ``corner_frequency`` (k/(2 pi gamma)), ``force_per_nm`` (k x 1 nm, [N]), with the same
      ``[...]`` suffix as their k when there are several.
    - ``chain``: (n_kept, n_walkers, n_params) natural parameters in ``param_names`` order.
    - ``acceptance_fraction`` (per walker), ``autocorr_time`` and ``ess`` (dicts over
      ``param_names``; tau in steps, ESS in independent samples), ``burn_in`` (steps).
    """

    samples: dict
    param_names: tuple
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance_fraction: np.ndarray
    autocorr_time: dict
    ess: dict
    burn_in: int
    n_steps: int
    n_walkers: int
    likelihood: str
    model: str
    k_mode: str
    temperature: float
    seed: int
    ml: CalibrationResult
    timing: dict = dataclasses.field(default_factory=dict)

    @property
    def n_samples(self) -> int:
        return int(self.chain.shape[0] * self.chain.shape[1])

    def quantiles(self, name: str, q=(0.025, 0.16, 0.5, 0.84, 0.975)) -> np.ndarray:
        """Quantiles of ``samples[name]`` (SI)."""
        return np.quantile(self.samples[name], q)

    def interval(self, name: str, level: float = 0.68) -> tuple[float, float]:
        """Central credible interval of ``samples[name]`` at ``level`` (SI)."""
        lo, hi = np.quantile(self.samples[name], [0.5 - level / 2, 0.5 + level / 2])
        return float(lo), float(hi)

    def stats(self) -> dict[str, dict[str, float]]:
        """Per quantity: median, 68 % and 95 % central intervals, mean and SD (SI)."""
        out = {}
        for name, s in self.samples.items():
            q = np.quantile(s, [0.025, 0.16, 0.5, 0.84, 0.975])
            out[name] = {"median": float(q[2]), "q16": float(q[1]), "q84": float(q[3]),
                         "q2.5": float(q[0]), "q97.5": float(q[4]),
                         "mean": float(np.mean(s)), "sd": float(np.std(s, ddof=1))}
        return out

    def summary(self) -> str:
        """Table in lab units: median, 68 % and 95 % central intervals, plus diagnostics."""
        head = (f"posterior ({self.likelihood} likelihood, model {self.model}, k {self.k_mode}): "
                f"{self.n_walkers} walkers x {self.n_steps} steps, burn-in {self.burn_in}, "
                f"{self.n_samples} samples, acceptance {np.mean(self.acceptance_fraction):.3f}")
        lines = [head, f"  {'quantity':<26s} {'median':>11s}   {'68 % interval':>25s}   "
                       f"{'95 % interval':>25s}  unit"]
        for name, st in self.stats().items():
            fac, unit = LAB_UNITS.get(_base(name), (1.0, "SI"))
            lines.append(
                f"  {name:<26s} {st['median'] * fac:11.5g}   "
                f"[{st['q16'] * fac:11.5g}, {st['q84'] * fac:11.5g}]   "
                f"[{st['q2.5'] * fac:11.5g}, {st['q97.5'] * fac:11.5g}]  {unit}"
            )
        taus = ", ".join(f"{n} {t:.3g}" for n, t in self.autocorr_time.items())
        esss = ", ".join(f"{n} {e:.0f}" for n, e in self.ess.items())
        lines.append(f"  autocorrelation time [steps]: {taus}")
        lines.append(f"  effective sample size: {esss}")
        return "\n".join(lines)

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.summary()

    def to_dict(self, include_samples: bool = False) -> dict[str, Any]:
        """JSON-able dict in SI units. Top-level ``k``/``gamma``/``tracking_var``/... hold
        posterior medians and ``*_err`` half the 68 % interval, as in
        :meth:`CalibrationResult.to_dict`; ``stats`` has the intervals."""
        st = self.stats()
        out: dict[str, Any] = {}
        for name, s in st.items():
            out[name] = s["median"]
            out[f"{name}_err"] = 0.5 * (s["q84"] - s["q16"])
        out.update({
            "method": "posterior",
            "likelihood": self.likelihood,
            "model": self.model,
            "k_mode": self.k_mode,
            "param_names": list(self.param_names),
            "stats": st,
            "acceptance_fraction": float(np.mean(self.acceptance_fraction)),
            "autocorr_time": {k: float(v) for k, v in self.autocorr_time.items()},
            "ess": {k: float(v) for k, v in self.ess.items()},
            "burn_in": int(self.burn_in),
            "n_steps": int(self.n_steps),
            "n_walkers": int(self.n_walkers),
            "n_samples": self.n_samples,
            "temperature": float(self.temperature),
            "seed": int(self.seed),
            "ml": self.ml.to_dict(),
            "timing": {k: float(v) for k, v in self.timing.items()},
            "units": "SI",
        })
        if include_samples:
            out["samples"] = {k: [float(x) for x in v] for k, v in self.samples.items()}
        return out

    def to_arviz(self):
        """An ``arviz.InferenceData`` (walkers as chains) of the sampled parameters.

        **Raises:** ``ImportError`` when arviz is not installed.
        """
        try:
            import arviz as az
        except ImportError:
            raise ImportError(
                "Posterior.to_arviz() needs arviz, which is not installed: pip install arviz"
            ) from None
        post = {name: np.swapaxes(self.chain[..., i], 0, 1)
                for i, name in enumerate(self.param_names)}
        return az.from_dict(posterior=post,
                            sample_stats={"lp": np.swapaxes(self.log_prob, 0, 1)})


# ------------------------------------------------------------------------------------------
# set-up helpers
# ------------------------------------------------------------------------------------------
def _resolve_priors(layout, priors) -> tuple[tuple, tuple]:
    """Per-parameter Prior objects (defaults: log-uniform bounds) and user log-prior fns.

    ``priors`` maps parameter names (``layout.names``; the base name ``k`` applies to every
    ``k[...]``) to :class:`Prior` objects; callables under the key ``None`` or in a list under
    ``"log_prior"``, or ``priors`` given as a callable / sequence of callables, are
    user log-prior functions ``f(params: dict) -> scalar`` (JAX-traceable, natural SI values
    keyed by ``layout.names``; a density in the natural parameters)."""
    per: dict[str, Prior] = {}
    fns: list[Callable] = []
    if priors is None:
        priors = {}
    if callable(priors) and not isinstance(priors, Prior):
        fns.append(priors)
        priors = {}
    elif isinstance(priors, (list, tuple)):
        for f in priors:
            if not callable(f):
                raise TypeError(f"priors: expected callables in a sequence; got {f!r}")
            fns.append(f)
        priors = {}
    valid = set(layout.names) | {_base(n) for n in layout.names}
    for key, val in dict(priors).items():
        if key is None or key == "log_prior":
            vals = val if isinstance(val, (list, tuple)) else [val]
            for f in vals:
                if not callable(f):
                    raise TypeError(f"priors[{key!r}] must be callable; got {f!r}")
                fns.append(f)
            continue
        if key not in valid:
            raise ValueError(
                f"priors: unknown parameter {key!r}; the parameters of this model are "
                f"{list(layout.names)}"
            )
        if not isinstance(val, Prior):
            raise TypeError(
                f"priors[{key!r}] must be a blurtrap Prior (LogUniform, Normal, LogNormal, "
                f"InverseGamma, ...); got {type(val).__name__}"
            )
        per[key] = val
    out = []
    for name in layout.names:
        base = _base(name)
        if name in per:
            out.append(per[name])
        elif base in per:
            out.append(per[base])
        else:
            out.append(LogUniform(*DEFAULT_BOUNDS[base]))
    return tuple(out), tuple(fns)


def _derived(layout, chain_nat: np.ndarray, temperature: float) -> dict[str, np.ndarray]:
    flat = chain_nat.reshape(-1, chain_nat.shape[-1])
    names = layout.names
    samples: dict[str, np.ndarray] = {}
    col = {n: flat[:, i] for i, n in enumerate(names)}
    gamma = col["gamma"]
    ks: dict[str, np.ndarray] = {}
    if layout.linear_power:
        samples["c"] = col["c"]
        for pw in np.unique(np.asarray(layout.power)):
            ks[f"k[P={pw * 1e3:g} mW]"] = col["c"] * pw
    else:
        for lab in layout.k_labels:
            ks[lab] = col[lab]
    samples.update(ks)
    samples["gamma"] = gamma
    if "tracking_var" in col:
        samples["tracking_var"] = col["tracking_var"]
    samples["diffusion"] = BOLTZMANN * temperature / gamma
    for lab, kv in ks.items():
        suffix = lab[1:]  # "" or "[...]"
        samples["tau" + suffix] = gamma / kv
        samples["corner_frequency" + suffix] = kv / (2.0 * np.pi * gamma)
        samples["force_per_nm" + suffix] = kv * 1e-9
    return samples


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


def _integrated_time(emcee, chain) -> np.ndarray:
    """emcee's integrated autocorrelation time per parameter (quiet: its too-short-chain
    message is logged by emcee; :class:`ShortChainWarning` reports it once instead)."""
    logger = logging.getLogger("emcee.autocorr")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        return np.asarray(emcee.autocorr.integrated_time(chain, quiet=True), dtype=float)
    finally:
        logger.setLevel(level)


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
    n_steps: int = 2000,
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
      physical bounds (``DEFAULT_BOUNDS``). User log-prior functions ``f(params) -> scalar``
      (JAX-traceable; ``params`` maps ``layout.names`` to SI values; density in the natural
      parameters) are given as ``priors=f``, a list of functions, or under the key
      ``"log_prior"``; they add to the per-parameter priors.
    - `n_walkers`: even, >= 2 x the number of parameters. `n_steps`: steps per walker.
    - `seed`: seeds ``np.random.default_rng(seed)``, which draws the initial ball and seeds the
      ``RandomState`` handed to emcee (no global RNG state is used or changed).
    - `progress`: emcee's progress bar.
    - `likelihood`: ``"whittle"`` (periodogram, O(N log N) once, then O(N) per evaluation) or
      ``"exact"`` (O(N) ARMA likelihood with REML mean).
    - `k`: ``"shared"``, ``"per_recording"``, ``"per_power"`` or ``"linear_power"`` (``k = c
      P``); default: per power when the recordings' powers differ.
    - `f_range`: ``(f_min, f_max)`` [Hz] for the Whittle likelihood.
    - `init_scale`: walkers start at ``theta_ML + init_scale * L z`` (``L L^T`` the ML
      covariance of log parameters from :func:`calibrate`, ``z`` standard normal).
    - `burn_in`: steps discarded; default ``max(3 tau_max, n_steps / 10)`` (at most half).

    **Returns:** :class:`Posterior`.

    **Warns:** :class:`ShortChainWarning` when ``n_steps < 50 tau_max``.

    **Raises:** ``ValueError`` for bad arguments or a start outside the prior's support;
    ``FitError`` when the maximum-likelihood start cannot be found.
    """
    import emcee

    if likelihood not in ("whittle", "exact"):
        raise ValueError(f"likelihood must be 'whittle' or 'exact'; got {likelihood!r}")
    n_walkers, n_steps = int(n_walkers), int(n_steps)
    if n_steps < 10:
        raise ValueError(f"n_steps must be >= 10; got {n_steps}")
    if not init_scale > 0:
        raise ValueError(f"init_scale must be > 0; got {init_scale!r}")
    recs = as_recordings(data)
    mdl = get_model(model)
    k_mode = k if k is not None else _default_k_mode(recs)
    layout = make_layout(recs, k_mode, mdl.noise)
    ndim = len(layout.names)
    if n_walkers % 2 or n_walkers < 2 * ndim:
        raise ValueError(
            f"n_walkers must be even and >= 2 x {ndim} parameters {list(layout.names)}; "
            f"got n_walkers = {n_walkers}"
        )
    prior_objs, user_fns = _resolve_priors(layout, priors)

    # ---- maximum-likelihood start ------------------------------------------------------
    ml = calibrate(recs, method="likelihood", likelihood=likelihood, model=mdl, k=k_mode,
                   f_range=f_range)
    if tuple(ml.param_names) != tuple(layout.names):  # pragma: no cover - defensive
        raise AssertionError((ml.param_names, layout.names))
    p_ml = np.asarray(ml.values, dtype=float)
    if not np.all(p_ml > 0):
        # eps^2 = 0 on the boundary: start just inside
        p_ml = np.where(p_ml > 0, p_ml, 1e-3 * np.abs(p_ml).max() + 1e-30)
    theta_ml = np.log(p_ml)
    cov_theta = np.asarray(ml.covariance, dtype=float) / np.outer(p_ml, p_ml)

    # ---- likelihood arguments and the batched log-posterior ----------------------------
    if likelihood == "whittle":
        lik = _spectral_args(recs, layout, mdl, 1, f_range)
    else:
        lik = make_exact_args(recs, layout, mdl)
    args = _PostArgs(lik=lik, priors=prior_objs, names=tuple(layout.names),
                     exact=likelihood == "exact", user_log_prior=user_fns,
                     chunk=None if likelihood == "exact" else 1)

    log_prob = _compiled_log_posterior(args)

    # compile both batch shapes (full and half ensemble) before sampling
    t0 = time.perf_counter()
    log_prob(np.broadcast_to(theta_ml, (n_walkers, ndim)))
    log_prob(np.broadcast_to(theta_ml, (n_walkers // 2, ndim)))
    t_compile = time.perf_counter() - t0

    # ---- initial ball and RNG ----------------------------------------------------------
    rng = np.random.default_rng(seed)
    theta0, chol = _initial_ball(rng, theta_ml, cov_theta, n_walkers, init_scale)
    lp0 = log_prob(theta0)
    for _ in range(100):
        bad = ~np.isfinite(lp0)
        if not bad.any():
            break
        z = rng.standard_normal((int(bad.sum()), ndim))
        theta0[bad] = theta_ml[None, :] + init_scale * z @ chol.T
        lp0 = log_prob(theta0)  # whole ensemble: no third batch shape is compiled
    if not np.all(np.isfinite(lp0)):
        at = dict(zip(layout.names, map(float, p_ml), strict=True))
        raise ValueError(
            f"the posterior is zero around the maximum-likelihood point {at}: check that the "
            "priors' support contains it (e.g. LogUniform bounds, units in SI)"
        )
    rstate = np.random.RandomState(int(rng.integers(0, 2**32 - 1)))

    sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True)
    state = emcee.State(theta0, log_prob=lp0, random_state=rstate.get_state())
    t0 = time.perf_counter()
    sampler.run_mcmc(state, n_steps, progress=progress)
    t_sample = time.perf_counter() - t0

    # ---- diagnostics -------------------------------------------------------------------
    chain = sampler.get_chain()  # (n_steps, n_walkers, ndim) in theta
    lps = sampler.get_log_prob()
    tau_full = _integrated_time(emcee, chain)
    tau_max = float(np.nanmax(tau_full)) if np.any(np.isfinite(tau_full)) else float(n_steps)
    if burn_in is None:
        burn = max(int(math.ceil(3.0 * tau_max)), int(math.ceil(0.1 * n_steps)))
        burn = min(burn, n_steps // 2)
    else:
        burn = int(burn_in)
        if not 0 <= burn < n_steps:
            raise ValueError(f"burn_in must be in [0, n_steps); got {burn_in!r}")
    kept = chain[burn:]
    tau = _integrated_time(emcee, kept)
    tau_chk = float(np.nanmax(np.maximum(tau, tau_full)))
    if n_steps < 50.0 * tau_chk:
        warnings.warn(
            f"the chain ({n_steps} steps) is shorter than 50 integrated autocorrelation "
            f"times (tau_max = {tau_chk:.3g} steps): intervals are noisy; use n_steps >= "
            f"{int(math.ceil(50 * tau_chk))}",
            ShortChainWarning,
            stacklevel=3,
        )
    ess = n_walkers * kept.shape[0] / tau
    chain_nat = np.exp(kept)
    temps = {float(r.temperature) for r in recs}
    temperature = float(np.mean(list(temps)))
    samples = _derived(layout, chain_nat, temperature)
    return Posterior(
        samples=samples,
        param_names=tuple(layout.names),
        chain=chain_nat,
        log_prob=lps[burn:],
        acceptance_fraction=np.asarray(sampler.acceptance_fraction, dtype=float),
        autocorr_time=dict(zip(layout.names, map(float, tau), strict=True)),
        ess=dict(zip(layout.names, map(float, ess), strict=True)),
        burn_in=burn,
        n_steps=n_steps,
        n_walkers=n_walkers,
        likelihood=likelihood,
        model=mdl.name,
        k_mode=k_mode,
        temperature=temperature,
        seed=int(seed),
        ml=ml,
        timing={"compile_s": t_compile, "sampling_s": t_sample},
    )
