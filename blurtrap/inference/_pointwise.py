r"""Pointwise log-likelihood of posterior draws (``Posterior.log_likelihood``, the
``log_likelihood`` group of ``Posterior.to_arviz``), for LOO/WAIC model comparison.

An "observation" must be a piece of the data that is (nearly) independent of the others given
the parameters, or leave-one-out scores mean nothing:

- **Whittle likelihoods** (``sample_posterior(likelihood="whittle")``): the periodogram
  ordinates are independent to O(tau/T). Each ordinate's density is the Gamma law of a
  (blocked) periodogram, shape ``a`` (its weight: the number of averaged blocks, half of it at
  Nyquist) and mean ``S`` (the model): ``a log a - lgamma(a) + (a - 1) log I - a log S -
  a I / S`` (I and S in m^2/Hz). Ordinates are summed in frequency **bands**, log-spaced in
  the ordinate index (``n_bands`` per recording; fewer where the low bands would be empty),
  so an observation is one band of one recording. The sum over all observations is the
  log-likelihood the sampler used (same model spectrum: the discrete PSD for the closed-form
  lag-sum evaluation, the expected periodogram otherwise), plus the data-only terms.
- **The exact likelihood** (``likelihood="exact"``): frames are correlated, so an observation
  is one whole **recording** (its exact restricted log-likelihood).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaln

from .._config import float64_scope
from ._likelihood import arma_loglik
from ._problems import ExactArgs, SpectralArgs, spectral_model_psd


@dataclasses.dataclass(frozen=True)
class Pointwise:
    """``fn(params)``: natural parameters (n, d) -> log-likelihood per observation (n, n_obs);
    ``dim`` the observation axis' name (``"band"`` or ``"recording"``) and ``labels`` one
    label per observation (recording index and frequency band in Hz)."""

    fn: Callable
    dim: str
    labels: tuple[str, ...]


def _bands(n_ord: int, n_bands: int) -> np.ndarray:
    """Band index of ordinates 1..n_ord: edges log-spaced in the index, empty bands merged."""
    edges = np.unique(np.round(np.geomspace(1, n_ord + 1, n_bands + 1)).astype(int))
    return np.searchsorted(edges, np.arange(1, n_ord + 1), side="right") - 1


def _spectral_segments(spec: SpectralArgs, n_bands: int):
    """Segment id of every (recording, ordinate) cell (padding -> the dropped last id) and the
    labels of the segments."""
    weight = np.asarray(spec.weight)
    f = np.asarray(spec.f)
    seg = np.full(weight.shape, -1, dtype=np.int64)
    labels: list[str] = []
    for r in range(weight.shape[0]):
        real = np.flatnonzero(weight[r] > 0)
        if real.size == 0:
            continue
        band = _bands(real.size, n_bands)
        for b in np.unique(band):
            idx = real[band == b]
            seg[r, idx] = len(labels)
            labels.append(f"recording {r}: {f[r, idx[0]]:.4g}-{f[r, idx[-1]]:.4g} Hz")
    n_obs = len(labels)
    return np.where(seg < 0, n_obs, seg), tuple(labels)


def spectral_pointwise(spec: SpectralArgs, n_bands: int = 64) -> Pointwise:
    """Per-band Gamma log-likelihood of the periodogram ordinates in `spec`."""
    seg, labels = _spectral_segments(spec, n_bands)
    n_obs = len(labels)
    seg_j = jnp.asarray(seg.ravel())
    a = spec.weight
    ok = a > 0
    a_safe = jnp.where(ok, a, 1.0)
    const = jnp.where(ok, a_safe * jnp.log(a_safe) - gammaln(a_safe)
                      + (a_safe - 1.0) * jnp.log(spec.power), 0.0)

    def one(p):
        s = spectral_model_psd(p, spec)
        ll = jnp.where(ok, const - a_safe * (jnp.log(s) + spec.power / s), 0.0)
        return jax.ops.segment_sum(ll.ravel(), seg_j, num_segments=n_obs + 1)[:n_obs]

    return Pointwise(_batched(one), "band", labels)


def exact_pointwise(ex: ExactArgs) -> Pointwise:
    """Per-recording exact (restricted) log-likelihood."""

    def one(p):
        k_rec, gamma, eps2 = ex.layout.unpack(p)
        c0, c1, rho = ex.model.moments(k_rec, gamma, eps2, ex.meta.dt, ex.meta.w, ex.meta.temp)
        return jax.vmap(lambda y, m, a, b, c: arma_loglik(y, a, b, c, mean=ex.mean, mask=m))(
            ex.ys, ex.mask, c0, c1, rho)

    labels = tuple(f"recording {r}" for r in range(ex.ys.shape[0]))
    return Pointwise(_batched(one), "recording", labels)


def _batched(one: Callable) -> Callable:
    """``params (n, d) -> (n, n_obs)`` float64 numpy, compiled once, draws in chunks."""
    fn = jax.jit(lambda ps: jax.lax.map(one, ps, batch_size=16))

    @float64_scope  # called from Posterior methods, outside sample_posterior's scope
    def run(params):
        return np.asarray(fn(jnp.asarray(np.asarray(params, dtype=np.float64))))

    return run
