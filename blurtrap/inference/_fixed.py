r"""Fits with some parameters held at given values (``calibrate(..., fixed={...})``), and the
propagation of the given values' uncertainties into the errors of the fitted ones.

Holding a parameter is a reduced objective: ``nll_fixed(q, args) = nll(p(q), args.inner)``
with ``p`` the full vector (the held entries from ``args.full``, the free ones from ``q``).
The reduced objective is a module-level function per original objective (cached), so the
fits compile once per problem shape as usual.

**Uncertainty of a held input.** If a held parameter ``x`` is known only to ``x0 +- s_x`` (a
bead radius +- 3 %, a viscosity, a temperature), the free estimate moves with it:
``q_hat(x) ~ q_hat(x0) + J (x - x0)`` with ``J = -H_qq^{-1} H_qx`` (implicit function
theorem at the optimum; ``H`` the Hessian of the negative log-likelihood in natural
parameters). The reported covariance is ``Cov(q) + J V_x J^T`` with the cross covariance
``J V_x`` and ``Var(x) = V_x``: the usual first-order propagation of an input error (its
bias is second order).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _chunked
from ._exact_chunks import exact_chunk_grads
from ._fit import FitOutput
from ._newton import FixedArgs, ReducedObjective


def reduced_objective(nll) -> ReducedObjective:
    """``nll`` with the held parameters of :class:`._newton.FixedArgs` inserted
    (:class:`._newton.ReducedObjective`: the full objective's own pass on the free
    parameters)."""
    return ReducedObjective(nll)


def parse_fixed(fixed, names) -> dict[str, tuple[float, float]]:
    """``{name: (value, standard error)}`` from ``fixed`` (``{name: value}`` or
    ``{name: (value, se)}``), checked against the model's parameter ``names``."""
    if fixed is None:
        return {}
    if not isinstance(fixed, dict):
        raise ValueError(f"fixed must be a dict {{parameter name: value or (value, se)}} (SI); "
                         f"got {type(fixed).__name__} {fixed!r:.80}")
    out = {}
    for name, spec in fixed.items():
        if names is not None and name not in names:
            raise ValueError(f"fixed names parameter {name!r}, which this model does not have; "
                             f"its parameters are {list(names)}")
        pair = isinstance(spec, (tuple, list)) and len(spec) == 2
        value, se = (spec[0], spec[1]) if pair else (spec, 0.0)
        checks: tuple[tuple[str, Any], ...] = (("value", value), ("standard error", se))
        for what, v in checks:
            if not (isinstance(v, numbers.Real) and not isinstance(v, bool)
                    and math.isfinite(float(v)) and float(v) >= 0):
                raise ValueError(f"fixed[{name!r}]: the {what} must be a finite number >= 0 "
                                 f"(SI); got {v!r}")
        if float(value) == 0 and name != "tracking_var":  # pyright: ignore[reportArgumentType]
            raise ValueError(f"fixed[{name!r}] = 0: only tracking_var may be held at 0; "
                             "the others are positive")
        out[name] = (float(value), float(se))  # pyright: ignore[reportArgumentType]
    if names is not None and len(out) == len(names):
        raise ValueError(f"fixed holds every parameter {list(names)}: nothing left to fit")
    return out


def reduce(names, scale, args, fixed: dict):
    """``(free indices, free scale, FixedArgs)`` for a fit of ``names`` with ``fixed`` held."""
    free = tuple(i for i, n in enumerate(names) if n not in fixed)
    full = np.asarray(scale, dtype=float).copy()
    for i, n in enumerate(names):
        if n in fixed:
            full[i] = fixed[n][0]
    positive = all(fixed[n][0] > 0 for n in names if n in fixed)
    return free, jnp.asarray(np.asarray(scale)[list(free)]), FixedArgs(args, jnp.asarray(full),
                                                                        free, positive)


