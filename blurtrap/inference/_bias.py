"""Parametric-bootstrap bias correction of a single-recording likelihood fit.

Simulate ``B`` recordings from the fitted parameters with blurtrap's exact frame sampler
(``simulate(..., method="exact_frames")``: same frame interval, exposure, temperature, length
and tracking noise), refit each with the same estimator (the exact time-domain REML likelihood
with eps^2 >= 0, the same log-parameter safeguarded Newton iteration as
``calibrate(..., likelihood="exact")``, vmapped over the replicates), and subtract the mean
shift of the refits from the fit: ``corrected = fit - (mean(refits) - fit)``.

:func:`bootstrap_correct` is the estimator-agnostic core (a callable simulates and refits);
:func:`refit_exact` the batched exact refit. ``inference`` may not import ``simulate``
(tests/test_layout.py), so the caller supplies the simulation. Whether the correction is
offered by ``calibrate`` depends on the measured result (benchmarks/RESULTS_boundary.md,
session 12).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._newton import fd_hessian_pass, newton_minimise
from ._problems import ExactArgs, bucket_length, exact_nll

#: Newton settings of ``calibrate``'s exact fit (:func:`._fit.fit_ml_fd_newton`).
_H, _TOL, _MAX_ITER = 1e-4, 1e-9, 30
#: start value of eps^2 for the refits, as a fraction of kT/k at the fit, when the fit's own
#: eps^2 is smaller (a start deep in the bound region would need many log-space steps).
_EPS2_START = 1e-2


def exact_template(model, layout, meta, n_frames: int) -> ExactArgs:
    """Exact-likelihood arguments of one recording of ``n_frames`` frames (frames zero),
    to be filled per replicate by :func:`refit_exact`."""
    n_max = bucket_length(n_frames)
    mask = np.zeros((1, n_max))
    mask[0, :n_frames] = 1.0
    return ExactArgs(layout=layout, model=model, meta=meta, ys=jnp.zeros((1, n_max)),
                     mask=jnp.asarray(mask), mean="reml")


@eqx.filter_jit
def _refit_batch(template: ExactArgs, ys, scale, max_iter):
    pass_fn = fd_hessian_pass(exact_nll, _H)

    def one(y, scale):
        args = eqx.tree_at(lambda a: a.ys, template, y[None])
        sol = newton_minimise(pass_fn, scale, args, jnp.zeros_like(scale), _TOL, _TOL,
                              max_iter)
        st = sol.state
        x_hat = st.x - st.step
        ok = st.done & jnp.all(jnp.isfinite(x_hat))
        return scale * jnp.exp(x_hat), ok

    return jax.vmap(one)(ys, scale)


def refit_exact(template: ExactArgs, frames, start, max_iter: int = _MAX_ITER):
    """Exact-likelihood estimates of each row of ``frames`` (B, n): ``(values (B, P), ok
    (B,))``. Rows are centred on the host (REML is invariant to a constant) and padded to the
    template's length; ``start`` (P,) or (B, P) is the Newton start of the rows."""
    frames = np.asarray(frames, dtype=float)
    b, n = frames.shape
    ys = np.zeros((b, template.ys.shape[1]))
    ys[:, :n] = frames - frames.mean(axis=1, keepdims=True)
    scale = np.broadcast_to(np.asarray(start, dtype=float), (b, len(template.layout.names)))
    val, ok = _refit_batch(template, jnp.asarray(ys), jnp.asarray(scale), int(max_iter))
    return np.asarray(val), np.asarray(ok)


def refit_start(values, temperature: float):
    """Newton start for the refits: the fit, eps^2 raised to ``_EPS2_START kT/k`` if below."""
    k, gamma, eps2 = (float(v) for v in values)
    kt = 1.380649e-23 * float(temperature)
    return np.array([k, gamma, max(eps2, _EPS2_START * kt / k)])


@dataclasses.dataclass(frozen=True)
class BootstrapCorrection:
    """Result of :func:`bootstrap_correct` (arrays over the parameters)."""

    estimate: np.ndarray  # the uncorrected estimate
    corrected: np.ndarray
    bias: np.ndarray  # the bias subtracted (estimate - corrected before validity fixes)
    bias_se: np.ndarray  # Monte Carlo standard error of the bootstrap bias
    n_boot: int
    iterations: int


#: what a parameter's corrected value must satisfy (see :func:`_keep_valid`)
SUPPORTS = ("real", "nonnegative", "positive")


def _keep_valid(c, est, support):
    """``c`` kept in each parameter's ``support``: a ``"nonnegative"`` one (eps^2) below 0 is
    clipped to 0 (its bound); a ``"positive"`` one (k, gamma) at or below 0 takes the ratio
    form ``est^2 / (2 est - c)`` (positive, the same first-order correction)."""
    c = np.array(c, dtype=float)
    for j, kind in enumerate(support):
        if kind == "nonnegative" and c[j] < 0:
            c[j] = 0.0
        elif kind == "positive" and not c[j] > 0:
            c[j] = est[j] ** 2 / (2 * est[j] - c[j])
    return c


def bootstrap_correct(estimate, simulate_refit: Callable, key, n_boot: int, *,
                      iterate: bool = False, support=None) -> BootstrapCorrection:
    """Parametric-bootstrap bias correction of ``estimate`` (P,).

    ``simulate_refit(theta, key, n_boot)`` must simulate ``n_boot`` data sets from the
    parameters ``theta`` with the PRNG ``key`` and return the same estimator's values on each,
    shape (n_boot, P) (NaN rows are dropped). The bias ``b(theta) = mean(refits) - theta`` is
    estimated at the estimate and ``corrected = estimate - b(estimate)``; with ``iterate``
    once more at that corrected value, ``corrected = estimate - b(corrected)`` (one step of the
    fixed point ``theta = estimate - b(theta)``, a new key ``fold_in(key, 1)``). ``support``:
    one of :data:`SUPPORTS` per parameter (default all ``"real"``), kept by
    :func:`_keep_valid`.
    """
    est = np.asarray(estimate, dtype=float)
    if est.ndim != 1 or not np.all(np.isfinite(est)):
        raise ValueError(f"estimate must be a finite 1-D array; got estimate = {estimate!r}")
    if isinstance(n_boot, bool) or not isinstance(n_boot, (int, np.integer)) or n_boot < 2:
        raise ValueError(f"n_boot must be an integer >= 2; got n_boot = {n_boot!r}")
    support = ("real",) * est.size if support is None else tuple(support)
    if len(support) != est.size or any(s not in SUPPORTS for s in support):
        raise ValueError(f"support must name one of {SUPPORTS} for each of the {est.size} "
                         f"parameters; got support = {support!r}")

    def bias_at(theta, k):
        r = np.asarray(simulate_refit(theta, k, int(n_boot)), dtype=float).reshape(n_boot, -1)
        r = r[np.all(np.isfinite(r), axis=1)]
        if r.shape[0] < 2:
            raise ValueError("bootstrap: fewer than 2 refits succeeded")
        return r.mean(0) - theta, r.std(0, ddof=1) / np.sqrt(r.shape[0])

    b, se = bias_at(est, key)
    c = _keep_valid(est - b, est, support)
    if iterate:
        b, se = bias_at(c, jax.random.fold_in(key, 1))
        c = _keep_valid(est - b, est, support)
    return BootstrapCorrection(est, c, b, se, int(n_boot), 2 if iterate else 1)
