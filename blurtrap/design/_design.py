"""``bt.design``: the acquisition that minimises the expected error of k and/or gamma.

Each candidate acquisition is a list of recordings (frame interval dt, exposure W, frames N);
its Fisher information is the sum of the recordings' (:mod:`._fisher`; shared k, gamma, eps^2;
with photon-limited noise eps^2 = eps_ref^2 W_ref / W, still one shared parameter). The
continuous choices (dt, W, and the exposures of a series) are optimised by gradients
(optimistix BFGS on unconstrained coordinates, several starts); the discrete ones (a single
recording, an exposure series of 2 or 3 exposures, the user's current design, W = dt at the
fastest frame rate, the paper's series) are compared on the same objective. With the available
laser powers given, power series are candidates too: recording i at p_i times the power k is
given at has k_i = k p_i (k = c P), so its information in (log c, ...) is its own in
(log k_i, ...), summed over the series like an exposure series'.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._config import float64_scope
from ..physics import BOLTZMANN
from ._bounds import bound_probability, bounded_covariance
from ._checks import (
    PAPER_SERIES,
    NotIdentifiedError,
    _check,
    _checked_friction,
    _checked_noise,
    check_timing,
    check_units_of,
    checked_budget,
    checked_current,
    checked_trap,
)
from ._checks import TARGETS as TARGETS  # the targets design accepts (re-exported)
from ._fisher import K_PAD, _informations, candidate_informations, padded
from ._power import checked_powers, power_candidates
from ._result import Acquisition, DesignResult

#: the relative SE standing for "exactly known friction" (its prior precision 1/SE^2 makes the
#: fit's log gamma fixed to rounding; the information of the data is ~1e4-1e10)
_EXACT_FRICTION_SE = 1e-12
#: a relative SE of k or gamma above this (100 %) means the design does not identify it
UNIDENTIFIED_SE = 1.0
#: exposure slots of the optimiser's program: series of up to 3 exposures share one
#: compilation (a single stiffness and a range of three are two programs: padding the
#: stiffnesses would triple every evaluation of a single-stiffness design)
N_SLOTS = 3


def _with_friction_prior(infos, friction_se):
    """The information plus a known friction's: precision ``1 / friction_se^2`` on log gamma
    (``friction_se`` < 0: friction fitted freely, nothing added)."""
    prec = jnp.where(friction_se < 0, 0.0,
                     1.0 / jnp.maximum(friction_se, _EXACT_FRICTION_SE) ** 2)
    return infos.at[:, 1, 1].add(prec)


def relative_covariance(recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited, noise,
                        friction_se=-1.0, bounded=True):
    """Covariance (n_k, n_par, n_par) of log k, log gamma[, log eps^2] at each stiffness in
    ``ks`` (inverse Whittle information; ``friction_se`` >= 0: the friction is known to that
    relative SE, 0 = exactly, and enters as prior information on log gamma; ``bounded``: the
    scatter of the fit with eps^2 >= 0, :func:`bounded_covariance`, else the unconstrained
    Cramer-Rao bound)."""
    infos = _informations(recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited, noise)
    cov = jnp.linalg.inv(_with_friction_prior(infos, jnp.asarray(friction_se, dtype=float)))
    return bounded_covariance(cov) if bounded else cov


def relative_se(recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited, noise,
                friction_se=-1.0, bounded=True):
    """Relative SEs (n_k, n_par) of log k, log gamma[, log eps^2] of the recordings ``recs``
    ((dt, W, N) each; shared k, gamma, eps^2) at each stiffness in ``ks``: one vmapped
    evaluation over recordings and stiffnesses (jitted below for the host-side candidates).
    ``friction_se``, ``bounded``: as :func:`relative_covariance`."""
    cov = relative_covariance(recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited,
                              noise, friction_se, bounded)
    return jnp.sqrt(jnp.diagonal(cov, axis1=-2, axis2=-1))


def force_sensitivity_se(free_cov, friction_se):
    """Relative SE of the force sensitivity Rf = k Rd of a passive calibration in detector
    units (volts) with the friction gamma0 known to relative SE ``friction_se``: the fit in
    volts has k' = k Rd^2 and gamma' = gamma0 Rd^2 free, so Rf = k' sqrt(gamma0 / gamma') and
    var(log Rf) = v_kk + v_gg / 4 - v_kg + friction_se^2 / 4 (``free_cov``: covariance of the
    free-friction fit, (n_k, n_par, n_par))."""
    v = free_cov[:, 0, 0] + free_cov[:, 1, 1] / 4.0 - free_cov[:, 0, 1]
    return jnp.sqrt(v + jnp.maximum(friction_se, 0.0) ** 2 / 4.0)


def _target_per_k(infos, target, friction_se):
    """The target's relative SE at each stiffness, from the data's information."""
    if target == "force_sensitivity":
        return force_sensitivity_se(bounded_covariance(jnp.linalg.inv(infos)), friction_se)
    cov = bounded_covariance(jnp.linalg.inv(_with_friction_prior(infos, friction_se)))
    if target == "k":
        return jnp.sqrt(cov[:, 0, 0])
    if target == "gamma":
        return jnp.sqrt(cov[:, 1, 1])
    if target == "both":
        return (cov[:, 0, 0] * cov[:, 1, 1]) ** 0.25
    return jnp.linalg.det(cov[:, :2, :2]) ** 0.25  # determinant (D-optimal), SE units


def _objective(infos, target, friction_se):
    return jnp.max(_target_per_k(infos, target, friction_se))


class _Problem(eqx.Module):
    """Recordings at a common frame interval (at the relative laser powers ``powers``), as a
    function of unconstrained coordinates ``u = (log(dt/dt_min - 1), logit of each exposure
    in [w_min, dt - dead])``. The program has ``n_slots`` exposure slots whatever the
    series' length (one compilation for series of 1, 2 and 3 exposures): a slot that is not
    ``active`` is a recording of one frame, whose Whittle information ((N - 1) times the
    mean) is exactly zero, so its coordinate has no gradient and stays where it starts."""

    dt_min: jax.Array
    w_min: jax.Array
    dead: jax.Array
    budget: jax.Array  # frames per recording, or the total time [s]
    ks: jax.Array
    gamma: jax.Array
    temperature: jax.Array
    eps_ref2: jax.Array
    w_ref: jax.Array
    friction_se: jax.Array  # < 0: friction fitted; >= 0: known to this relative SE
    powers: jax.Array  # (n_slots,) laser power of each recording / the power k is given at
    active: jax.Array  # (n_slots,) bool: the slot is one of the series' recordings
    total_time: jax.Array  # bool: ``budget`` is the total time (else frames per recording)
    photon_limited: jax.Array  # bool: eps^2 = eps_ref^2 w_ref / W
    n_slots: int = eqx.field(static=True)
    target: str = eqx.field(static=True)
    noise: bool = eqx.field(static=True, default=True)  # log eps^2 is a parameter

    def recs(self, u):
        u = jnp.clip(u, -30.0, 30.0)
        dt = self.dt_min * (1.0 + jnp.exp(u[0]))
        ws = self.w_min + jax.nn.sigmoid(u[1:]) * (dt - self.dead - self.w_min)
        n_rec = jnp.sum(self.active)
        n = jnp.where(self.total_time, self.budget / dt / n_rec, self.budget)
        ns = jnp.where(self.active, n, 1.0)
        return [(dt, ws[i], ns[i], self.powers[i]) for i in range(self.n_slots)]


def _log_objective(u, prob: _Problem):
    infos = _informations(prob.recs(u), prob.ks, prob.gamma, prob.temperature, prob.eps_ref2,
                          prob.w_ref, prob.photon_limited, prob.noise)
    return jnp.log(_objective(infos, prob.target, prob.friction_se))


@eqx.filter_jit
def _minimise_all(prob: _Problem, starts):
    """BFGS from every start at once (vmapped): ``(optima, objective values)``."""
    solver = optx.BFGS(rtol=1e-6, atol=1e-6)

    def one(u0):
        sol = optx.minimise(_log_objective, solver, u0, args=prob, max_steps=200, throw=False)
        val = _log_objective(sol.value, prob)
        return sol.value, jnp.where(jnp.isfinite(val), val, jnp.inf)

    return jax.vmap(one)(starts)


def _evaluate(infos, friction_se, *, target):
    """Relative SEs (n_k, n_par) with the friction prior, the force sensitivity's (n_k,) and
    the objective of one candidate of information ``infos``."""
    unbounded = jnp.linalg.inv(_with_friction_prior(infos, friction_se))
    cov = bounded_covariance(unbounded)
    free = bounded_covariance(jnp.linalg.inv(infos))
    se = jnp.sqrt(jnp.diagonal(cov, axis1=-2, axis2=-1))
    free_se = jnp.sqrt(jnp.diagonal(free, axis1=-2, axis2=-1))
    crb = jnp.sqrt(jnp.diagonal(unbounded, axis1=-2, axis2=-1))
    return (se, free_se, force_sensitivity_se(free, friction_se),
            _objective(infos, target, friction_se), crb, bound_probability(unbounded))


_evaluate_jit = jax.jit(_evaluate, static_argnames=("target",))


def _acquisition(label, recs, ks, gamma, temperature, eps_ref2, w_ref, photon_limited,
                 target, friction_se=-1.0):
    """The candidate ``recs``: (dt, W, N) each, or (dt, W, N, p) each for recordings at laser
    powers p times the one k is given at (a power series; k_i = k p, SE of k = SE of c)."""
    recs = tuple(tuple(float(x) for x in r) for r in recs)
    powers = tuple(r[3] for r in recs) if recs and all(len(r) == 4 for r in recs) else None
    infos = candidate_informations(recs, ks, gamma, temperature, eps_ref2, w_ref,
                                   photon_limited, eps_ref2 > 0)
    n_k = len(ks)
    # stiffnesses padded as the information's (one program for a single one and a range)
    out = _evaluate_jit(padded(infos, K_PAD), friction_se, target=target)
    se, free_se, fs, crb, p_bound = (np.asarray(out[i])[:n_k] for i in (0, 1, 2, 4, 5))
    obj = float(out[3])
    names = ("k", "gamma", "tracking_var")[: se.shape[1]]
    predicted = {n: se[:, i] for i, n in enumerate(names)}
    known = friction_se >= 0
    if friction_se == 0:
        predicted["gamma"] = np.zeros_like(se[:, 1])  # known exactly (the prior's 1e-12)
    if known:
        predicted["force_sensitivity"] = fs
    # what must be identified: k, and gamma unless the friction is known; for the force
    # sensitivity the volts fit's k' and gamma' (free friction), whatever gamma0's SE
    free_gamma = not known or target == "force_sensitivity"
    core = free_se[:, :2] if target == "force_sensitivity" else se[:, :2 if free_gamma else 1]
    if not np.all(np.isfinite(core)) or np.any(core > UNIDENTIFIED_SE) or not np.isfinite(obj):
        # k or gamma not identified (dt >> tau on one exposure, a near-singular information):
        # the SE of the target alone would be a confident-looking number of a fit that cannot
        # be made, so such a design is never recommended
        obj = math.inf
        label += " (k or gamma not identified)" if free_gamma else " (k not identified)"
    crb = np.asarray(crb)
    unconstrained = {n: crb[:, i] for i, n in enumerate(names) if n in predicted}
    if friction_se == 0:
        unconstrained["gamma"] = np.zeros_like(crb[:, 1])
    return Acquisition(label, tuple(r[:3] for r in recs), predicted, obj, powers,
                       unconstrained_se=unconstrained, bound_probability=np.asarray(p_bound))


def _optimised(n_exp: int, common: tuple, dt_min: float, w_min: float, dead_time: float,
               budget: float, by_time: bool, powers=None,
               label: str | None = None) -> Acquisition | None:
    """The best series of ``n_exp`` exposures at a common frame interval, from a few starts
    (None when no start gives a finite objective). ``powers``: one laser power per recording
    (relative to the one k is given at; a power series with one exposure per power); the
    program compiled is the same as the exposure series' (there: powers 1)."""
    ks, gamma, temperature, eps_ref2, w_ref, photon_limited, target, friction_se = common
    n_slots = max(N_SLOTS, n_exp)
    pw = np.ones(n_slots)
    pw[:n_exp] = 1.0 if powers is None else np.asarray(powers, dtype=float)
    prob = _Problem(dt_min=jnp.asarray(dt_min), w_min=jnp.asarray(w_min),
                    dead=jnp.asarray(dead_time),
                    budget=jnp.asarray(budget),
                    ks=jnp.asarray(ks), gamma=jnp.asarray(gamma),
                    temperature=jnp.asarray(temperature), eps_ref2=jnp.asarray(eps_ref2),
                    w_ref=jnp.asarray(w_ref), friction_se=jnp.asarray(friction_se),
                    powers=jnp.asarray(pw), active=jnp.asarray(np.arange(n_slots) < n_exp),
                    n_slots=n_slots, total_time=jnp.asarray(bool(by_time)),
                    photon_limited=jnp.asarray(bool(photon_limited)),
                    target=target, noise=eps_ref2 > 0)
    spread = np.linspace(-2.0, 2.0, n_exp) if n_exp > 1 else np.zeros(1)
    idle = np.zeros(n_slots - n_exp)
    starts = np.array([np.concatenate([[u0], spread + s0, idle]) for u0 in (-6.0, 0.0, 2.0)
                       for s0 in (-2.0, 2.0)])
    us, vals = _minimise_all(prob, jnp.asarray(starts))
    vals = np.asarray(vals)
    if not np.isfinite(vals).any():
        return None
    best_u = us[int(np.argmin(vals))]
    if label is None:
        label = "optimised single recording" if n_exp == 1 else \
            f"optimised series of {n_exp} exposures"
    recs = prob.recs(best_u)[:n_exp]
    return _acquisition(label, recs if powers is not None else [r[:3] for r in recs], *common)