def expand(out: FitOutput, free, n: int, full) -> FitOutput:
    """The reduced fit's output on the full parameter vector (held entries: their value,
    zero covariance, not at a bound). On the host (numpy): eager scatters compiled a small
    program each on a process's first held fit."""
    idx = np.asarray(free)
    value = np.array(full, dtype=float)
    value[idx] = np.asarray(out.value)

    def embed(c):
        e = np.zeros((n, n), dtype=float)
        e[np.ix_(idx, idx)] = np.asarray(c)
        return jnp.asarray(e)

    at_bound = None
    if out.at_bound is not None:
        at_bound = np.zeros(n, dtype=bool)
        at_bound[idx] = np.asarray(out.at_bound)
        at_bound = jnp.asarray(at_bound)
    return FitOutput(value=jnp.asarray(value), cov=embed(out.cov), nll=out.nll, grad_norm=out.grad_norm,
                     n_steps=out.n_steps, success=out.success, converged=out.converged,
                     hessian_pd=out.hessian_pd, at_bound=at_bound, result=out.result,
                     cov_given_bound=(None if out.cov_given_bound is None
                                      else embed(out.cov_given_bound)), conditional=out.conditional)


_GRADS: dict = {}


def _grad_fn(nll):
    if nll not in _GRADS:
        _GRADS[nll] = eqx.filter_jit(jax.vmap(jax.grad(nll), in_axes=(0, None)))
    return _GRADS[nll]


def _grads(nll, pts, args) -> np.ndarray:
    """The gradients of ``nll`` at the rows of ``pts`` (P, n), numpy. The batch is padded
    with copies of the first row to the power of two at or above ``max(P, 2 n + 1)``, so the
    propagation of held errors (2 points per held input) and the held-value test's exact
    gradient (1) and Whittle information (2 n + 1) share one compiled gradient per objective
    and shape (a hydrodynamic model's took ~4 s to compile; a few more evaluations cost
    milliseconds). The Whittle objective's gradient is summed over its ordinate chunks
    (:mod:`._chunked`), the exact likelihood's carried through its frame chunks
    (:mod:`._exact_chunks`), so a record of a new length compiles nothing here (the exact
    one compiled ~2 s per padded length before)."""
    pts = np.asarray(pts, dtype=float)
    size = 1 << (max(len(pts), 2 * pts.shape[1] + 1) - 1).bit_length()
    padded = jnp.asarray(np.concatenate([pts, np.repeat(pts[:1], size - len(pts), axis=0)]))
    fn = _grad_fn(nll)
    framed = exact_chunk_grads(nll, args)
    if _chunked.objective_chunkable(nll, args):  # a sum over ordinates: a new length
        out = np.sum([np.asarray(fn(padded, c), dtype=float)  # compiles nothing
                      for c in _chunked.ordinate_chunks(args)], axis=0)
    elif framed is not None:  # the exact likelihood carried through its frame chunks
        out = np.asarray(framed(padded, None)[1], dtype=float)
    else:
        out = np.asarray(fn(padded, args), dtype=float)
    return out[:len(pts)]


def propagate(nll, args, value, cov, names, fixed: dict, rel_step=1e-4):
    """The covariance with the held inputs' standard errors propagated (module docstring).
    ``value``/``cov``: full vector and covariance with zero rows for the held entries;
    ``args``: the original (full) objective's args. Unchanged when no held input has an
    error."""
    cov = np.array(cov, dtype=float)
    held = [i for i, n in enumerate(names) if n in fixed and fixed[n][1] > 0]
    if not held:
        return cov
    value = np.asarray(value, dtype=float)
    free = [i for i, n in enumerate(names) if n not in fixed]
    pts = []
    steps = []
    for i in held:
        h = rel_step * abs(value[i])
        steps.append(h)
        for s in (h, -h):
            p = value.copy()
            p[i] += s
            pts.append(p)
    grads = _grads(nll, np.stack(pts), args)
    # H[free, x]: d/dx of the free gradient, by central differences of the exact gradient
    h_fx = np.stack([(grads[2 * j][free] - grads[2 * j + 1][free]) / (2 * steps[j])
                     for j in range(len(held))], axis=-1)
    c_ff = cov[np.ix_(free, free)]
    c_ff = np.where(np.isfinite(c_ff), c_ff, 0.0)  # a parameter at its bound stays there
    jac = -c_ff @ h_fx  # (free, held): J = -H_ff^{-1} H_fx
    v_x = np.diag([fixed[names[i]][1] ** 2 for i in held])
    add = np.zeros_like(cov)
    add[np.ix_(free, free)] = jac @ v_x @ jac.T
    add[np.ix_(free, held)] = jac @ v_x
    add[np.ix_(held, free)] = (jac @ v_x).T
    add[np.ix_(held, held)] = v_x
    return cov + add


