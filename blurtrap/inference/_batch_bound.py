"""The items of :func:`blurtrap.calibrate_batch` with a parameter at its lower bound 0: their
other errors become the unconstrained Cramer-Rao bound at the estimate, as ``calibrate``'s
(:func:`blurtrap.inference._fit.release_bound`): the inverse of the full natural-parameter
information, the bound parameter counted as free. Decided on the host after the fits; only
the at-bound rows are touched (their periodograms are recomputed, one vmapped Hessian call
per group of rows)."""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np

from ._batch_host import _prepare
from ._bound_errors import bound_units, cov_from_hessian, natural_hessian
from ._problems import SpectralArgs, spectral_nll


@eqx.filter_jit
def _hessians(value, s, at_bound, power, log_ref, shared: SpectralArgs):
    """Natural-parameter Hessians (units ``s``) of each row's Whittle / Gamma objective."""

    def one(v, s_, ab, pw, lr):
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw, lr))
        return natural_hessian(spectral_nll, v, a, s_, ab)

    return jax.vmap(one)(value, s, at_bound, power, log_ref)


def _padded(n: int, cap: int) -> int:
    """Rows per call: the next power of two >= n (at least 8, at most ``cap``), so that few
    shapes are compiled."""
    size = 8
    while size < n and size < cap:
        size *= 2
    return size


def release_bound_rows(rows, y, val, cov, shared: SpectralArgs, acq, n_blocks, m,
                       check_units: bool, cap: int):
    """For the items ``rows`` (each with a parameter at its bound: NaN variance there), set
    ``cov`` (in place) to the unconstrained covariance where the full information is
    positive definite. Returns a bool per item of the batch: True where the errors stay
    conditional on the bound (the full information was not positive definite)."""
    conditional = np.zeros(val.shape[0], bool)
    rows = np.asarray(rows, dtype=int)
    if rows.size == 0:
        return conditional
    dt, w, t = acq
    for i0 in range(0, rows.size, cap):
        idx = rows[i0:i0 + cap]
        power, starts, log_ref, _, _ = _prepare(y[idx], n_blocks, m, dt, w, t,
                                                shared.model.noise, check_units)
        bound = np.isnan(np.diagonal(cov[idx], axis1=1, axis2=2))
        s = bound_units(starts, val[idx], bound)
        size = _padded(idx.size, cap)
        pad = size - idx.size  # repeat the first row: one compiled shape per size

        def rep(z):
            return np.concatenate([z, np.repeat(z[:1], pad, axis=0)]) if pad else z

        h = np.asarray(_hessians(rep(val[idx]), rep(s), rep(bound), rep(power[:, None, :]),
                                 rep(log_ref), shared))[:idx.size]
        new, pd = cov_from_hessian(h, s, bound)
        cov[idx[pd]] = new[pd]
        conditional[idx[~pd]] = True
    return conditional