@float64_scope
def design(*, k, gamma=None, radius=None, viscosity=None, temperature: float = 295.0,
           max_fps: float, min_exposure: float = 1e-6, dead_time: float = 0.0,
           n_frames: int | None = None, total_time: float | None = None,
           tracking_std: float = 0.0, photon_limited: bool = False,
           reference_exposure: float | None = None, target: str = "k",
           friction_error: float | None = None, current=None,
           series=(1, 2, 3), laser_powers=None, check_units: bool = True) -> DesignResult:
    """Recommend an acquisition that minimises the expected error of the calibration.

    The expected errors are the Cramer-Rao bound of the Whittle Fisher information, corrected
    for the bound eps^2 >= 0 of the fit (near it the estimates scatter less than the bound
    says; :func:`bounded_covariance`): ``predicted_se`` is the scatter of the estimates one
    should see over repeated experiments, ``best.unconstrained_se`` the Cramer-Rao bound.

    **Arguments** (SI):

    - `k`: expected stiffness [N/m], or a range ``(k_min, k_max)`` (the worst case over three
      log-spaced values is minimised).
    - `gamma` [N s/m], or `radius` [m] (with `viscosity` [Pa s], default water at
      `temperature` [K]) for Stokes friction.
    - `max_fps` [Hz]: fastest frame rate; `min_exposure` [s]; `dead_time` [s] (W <= dt - dead).
    - `n_frames` per recording, or `total_time` [s] shared by all recordings (one required).
    - `tracking_std` [m]: tracking-error rms; with `photon_limited` it scales as
      ``sqrt(reference_exposure / W)`` (default reference: 1/max_fps), what makes short
      exposures costly on a real camera.
    - `target`: ``"k"``, ``"gamma"``, ``"both"`` (geometric mean of the two relative SEs),
      ``"determinant"`` (D-optimal: det of the covariance of log k and log gamma, to the 1/4
      power, so also a relative SE), or ``"force_sensitivity"`` (Rf = k Rd of a passive
      calibration in volts with the friction known from the bead: needs `friction_error`).
    - `friction_error`: None (default): gamma is fitted with k; a number >= 0: the friction is
      known (Stokes from the bead, or given) to this relative SE (0 = exactly; e.g. 0.06 for a
      radius known to 3 %... plus viscosity), as calibrate does with ``friction="stokes"`` or
      ``fixed={"gamma": ...}``. This is what makes dt >> tau usable: there one recording
      cannot separate k from gamma, but with gamma known only k (and eps^2) must be
      identified. ``predicted_se`` then also has ``"force_sensitivity"``.
    - `current`: the user's design, ``[(frame_interval, exposure, n_frames), ...]`` (a
      fourth number per recording: its laser power, as a multiple of the one `k` is at).
    - `series`: numbers of exposures to try at a common frame interval (1 = single recording).
    - `laser_powers`: the available laser powers as multiples of the power at which `k` is
      given, e.g. ``(0.5, 1, 2)`` (k_i = k p_i: k = c P, paper section 6.3; gamma and eps^2
      shared). Adds three candidates: a power series at W = dt (every power, the budget split
      equally), a power series with each power's exposure and the common frame interval
      optimised by gradients, and the best single power (exposure and frame interval
      optimised). A power series' information is the sum of its recordings' in
      (log k_i, log gamma, log eps^2), log k_i = log c + log p_i, so its ``predicted_se["k"]``
      is the relative SE of c, equal to that of k at the power `k` is given at. That is what
      ``bt.calibrate(recordings, k="linear_power")`` fits (each recording's ``laser_power``
      set); ``k="per_power"`` fits one k per power, each with a larger SE. The best single
      power's SE of k is that of k at its power, carried to the reference power by k = c P
      (it trusts the proportionality; a series tests it). A candidate's ``laser_powers``
      lists the power of each recording.
    - `check_units`: refuse values outside what a trapped bead shows, naming the likely unit
      (k, gamma or radius in lab units, tracking_std in nm, temperature in Celsius, exposures
      and the current design's frame intervals in ms) and warn of a max_fps below 10 Hz
      (kHz?); as :class:`blurtrap.Recording`'s ``check_units``.

    **Returns:** :class:`DesignResult` (``best``, ``predicted_se``, ``summary()``,
    ``to_dict()``).
    """
    friction_se = _checked_friction(target, friction_error)
    powers = checked_powers(laser_powers)
    ks, gamma, temperature = checked_trap(k, gamma, radius, viscosity, temperature, check_units)
    dt_min = 1.0 / _check("max_fps", max_fps, unit="Hz")
    checked_budget(n_frames, total_time, max_fps, series, powers)
    w_min = _check("min_exposure", min_exposure, unit="s")
    if check_units:
        check_units_of(tracking_std, max_fps, w_min, reference_exposure)
    cur = None if current is None else checked_current(current, check_units)
    check_timing(max_fps, w_min, dead_time)
    eps_ref2 = _checked_noise(tracking_std, photon_limited)
    w_ref = float(reference_exposure) if reference_exposure is not None else dt_min
    common = (ks, gamma, temperature, eps_ref2, w_ref, bool(photon_limited), target, friction_se)

    def n_each(n_rec):
        return total_time / dt_min / n_rec if total_time is not None else n_frames

    cands = [_acquisition("W = dt at the fastest frame rate",
                          [(dt_min, dt_min - dead_time, n_each(1))], *common),
             _acquisition("the paper's exposure series",
                          [(dt_min, max(w_min, f * (dt_min - dead_time)), n_each(len(PAPER_SERIES)))
                           for f in PAPER_SERIES], *common)]
    if cur is not None:
        cands.append(_acquisition("your current design", cur, *common))
    budget = total_time if total_time is not None else n_frames
    assert budget is not None  # exactly one of n_frames / total_time is given (checked above)
    for n_exp in series:
        best = _optimised(int(n_exp), common, dt_min, w_min, float(dead_time), float(budget),
                          total_time is not None)
        if best is not None:
            cands.append(best)
    if powers is not None:
        cands += power_candidates(powers, common, dt_min, w_min, float(dead_time),
                                   float(budget), total_time is not None)
    cands.sort(key=lambda c: c.objective)  # unidentified designs (objective inf) last
    if not math.isfinite(cands[0].objective):
        what = "both k and gamma" if friction_se < 0 or target == "force_sensitivity" else "k"
        raise NotIdentifiedError(f"no candidate design identifies {what} under these constraints "
                                 "(dt >> tau at the fastest frame rate?): allow a faster frame rate or "
                                 "shorter exposures" + (", or give the friction from the bead size "
                                                        "(friction_error=...) and calibrate k with it"
                                                        if friction_se < 0 else ""),
                                 what=what, friction_fitted=friction_se < 0)
    settings = {"gamma_N_s_per_m": gamma, "temperature_K": temperature, "max_fps_Hz": max_fps,
                "min_exposure_s": w_min, "dead_time_s": dead_time, "n_frames": n_frames,
                "total_time_s": total_time, "tracking_std_m": tracking_std,
                "photon_limited": bool(photon_limited), "reference_exposure_s": w_ref,
                "friction_error": friction_error,
                "laser_powers": None if powers is None else list(powers),
                "kT_J": BOLTZMANN * temperature}
    return DesignResult(best=cands[0], candidates=tuple(cands), target=target, k=ks,
                        settings=settings)