#: a held tracking_var above 0 but below this [m^2] (eps = 0.1 pm) is a unit slip, not a
#: tracking error: on the CLI, SI m^2 given to the nm^2 option (4e-18 "nm^2" = 4e-36 m^2)
MIN_NONZERO_TRACKING_VAR = 1e-26
#: parameters whose values are in the positions' unit (volts) when the positions are
_VOLT_SCALED = ("k", "c", "tracking_var", "drift_diffusion", "line_amplitude")


def check_plausible(held: dict, volts: bool = False) -> None:
    """A held value outside the physically plausible range of its quantity (the support of
    the default prior, ``Param.bounds``) is a ValueError naming the value in SI and in lab
    units: almost always a unit slip (SI into a lab-unit CLI option, or lab units in
    Python). Values in the positions' unit are not checked when the positions are volts."""
    from ..effects import QUANTITIES

    for name, (value, _) in held.items():
        base = name.split("[")[0]
        q = QUANTITIES.get(base)
        if q is None or q.bounds is None or (volts and base in _VOLT_SCALED):
            continue
        tiny = base == "tracking_var" and 0.0 < value < MIN_NONZERO_TRACKING_VAR
        if not q.outside(value) and not tiny:
            continue
        rng = q.range_text()
        if tiny:
            rng = "0 (negligible tracking error) or " + dataclasses.replace(
                q, bounds=(MIN_NONZERO_TRACKING_VAR, q.bounds[1])).range_text()
        raise ValueError(
            f"fixed[{name!r}] = {value:g} {q.unit} ({value * q.lab_factor:g} {q.lab_unit}) is "
            f"outside the plausible range of the {q.description}, {rng}: this looks like a "
            f"unit slip. Python takes SI ({q.unit}); the CLI's --fix takes lab units "
            f"({q.lab_unit}), e.g. --fix {base}=<value in {q.lab_unit}>")


#: a held value is reported as disagreeing with the data when the score test's p is below
#: this: 1 % of fits with right held values get the note (it gives the p-value); a held gamma
#: from a bead diameter given as its radius gave p = 0.0014 (z = 3.2) on 65 536 camera frames
#: at dt = 1.75 tau where the free gamma is 3.1 SE from it, and k +58 %
HELD_TEST_ALPHA = 1e-2


def _score_and_information(nll, args, value, scale, fisher_args):
    """``(g, H)``: the exact gradient of ``nll`` at ``value`` and the expected (Whittle)
    information there, by central differences of the Whittle gradient on ``fisher_args``
    (forward ones at a bound 0); None when a step or an entry is not usable."""
    n = value.size
    steps = 1e-4 * np.maximum(np.abs(value), scale)
    if not np.all(steps > 0):
        return None  # no scale for a parameter at 0
    # central differences of the exact gradient; forward ones where the parameter is at or
    # near its lower bound 0 (eps^2 -> 0), where the objective is not defined below
    low = np.where(value - steps >= 0, -steps, 0.0)
    pts = [value]
    for i in range(n):
        for s in (steps[i], low[i]):
            p = value.copy()
            p[i] += s
            pts.append(p)
    pts = np.stack(pts)
    # the exact gradient at ``value`` only (a batch of one: the points above are for the
    # Whittle information, which is cheap; the exact likelihood's gradient may not be)
    g = _grads(nll, pts[:1], args)[0]
    # the expected information: the Whittle Hessian with the periodogram replaced by the
    # model spectrum at ``value``, sum_f w_f grad log S_f grad log S_f^T (positive
    # semi-definite however far the held value is from the data's optimum)
    from ._problems import spectral_nll

    grads = _grads(spectral_nll, pts, fisher_args)
    hess = np.stack([(grads[1 + 2 * i] - grads[2 + 2 * i]) / (steps[i] - low[i])
                     for i in range(n)])
    hess = 0.5 * (hess + hess.T)
    if not (np.all(np.isfinite(hess)) and np.all(np.isfinite(g))):
        return None
    return g, hess


