"""Profile-likelihood confidence intervals, for parameters whose Wald interval is not honest.

The 95 % likelihood-ratio interval of parameter ``i`` is ``{psi : nll_p(psi) - nll_min <=
1.92}`` with the profile ``nll_p(psi) = min over the others of nll(theta | theta_i = psi)``.
Unlike the Wald interval (estimate +- 1.96 SE) it follows a non-quadratic likelihood and it
handles a bound: every profile fit keeps all parameters positive, and for a parameter whose
profile at 0 is within 1.92 of the minimum (eps^2 at or near 0) the interval starts at 0.

Where the objective's pass runs in fixed-size chunks (the Whittle objective, the exact
likelihood) the same algorithm runs with its loops on the host over that pass
(:mod:`._profile_host`): a recording of a new length compiles nothing for its intervals.
For the other objectives everything runs in one jitted function per problem shape, vmapped
over (parameter, side),
with a single traced Newton fit (the minimum is the first pass of every end point's loop, a
restart from a bound the second pass of the fit's own loop: the compiled program is ~2-3x
smaller than with separate copies):
each end point is a bracketed root find (step out, then Illinois regula falsi) of the signed
root ``sqrt(2 (nll_p - nll_min)) - 1.96`` in the parameter's natural units, each evaluation a
constrained Newton fit (:func:`blurtrap.inference._fit._newton_iterate` with the parameter
held: its gradient row zeroed, its Hessian row the identity) warm-started from the previous
one: typically 3-5 fits of 1-3 Newton passes per end point. The objective's own fast pass is
used (the closed-form Whittle pass of :func:`blurtrap.inference._problems.spectral_newton_plan`),
or for objectives whose second-order autodiff graph is expensive (the exact time-domain
likelihood) a Hessian from central differences of the exact gradient.

Which intervals are profiled (:class:`ProfileIntervals`): all parameters when one is at its
bound or its Wald interval reaches below 0 (the bound then matters for every correlated
parameter); otherwise a parameter whose likelihood, evaluated at the two ends of its Wald
interval along the linearised profile path (the others moved by their regression on it),
is not within ``WALD_TOL`` (in units of the signed root) of the 1.92 drop a quadratic
likelihood has there. Elsewhere the Wald interval stays.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._fit import _autodiff_pass, _newton_iterate, _plan, at_lower_bound
from ._newton import fd_hessian_pass
from ._profile_host import chunked_pass, chunked_values, host_profile_ends, wald_path_roots

#: two-sided 95 % normal quantile and the likelihood drop at a 95 % interval end (chi^2_1)
Z95 = 1.959963984540054
DROP = 0.5 * Z95 * Z95
#: the Wald interval is kept when the signed root of the likelihood drop at both of its ends
#: is within this of 1.96 (a coverage change of ~0.5 % at most)
WALD_TOL = 0.05
#: x = log(p / scale) standing for p = 0 (p = 1e-30 scale: the likelihood is flat there)
_LOG_ZERO = -69.0
#: the lower side's last trial, "p = 0", is evaluated at this fraction of the estimate: a
#: model degenerates at k or gamma = 0 itself (tau = gamma / k of 1e30 frames: rho rounds to
#: 1), while a drop still below 1.92 there puts the end at 0 all the same (the profile of k
#: on a record ~10 relaxation times long is flat towards free diffusion: its lower end was
#: "not converged" in 81 of 98 fits)
_ZERO_FRACTION = 1e-6
#: root-find tolerance on the signed root (|drop - 1.92| < ~4e-4) and iteration caps
_ROOT_TOL = 2e-4
_ROOT_STEPS = 24
_NEWTON_STEPS = 32
_FD_STEP = 1e-4
#: a profile fit whose remaining decrease along a direction running into a bound is below
#: ~1e-7 nats (far below the 4e-4 root tolerance) is converged
_FLAT_ATOL = 1e-7


def fd_pass(nll, h=_FD_STEP):
    """A Newton pass whose Hessian is the central difference of the exact JAX gradient
    (:func:`blurtrap.inference._newton.fd_hessian_pass`, as ``fit_ml_fd_newton`` uses)."""
    return fd_hessian_pass(nll, h)


def _pass(nll, args, hessian):
    if hessian == "fd":
        return fd_pass(nll)
    if hessian == "autodiff":
        return _autodiff_pass(nll)
    return _plan(nll, args)[0]


def _held(pass_fn):
    """The pass of the objective with the parameters in ``mask`` held at ``t`` (in x)."""

    def f(x, scale, cargs):
        args, mask, t = cargs
        v, g, h = pass_fn(jnp.where(mask, t, x), scale, args)
        keep = ~mask[:, None] & ~mask[None, :]
        return (v, jnp.where(mask, 0.0, g),
                jnp.where(keep, h, jnp.eye(x.shape[0], dtype=h.dtype)))

    return f


def _fit_held(held, scale, args, mask, t, x0, x_lift, tol=1e-9):
    """Minimum over the free parameters with ``x[mask] = t``: (value, x at the minimum, ok).

    In log parameters a parameter driven to its bound (u -> 0) cannot come back by itself
    (its log-space gradient u f' vanishes with u), and the likelihood can have a second,
    lower minimum inside (measured: an exact-likelihood profile of gamma with eps^2 = 0 at
    the estimate stopped at the bound with a drop of 1.92 where the true profile drop was
    0.71). So a fit that ends with a free parameter at its bound
    (:func:`blurtrap.inference._fit.at_lower_bound`) is restarted with that parameter at
    ``x_lift`` (its estimate, or for one at its bound at the estimate the distance at which
    its profile rises by 1.92), and the lower of the two minima kept."""

    def run(x_start):
        x, v, g, h, dx, _, done, _ = _newton_iterate(held, scale, (args, mask, t), x_start,
                                                     tol, tol, _NEWTON_STEPS,
                                                     flat_atol=_FLAT_ATOL)
        trapped = at_lower_bound(g, h) & ~mask
        return v - 0.5 * jnp.dot(g, dx), jnp.where(mask, t, x - dx), done, trapped

    # one traced Newton fit (compilation cost): the loop runs it from x0 and, when a free
    # parameter ended at its bound, once more from the lifted start, keeping the lower one
    def body(st):
        v1, x1, d1, start, first, _ = st
        v2, x2, d2, tr = run(start)
        take = first | (d2 & (v2 < v1))
        return (jnp.where(take, v2, v1), jnp.where(take, x2, x1),
                jnp.where(first, d2, d1 | d2), jnp.where(tr, x_lift, x2),
                jnp.zeros_like(first), first & jnp.any(tr))

    z = jnp.zeros((), x0.dtype)
    init = (z, x0, jnp.asarray(False), x0, jnp.asarray(True), jnp.asarray(True))
    v, x, done, _, _, _ = jax.lax.while_loop(lambda st: st[5], body, init)
    return v, x, done


def _end_point(held, scale, args, x_hat, at_bound, i_mask, side, d1, slope, x_lift):
    """Distance ``d >= 0`` from the estimate ``theta_i`` (natural units) to the interval end
    on ``side`` (+1 / -1): the root of ``sqrt(2 (nll_p - v_min)) - 1.96``, or the bound 0
    (lower side) when the profile there is still within 1.92 of the minimum. ``slope``:
    d theta / d theta_i along the linearised profile (warm starts: each profile fit starts
    from the previous one moved along it).

    The loop's first pass is the unconstrained minimum from ``x_hat`` (``v_min``, with the
    same Newton fit and tolerances as the profile fits), so that the program holds a single
    traced fit: every (parameter, side) lane repeats that short, warm-started fit instead of
    a second copy of the fit being compiled. Returns ``(d, ok, theta_i, v_min)``."""
    sc_i = jnp.sum(jnp.where(i_mask, scale, 0.0))

    def body(st):
        (d_a, g_a, d_b, g_b, have_b, d, x, it, done, ok, last, d_prev,
         v_min, th_i, d_max) = st
        first = it == 0
        # the trial: the held profile fit at th_i + side d (the minimum on the first pass)
        psi = jnp.maximum(th_i + side * d, _ZERO_FRACTION * th_i)
        t = jnp.where(first, 0.0, jnp.maximum(jnp.log(jnp.maximum(psi, 0.0) / sc_i), _LOG_ZERO))
        p_now = scale * jnp.exp(x)
        p0 = p_now + side * (d - d_prev) * slope
        # below half its value, the same regression on log scale (``_profile_host``)
        psi_prev = jnp.maximum(th_i + side * d_prev, _ZERO_FRACTION * th_i)
        ratio = jnp.log(jnp.maximum(psi, 1e-300) / jnp.maximum(psi_prev, 1e-300))
        log_step = jnp.where((psi_prev > 0) & (psi > 0), jnp.clip(
            slope * psi_prev / jnp.maximum(p_now, 1e-300) * ratio, -10.0, 10.0), 0.0)
        moved = jnp.where(p0 > 0.5 * p_now, jnp.log(jnp.maximum(p0, 1e-300) / scale),
                          x + log_step)
        v, x_new, ok_fit = _fit_held(held, scale, args, i_mask & ~first, t,
                                     jnp.where(first, x_hat, moved), x_lift)
        # first pass: the minimum, the estimate theta_i and the lower side's bound 0
        theta = jnp.where(at_bound, 0.0, scale * jnp.exp(x_new))
        th_new = jnp.sum(jnp.where(i_mask, theta, 0.0))
        v_min = jnp.where(first, v, v_min)
        th_i = jnp.where(first, th_new, th_i)
        d_max = jnp.where(first, jnp.where(side < 0, th_new, jnp.inf), d_max)
        g = jnp.sqrt(2.0 * jnp.maximum(v - v_min, 0.0)) - Z95
        ok = ok & ok_fit & jnp.isfinite(g)
        at_max = (g < 0) & (d >= d_max)
        hit = ~first & ((jnp.abs(g) < _ROOT_TOL) | at_max)
        lower = g < 0  # replaces the inner end a
        # Illinois: when the same end is replaced twice in a row, halve the other's value
        upd = ~first
        g_b = jnp.where(upd & lower & (last == 0), 0.5 * g_b, g_b)
        g_a = jnp.where(upd & ~lower & (last == 1), 0.5 * g_a, g_a)
        d_a, g_a = jnp.where(upd & lower, d, d_a), jnp.where(upd & lower, g, g_a)
        d_b, g_b = jnp.where(upd & ~lower, d, d_b), jnp.where(upd & ~lower, g, g_b)
        have_b = have_b | (upd & ~lower)
        # next trial: regula falsi inside a bracket; else step out (the signed root grows
        # like d near an interior optimum and like sqrt(d) at a bound: scaling d by
        # (1.96 / r)^2 overshoots both, which brackets the root next time)
        r = jnp.maximum(g + Z95, 1e-3)
        d_out = jnp.minimum(d * jnp.clip((Z95 / r) ** 2, 1.5, 16.0), d_max)
        d_in = d_b - g_b * (d_b - d_a) / (g_b - g_a)
        d_in = jnp.where(jnp.isfinite(d_in) & (d_in > d_a) & (d_in < d_b), d_in,
                         0.5 * (d_a + d_b))
        narrow = have_b & (d_b - d_a <= 1e-12 * (jnp.abs(th_i) + d_b))
        d_next = jnp.where(first, jnp.minimum(d1, d_max), jnp.where(have_b, d_in, d_out))
        done = hit | narrow | ~ok
        d_res = jnp.where(hit, jnp.minimum(d, d_max), jnp.where(narrow, d_b, d))
        d_next = jnp.where(done, d_res, d_next)
        return (d_a, g_a, d_b, g_b, have_b, d_next, x_new, it + 1, done, ok,
                jnp.where(first, last, jnp.where(lower, 0, 1)), jnp.where(first, 0.0, d),
                v_min, th_i, d_max)

    def cond(st):
        return ~st[8] & (st[7] < _ROOT_STEPS + 1)

    z = jnp.zeros((), x_hat.dtype)
    init = (z, -Z95 + z, z, z, jnp.asarray(False), z, x_hat, jnp.asarray(0),
            jnp.asarray(False), jnp.asarray(True), jnp.asarray(-1), z, z, z, z)
    st = jax.lax.while_loop(cond, body, init)
    return st[5], st[9] & st[8], st[13], st[12]


@eqx.filter_jit
def _profile_ends(nll, args, scale, x_hat, cov, at_bound, hessian):
    """Lower and upper end points (natural units) of the profile 95 % interval of every
    parameter, with ok flags, all at once (vmapped over parameter and side)."""
    pass_fn = _pass(nll, args, hessian)
    held = _held(pass_fn)
    n = x_hat.shape[0]
    # first trial distances: 1.96 SE; at a bound, where the profile rises linearly with
    # slope f' = dnll/dp > 0, the distance of a drop of 1.92 on that line (the curvature
    # only shortens it); that distance is also where a parameter stuck at its bound in a
    # profile fit is restarted (see _fit_held)
    _, g_x, _ = pass_fn(x_hat, scale, args)
    fprime = g_x / (scale * jnp.exp(x_hat))
    d_bound = DROP / jnp.clip(fprime, 1e-300, None)
    theta_hat = scale * jnp.exp(x_hat)
    x_lift = jnp.log(jnp.where(at_bound, d_bound, theta_hat) / scale)
    se = jnp.sqrt(jnp.abs(jnp.diagonal(cov)))
    d1 = jnp.where(at_bound | ~jnp.isfinite(se), d_bound, Z95 * se)
    masks = jnp.concatenate([jnp.eye(n, dtype=bool), jnp.eye(n, dtype=bool)])
    sides = jnp.concatenate([-jnp.ones(n), jnp.ones(n)]).astype(x_hat.dtype)
    d1s = jnp.concatenate([d1, d1])

    # linearised profile path: the others move by cov[:, i] / cov_ii per unit of theta_i
    # (conditional on parameters at their bound, which stay)
    var = jnp.diagonal(cov)
    slopes = jnp.where(var[None, :] > 0, cov / jnp.where(var > 0, var, 1.0)[None, :], 0.0).T
    slopes = jnp.where(jnp.eye(n, dtype=bool) | at_bound[None, :], 0.0, slopes)
    slopes = jnp.concatenate([slopes, slopes])

    def one(mask, side, d1_, slope):
        return _end_point(held, scale, args, x_hat, at_bound, mask, side, d1_, slope, x_lift)

    d, ok, th, v_min = jax.vmap(one)(masks, sides, d1s, slopes)
    low = th[:n] - d[:n]
    high = th[n:] + d[n:]
    low = jnp.where(d[:n] >= th[:n], 0.0, low)
    return low, high, ok[:n], ok[n:], v_min[0]


@eqx.filter_jit
def _wald_path_roots(nll, args, value, cov):
    """Signed likelihood root at both ends of every Wald interval along the linearised
    profile path ``theta + delta cov[:, i] / cov_ii``, ``delta = +-1.96 SE_i`` (1.96 exactly
    for a quadratic likelihood; NaN where the path leaves the positive parameters)."""
    n = value.shape[0]
    v0 = nll(value, args)
    se = jnp.sqrt(jnp.diagonal(cov))
    steps = Z95 * cov / se[None, :]  # column i: the path's step for parameter i
    pts = jnp.concatenate([value[None] - steps.T, value[None] + steps.T])  # (2n, n)
    vals = jax.vmap(lambda p: nll(p, args))(pts)
    r = jnp.sqrt(2.0 * jnp.maximum(vals - v0, 0.0))
    good = jnp.all(pts > 0, axis=1) & jnp.isfinite(vals)
    r = jnp.where(good, r, jnp.nan)
    return r[:n], r[n:]


def _consts():
    return {"z95": Z95, "drop": DROP, "log_zero": _LOG_ZERO, "zero_fraction": _ZERO_FRACTION,
            "root_tol": _ROOT_TOL,
            "root_steps": _ROOT_STEPS, "newton_steps": _NEWTON_STEPS, "tol": 1e-9,
            "flat_atol": _FLAT_ATOL}


def needs_profile(nll, args, value, cov, at_bound, pass_fn=None, scale=None, values=None):
    """Which parameters need a profile interval (bool per parameter; see the module doc);
    with ``pass_fn`` (a chunked pass, :func:`._profile_host.chunked_pass`, at ``scale``)
    the likelihood along the Wald paths is evaluated with it (nothing compiled per length),
    or with ``values`` (:func:`._profile_host.chunked_values`) at all points at once."""
    value = np.asarray(value, float)
    cov = np.asarray(cov, float)
    at_bound = np.asarray(at_bound, bool)
    se = np.sqrt(np.abs(np.diag(cov)))
    if at_bound.any() or np.any(value - Z95 * se <= 0):
        return np.ones(value.size, bool)
    if not np.all(np.isfinite(cov)):
        return np.zeros(value.size, bool)
    if pass_fn is not None:
        lo, hi = wald_path_roots(pass_fn, scale, value, cov, Z95, values)
    else:
        lo, hi = _wald_path_roots(nll, args, jnp.asarray(value), jnp.asarray(cov))
        lo, hi = np.asarray(lo), np.asarray(hi)
    with np.errstate(invalid="ignore"):
        return ~((np.abs(lo - Z95) <= WALD_TOL) & (np.abs(hi - Z95) <= WALD_TOL))


def profile_intervals(nll, args, scale, value, cov, at_bound, hessian="auto"):
    """Profile 95 % intervals of every parameter: ``(low, high, ok)`` numpy arrays (natural
    units; ``ok`` False where a root find or a profile fit did not converge)."""
    low, high, ok_lo, ok_hi = profile_ends(nll, args, scale, value, cov, at_bound, hessian)
    return low, high, ok_lo & ok_hi


def profile_ends(nll, args, scale, value, cov, at_bound, hessian="auto", which=None):
    """:func:`profile_intervals` with an ok flag per end: ``(low, high, ok_low, ok_high)``;
    ``which`` (bool per parameter): only those are needed (the host loops compute only
    theirs; the compiled program, vmapped over all, computes every one)."""
    scale = jnp.asarray(scale)
    x_hat = jnp.log(jnp.maximum(jnp.asarray(value), 1e-300) / scale)
    x_hat = jnp.maximum(x_hat, _LOG_ZERO)
    cov = np.nan_to_num(np.asarray(cov, float), nan=0.0)
    pass_fn = chunked_pass(nll, args, hessian, _FD_STEP)
    if pass_fn is not None:  # loops on the host, pass in chunks: nothing compiled per length
        return host_profile_ends(pass_fn, scale, x_hat, cov, at_bound, _consts(), which)
    low, high, ok_lo, ok_hi, _ = _profile_ends(
        nll, args, scale, x_hat, jnp.asarray(cov), jnp.asarray(at_bound, bool), hessian)
    return np.asarray(low), np.asarray(high), np.asarray(ok_lo), np.asarray(ok_hi)


class ProfileIntervals:
    """A result's interval source (:attr:`CalibrationResult.intervals`): profile intervals for
    the parameters that need them (:func:`needs_profile`), computed on first use."""

    def __init__(self, nll, args, scale, value, cov, at_bound, hessian="auto"):
        self.nll, self.args, self.hessian = nll, args, hessian
        self.scale = np.asarray(scale, float)
        self.value = np.asarray(value, float)
        self.cov = np.asarray(cov, float)
        self.at_bound = np.asarray(at_bound, bool)

    def __call__(self, result):
        from .._config import float64_scope

        return float64_scope(self._compute)(result.param_names)

    def _compute(self, names):
        pass_fn = chunked_pass(self.nll, self.args, self.hessian, _FD_STEP)
        need = needs_profile(self.nll, self.args, self.value, self.cov, self.at_bound,
                             pass_fn, self.scale,
                             chunked_values(self.nll, self.args, self.hessian))
        if not need.any():
            return {}, {}
        low, high, ok_lo, ok_hi = profile_ends(self.nll, self.args, self.scale, self.value,
                                               self.cov, self.at_bound, self.hessian, need)
        ivs, kinds = {}, {}
        for j, name in enumerate(names):
            if need[j]:  # an end whose profile did not converge is NaN (the result fills it)
                ivs[name] = (float(low[j]) if ok_lo[j] else np.nan,
                             float(high[j]) if ok_hi[j] else np.nan)
                kinds[name] = "profile"
        return ivs, kinds
