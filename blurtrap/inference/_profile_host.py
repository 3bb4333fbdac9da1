"""Profile-likelihood intervals with every loop on the host, for the objectives whose pass
runs in fixed-size chunks (the Whittle objective in ordinate chunks, :mod:`._chunked`; the
exact and irregular-time likelihoods in frame chunks, :mod:`._exact_chunks`): a recording of
a new length then compiles nothing for its intervals either (the single program of
:func:`._profile._profile_ends` cost 5-6 s per new power-of-two bucket at 4096 frames
exact and 65 536 frames Whittle, and ran every lane for as long as the slowest).

The algorithm is :func:`._profile._end_point` and :func:`._profile._fit_held` step for step:
the same held Newton fits (:func:`._chunked.host_newton_loop`, the solver of the compiled
loop with the same tolerances), the same restart of a parameter trapped at its bound, the
same bracketed root find (step out, then Illinois regula falsi) of the signed root in the
parameter's natural units, the same first distances and warm starts along the linearised
profile path. The unconstrained minimum that each lane of the compiled program recomputes
as its first pass is computed once here and shared.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _chunked
from ._exact_chunks import exact_chunk_grads, exact_chunk_pass
from ._fit import at_lower_bound

#: profile intervals on the host over the chunked passes; False: the single compiled program
#: of :func:`._profile._profile_ends` (one per padded length), the previous way
HOST = True


def chunked_pass(nll, args, hessian, fd_step):
    """``pass(x, scale) -> (value, grad, hess)`` of ``nll`` in log parameters, summed over
    fixed-size chunks, or None where no chunked pass applies (other objectives; chunking or
    the host loops off)."""
    if not (HOST and _chunked.HOST_NEWTON):
        return None
    if hessian == "fd":
        return exact_chunk_pass(nll, args, fd_step)
    if hessian != "auto" or not _chunked.objective_chunkable(nll, args):
        return None
    chunks = _chunked.ordinate_chunks(args)

    def pass_fn(x, scale):
        n = x.shape[0]
        acc = (jnp.zeros((), x.dtype), jnp.zeros((n,), x.dtype), jnp.zeros((n, n), x.dtype))
        for c in chunks:
            acc = _chunked._chunk_pass(nll, x, scale, c, acc)
        return acc

    return pass_fn


def chunked_values(nll, args, hessian):
    """``values(xs, scale) -> (P,)``: ``nll`` at the points ``scale exp(xs)`` (P, n) in one
    sweep over the frame chunks (:func:`._exact_chunks.exact_chunk_grads`), or None where
    it does not apply (the Whittle pass: cheap per point; the host loops off)."""
    if not (HOST and _chunked.HOST_NEWTON) or hessian != "fd":
        return None
    grads = exact_chunk_grads(nll, args)
    if grads is None:
        return None
    return lambda xs, scale: grads(xs, scale)[0]


def wald_path_roots(pass_fn, scale, value, cov, z95, values=None):
    """:func:`._profile._wald_path_roots` from the chunked pass: the signed likelihood root
    at both ends of every Wald interval along the linearised profile path (NaN where the
    path leaves the positive parameters). With ``values`` (:func:`chunked_values`) the
    estimate and the 2n path points are evaluated in one sweep over the frames: 2n + 1
    points, the shape of the difference-Hessian pass, whose chunk program it reuses
    (pass by pass, each with its 2n + 1 points, they took 13 x a pass's time: ~20 s of the
    summary of a 122 880-frame joint fit, benchmarks/RESULTS.md "Profile intervals")."""
    n = value.size
    scale = np.asarray(scale, float)
    se = np.sqrt(np.diag(cov))
    steps = z95 * cov / se[None, :]
    pts = np.concatenate([value[None] - steps.T, value[None] + steps.T])
    good = np.all(pts > 0, axis=1)
    r = np.full(2 * n, np.nan)
    if values is not None:
        xs = np.log(np.concatenate([value[None], np.where(good[:, None], pts, value)]) / scale)
        vals = np.asarray(values(jnp.asarray(xs), jnp.asarray(scale)), float)
        v0, vals = float(vals[0]), np.where(good, vals[1:], np.nan)
    else:
        v0 = float(pass_fn(jnp.asarray(np.log(value / scale)), jnp.asarray(scale))[0])
        vals = np.full(2 * n, np.nan)
        for j in np.flatnonzero(good):
            vals[j] = float(pass_fn(jnp.asarray(np.log(pts[j] / scale)), jnp.asarray(scale))[0])
    for j in np.flatnonzero(good & np.isfinite(vals)):
        r[j] = math.sqrt(2.0 * max(vals[j] - v0, 0.0))
    return r[:n], r[n:]


class _HeldFits:
    """Held-parameter Newton fits of one objective (:func:`._profile._fit_held` on the
    host)."""

    def __init__(self, pass_fn, scale, consts):
        self.pass_fn, self.scale, self.c = pass_fn, jnp.asarray(scale), consts

    def _run(self, mask, t, x_start):
        def held(x):
            x = np.where(mask, t, np.asarray(x))
            v, g, h = self.pass_fn(jnp.asarray(x), self.scale)
            g = np.where(mask, 0.0, np.asarray(g))
            keep = ~mask[:, None] & ~mask[None, :]
            return v, g, np.where(keep, np.asarray(h), np.eye(x.size))

        tol = self.c["tol"]
        st, _ = _chunked.host_newton_loop(held, jnp.asarray(x_start), tol, tol,
                                          self.c["newton_steps"], self.c["flat_atol"])
        g, dx = np.asarray(st.grad), np.asarray(st.step)
        trapped = np.asarray(at_lower_bound(st.grad, st.hess)) & ~mask
        return (float(st.value) - 0.5 * float(g @ dx),
                np.where(mask, t, np.asarray(st.x) - dx), bool(st.done), trapped)

    def fit(self, mask, t, x0, x_lift):
        """Minimum over the free parameters with ``x[mask] = t``: ``(value, x, ok)``; a
        free parameter that ends at its bound is restarted at ``x_lift`` once, the lower
        converged minimum kept."""
        v, x, done, trapped = self._run(mask, t, x0)
        if trapped.any():
            v2, x2, d2, _ = self._run(mask, t, np.where(trapped, x_lift, x))
            if d2 and v2 < v:
                v, x = v2, x2
            done = done or d2
        return v, x, done


def _root_find(fits, scale, x_first, v_min, th_i, i, side, d1, slope, x_lift, c):
    """Distance from ``th_i`` to the interval end on ``side``: the loop of
    :func:`._profile._end_point` after its first pass. Returns ``(d, ok)``."""
    z95 = c["z95"]
    n = scale.size
    i_mask = np.arange(n) == i
    d_max = th_i if side < 0 else math.inf
    d_a, g_a, d_b, g_b, have_b = 0.0, -z95, 0.0, 0.0, False
    d, d_prev, last, x, ok = min(d1, d_max), 0.0, -1, x_first, True
    for _ in range(c["root_steps"]):
        psi = max(th_i + side * d, c["zero_fraction"] * th_i)  # "0": see _ZERO_FRACTION
        t = max(math.log(psi / scale[i]), c["log_zero"]) if psi > 0 else c["log_zero"]
        p_now = scale * np.exp(x)
        p0 = p_now + side * (d - d_prev) * slope
        # where the straight line would take a parameter below half its value, follow the
        # same regression on log scale (d log p = slope psi / p d log psi): left in place, a
        # friction at k / 3 led the held fit to the white-noise optimum (gamma 5e6 x) and
        # every later trial with it, so k's lower end came out at the estimate
        psi_prev = max(th_i + side * d_prev, c["zero_fraction"] * th_i)
        log_step = np.clip(slope * psi_prev / np.maximum(p_now, 1e-300)
                           * math.log(psi / psi_prev), -10.0, 10.0) if psi_prev > 0 else 0.0
        moved = np.where(p0 > 0.5 * p_now, np.log(np.maximum(p0, 1e-300) / scale),
                         x + log_step)
        v, x, ok_fit = fits.fit(i_mask, t, moved, x_lift)
        g = math.sqrt(2.0 * max(v - v_min, 0.0)) - z95
        ok = ok and ok_fit and math.isfinite(g)
        if not ok:
            return d, False
        if abs(g) < c["root_tol"] or (g < 0 and d >= d_max):
            return min(d, d_max), True
        lower = g < 0
        if lower:  # Illinois: the same end replaced twice in a row halves the other's value
            g_b = 0.5 * g_b if last == 0 else g_b
            d_a, g_a = d, g
        else:
            g_a = 0.5 * g_a if last == 1 else g_a
            d_b, g_b, have_b = d, g, True
        last = 0 if lower else 1
        if have_b and d_b - d_a <= 1e-12 * (abs(th_i) + d_b):
            return d_b, True
        d_prev = d
        if have_b:
            d_in = d_b - g_b * (d_b - d_a) / (g_b - g_a) if g_b != g_a else math.nan
            d = d_in if (math.isfinite(d_in) and d_a < d_in < d_b) else 0.5 * (d_a + d_b)
        else:
            r = max(g + z95, 1e-3)
            d = min(d * min(max((z95 / r) ** 2, 1.5), 16.0), d_max)
    return d, False


def host_profile_ends(pass_fn, scale, x_hat, cov, at_bound, consts, which=None):
    """:func:`._profile._profile_ends` on the host: ``(low, high, ok_low, ok_high)``
    (natural units) of every parameter's profile 95 % interval, or with ``which`` (bool per
    parameter) of those only (the others 0 and not ok). Each end's root find starts from
    the shared minimum, so an end is the same whichever others are computed; the ends not
    needed cost as much each (a 122 880-frame joint fit with two of six parameters
    profiled spent 100 of its 180 s on the eight ends it did not use)."""
    scale = np.asarray(scale, float)
    x_hat = np.asarray(x_hat, float)
    cov = np.asarray(cov, float)
    at_bound = np.asarray(at_bound, bool)
    n = x_hat.size
    _, g_x, _ = pass_fn(jnp.asarray(x_hat), jnp.asarray(scale))
    theta_hat = scale * np.exp(x_hat)
    with np.errstate(divide="ignore"):
        d_bound = consts["drop"] / np.clip(np.asarray(g_x) / theta_hat, 1e-300, None)
    x_lift = np.log(np.where(at_bound, d_bound, theta_hat) / scale)
    se = np.sqrt(np.abs(np.diag(cov)))
    d1 = np.where(at_bound | ~np.isfinite(se), d_bound, consts["z95"] * se)
    var = np.diag(cov)
    with np.errstate(invalid="ignore", divide="ignore"):
        slopes = np.where(var[None, :] > 0, cov / np.where(var > 0, var, 1.0)[None, :], 0.0).T
    slopes = np.where(np.eye(n, dtype=bool) | at_bound[None, :], 0.0, slopes)

    fits = _HeldFits(pass_fn, scale, consts)
    # the unconstrained minimum (each compiled lane's first pass), once for all lanes
    v_min, x_first, ok_first = fits.fit(np.zeros(n, bool), 0.0, x_hat, x_lift)
    theta = np.where(at_bound, 0.0, scale * np.exp(x_first))
    low, high = np.zeros(n), np.zeros(n)
    ok_lo, ok_hi = np.zeros(n, bool), np.zeros(n, bool)
    if not (ok_first and math.isfinite(v_min)):
        return low, high, ok_lo, ok_hi
    for i in range(n) if which is None else np.flatnonzero(which):
        for side in (-1.0, 1.0):
            d, ok = _root_find(fits, scale, x_first, v_min, float(theta[i]), i, side,
                               float(d1[i]), slopes[i], x_lift, consts)
            if side < 0:
                low[i], ok_lo[i] = (0.0 if d >= theta[i] else theta[i] - d), ok
            else:
                high[i], ok_hi[i] = theta[i] + d, ok
    return low, high, ok_lo, ok_hi