def held_consistency_note(nll, args, value, scale, names, fixed: dict,
                          fisher_args, gof_p: float = 1.0) -> str | None:
    """A note when the data disagree with a held value (a score test), else None.

    At the constrained optimum ``value`` (held entries in place), each held parameter ``x``
    is released alone (the others stay held; a bead's gamma and hydrodynamic radius, both
    set by its radius, are released together). The one-step (Fisher scoring) estimate of
    its shift is ``d = -(H_J^{-1} g_J)_x``, with ``g`` the gradient of the negative
    log-likelihood ``nll`` and ``H`` the expected (Whittle) information at ``value``, over
    ``J`` = the free parameters and ``x`` (``fisher_args``: the fit's spectral args with the
    periodogram replaced by the model spectrum at ``value``). If the held value is right,
    ``d`` has variance ``(H_J^{-1})_xx + s_x^2`` (``s_x`` its given standard error), so
    ``z = d / sd`` is standard normal (Bonferroni over the directions tested). A gamma held
    at a bead diameter given as its radius (2x), or an SI value given to a lab-unit option,
    fails it; a gamma held because the data cannot fix it (dt >> tau) passes, since
    ``(H_J^{-1})_xx`` is
    then large. The test is local: a held value far off (k 100x) can make the data's
    information at it small, so a poor goodness of fit (``gof_p`` below
    :data:`HELD_TEST_ALPHA` / 10) with held values also gets a note naming them.
    ``None`` when neither applies."""
    held = [i for i, n in enumerate(names) if n in fixed]
    if not held:
        return None
    value = np.asarray(value, dtype=float)
    scale = np.abs(np.asarray(scale, dtype=float))
    derivs = _score_and_information(nll, args, value, scale, fisher_args)
    if derivs is None:
        return None
    g, hess = derivs
    rests = held_tracking_sentence(hess, value, scale, names, fixed)
    out = _consistency(g, hess, value, scale, names, fixed, held, gof_p)
    return " ".join(n for n in (out, rests) if n) or None


def held_tracking_sentence(hess, value, scale, names, fixed) -> str | None:
    """A sentence when eps^2 is held without an error and k rests on it more than k's error
    says: the free parameters' shift per nm^2 of the held eps^2 is ``-H_FF^-1 H_F,eps2``
    (expected information ``hess``; the implicit function at the constrained optimum). An
    independent pass: the slow-camera recipe (``--fix tracking_var=0``, W/tau = 55) with
    2 nm rms of tracking error gave k half the truth, 85 SE off, nothing said; at dt = 2 tau
    (frames resolving the motion) eps^2 held at 0 against 4 nm^2 gave k 9 SE off, gof p 0.85."""
    if "tracking_var" not in fixed or float(fixed["tracking_var"][1]) > 0:
        return None
    kname = next((nm for nm in names if nm == "k" or nm.startswith("k[")), None)
    if kname is None:
        return None
    h, ki = names.index("tracking_var"), names.index(kname)
    free = [i for i in range(len(names)) if names[i] not in fixed]
    if ki not in free:
        return None
    d = np.where(scale > 0, scale, 1.0)
    hff = hess[np.ix_(free, free)] * np.outer(d[free], d[free])
    try:
        hinv = np.linalg.inv(hff)
    except np.linalg.LinAlgError:
        return None
    shift = -(hinv @ (hess[free, h] * d[free] * 1e-18))  # per nm^2, in units of the scale
    c = free.index(ki)
    dk, se = float(shift[c] * d[ki]), float(math.sqrt(max(hinv[c, c], 0.0)) * d[ki])
    k = float(value[ki])
    if not (se > 0 and k > 0 and math.isfinite(dk)) or abs(dk) < se:
        return None
    return (f"k rests on the held tracking_var = {float(value[h]) * 1e18:.3g} nm^2 (held "
            f"without an error): holding it 1 nm^2 larger (1 nm rms more tracking error) "
            f"changes {kname} by about {dk / k * 100:+.2g} % ({abs(dk) / se:.2g} SE), more than "
            "its error says, and the frames check it only weakly. "
            "Hold it with its uncertainty (fixed={'tracking_var': (value, se)}; CLI --fix "
            "tracking_var=V+-SE in nm^2) to carry it into k's error, or measure it (a bead "
            "stuck to the surface, or several exposures)")


