"""Running emcee and reading its chain: the sampler run (a fixed number of steps, or
``"auto"``: until the chain holds 50 integrated autocorrelation times), the burn-in and the
autocorrelation times, and :class:`ShortChainWarning`.

``n_steps="auto"`` (the default of :func:`blurtrap.sample_posterior`): an independent pass
found the former default of 2000 steps warning on every fit of a camera recording whose
eps^2 sits near 0 (tau_max 80-90 steps: 4000-4600 needed); the run now extends itself in
chunks, up to :data:`AUTO_MAX_STEPS`, and warns only when that is not enough."""

from __future__ import annotations

import logging
import math
import time
import warnings

import numpy as np

#: ``n_steps="auto"``: the first chunk, the most steps, and the chain length in integrated
#: autocorrelation times it runs to
AUTO_FIRST_STEPS = 2000
AUTO_MAX_STEPS = 20000
TAU_MULTIPLE = 50.0


class ShortChainWarning(UserWarning):
    """The chain is shorter than ~50 integrated autocorrelation times: the interval
    estimates are noisy; run more steps."""


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


def run_emcee(emcee, log_prob, theta0, lp0, rng, n_steps, progress: bool):
    """Run emcee's ensemble sampler (``vectorize=True``) from ``theta0``, seeded from
    ``rng``, for ``n_steps`` steps, or with ``"auto"`` in chunks until the chain holds
    ``TAU_MULTIPLE`` autocorrelation times (at most ``AUTO_MAX_STEPS``); return the
    sampler, the steps run and the sampling time."""
    n_walkers, ndim = theta0.shape
    rstate = np.random.RandomState(int(rng.integers(0, 2**32 - 1)))
    sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True)
    state = emcee.State(theta0, log_prob=lp0, random_state=rstate.get_state())
    t0 = time.perf_counter()
    steps = AUTO_FIRST_STEPS if n_steps == "auto" else int(n_steps)
    sampler.run_mcmc(state, steps, progress=progress)
    while n_steps == "auto" and steps < AUTO_MAX_STEPS:
        tau = _integrated_time(emcee, np.asarray(sampler.get_chain()))
        need = TAU_MULTIPLE * float(np.nanmax(tau)) if np.any(np.isfinite(tau)) else 2.0 * steps
        if steps >= need:
            break
        more = int(min(max(math.ceil(1.2 * need) - steps, 500), AUTO_MAX_STEPS - steps))
        sampler.run_mcmc(None, more, progress=progress)
        steps += more
    return sampler, steps, time.perf_counter() - t0


def burn_in_and_tau(emcee, chain, n_steps: int, burn_in) -> tuple[int, np.ndarray]:
    """The burn-in (default ``max(3 tau_max, n_steps / 10)``, at most half) and the
    integrated autocorrelation times of the kept chain; warns when the chain is short."""
    tau_full = _integrated_time(emcee, chain)
    tau_max = float(np.nanmax(tau_full)) if np.any(np.isfinite(tau_full)) else float(n_steps)
    if burn_in is None:
        burn = max(int(math.ceil(3.0 * tau_max)), int(math.ceil(0.1 * n_steps)))
        burn = min(burn, n_steps // 2)
    else:
        burn = int(burn_in)
        if not 0 <= burn < n_steps:
            raise ValueError(f"burn_in must be in [0, n_steps); got {burn_in!r}")
    tau = _integrated_time(emcee, chain[burn:])
    tau_chk = float(np.nanmax(np.maximum(tau, tau_full)))
    if n_steps < TAU_MULTIPLE * tau_chk:
        warnings.warn(
            f"the chain ({n_steps} steps) is shorter than 50 integrated autocorrelation "
            f"times (tau_max = {tau_chk:.3g} steps): intervals are noisy; use n_steps >= "
            f"{int(math.ceil(TAU_MULTIPLE * tau_chk))}",
            ShortChainWarning,
            stacklevel=4,  # the caller of sample_posterior (through float64_scope)
        )
    return burn, tau