def _consistency(g, hess, value, scale, names, fixed, held, gof_p) -> str | None:
    """The score test of :func:`held_consistency_note` (its docstring)."""
    n = value.size
    free = [i for i in range(n) if i not in held]
    # directions to release, one at a time (the others stay held): each held parameter, or
    # for a bead radius that sets both gamma (Stokes) and the hydrodynamic radius, the two
    # together
    dirs = []
    tied = "gamma" in fixed and "hydro_radius" in fixed  # both from the bead's radius
    for i in held:
        if tied and names[i] in ("gamma", "hydro_radius"):
            continue
        u = np.zeros(n)
        u[i] = value[i] if value[i] > 0 else scale[i]
        dirs.append((names[i], f"{names[i]} = {value[i]:.4g}", u, fixed[names[i]][1] / u[i]))
    if tied:
        u = np.zeros(n)
        for nm in ("gamma", "hydro_radius"):
            u[names.index(nm)] = value[names.index(nm)]
        rel = math.hypot(*(fixed[nm][1] / fixed[nm][0] for nm in ("gamma", "hydro_radius")))
        dirs.append(("bead radius", "the bead radius (gamma and hydro_radius together)", u,
                     rel))
    d = np.where(scale > 0, scale, 1.0)
    parts, informative = [], False
    for what, shown, u, rel_se in dirs:
        # the released direction's coefficient t (relative change): J = free + [t]
        basis = np.zeros((n, len(free) + 1))
        for c, i in enumerate(free):
            basis[i, c] = d[i]  # in units of the scale: the parameters span many decades
        basis[:, -1] = u
        h = basis.T @ hess @ basis
        try:
            hinv = np.linalg.inv(h)
        except np.linalg.LinAlgError:
            continue
        var = hinv[-1, -1] + rel_se**2
        if not (np.all(np.isfinite(hinv)) and var > 0):
            continue
        z = float(-(hinv[-1] @ (basis.T @ g)) / math.sqrt(var))
        informative |= math.sqrt(var) < 0.5  # the data fix it to better than 50 %
        p = float(math.erfc(abs(z) / math.sqrt(2.0)))
        if np.all(value[u > 0] == 0):  # held at its bound 0: one-sided, only larger values
            p = 0.5 * p if z > 0 else 1.0
        if p * len(dirs) < HELD_TEST_ALPHA:  # Bonferroni over the directions tested
            parts.append(f"{shown} (the data favour a {'larger' if z > 0 else 'smaller'} "
                         f"value: {abs(z):.3g} SE away, p = {p:.2g})")
    if not parts:
        # a poor fit is pinned on the held values only where the local test could not
        # judge them (little information at the held point)
        if gof_p < 0.1 * HELD_TEST_ALPHA and not informative:
            shown = ", ".join(f"{names[i]} = {value[i]:.4g}" for i in held)
            return (f"the fit with {shown} held fits the spectrum poorly (goodness of fit "
                    f"p = {gof_p:.2g}): a wrong held value (or unit: SI in Python, lab units "
                    "on the CLI) is one cause; compare with a fit that does not hold it")
        return None
    hint = ("; for gamma or the bead radius check it (a diameter given as bead_radius_m doubles "
            "gamma), viscosity, temperature and distance to the surface, or fit it "
            "(friction='free')" if any(names[i] == "gamma" for i in held) else "")
    return ("held values disagree with the data (score test, each released alone"
            + (f", Bonferroni over {len(dirs)}" if len(dirs) > 1 else "")
            + f"): {'; '.join(parts)}. A wrong held value biases "
            f"the fitted parameters: check its value and unit (SI in Python, lab units on "
            f"the CLI){hint}")
