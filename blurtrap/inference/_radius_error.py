r"""The bead radius's uncertainty in an active calibration with hydrodynamics (positions in
volts, a stage drive, the known bead's frequency-dependent friction; :mod:`._hydro_known`).

The radius ``R`` (given as ``bead_radius_m`` +- ``bead_radius_err_m``) enters the result in
three places:

1. the passive fit's model spectrum: the friction ``gamma(f)`` of the bead (``hydro_radius``
   held at ``R``) and its inertia ``f_m = gamma_b/(2 pi m*)``, whose friction ``gamma_b``
   (Stokes x Faxen of the bead, the effect's ``bead_friction``; the fitted gamma is in volts
   units) also scales with ``R``;
2. the drive response ``H(f_d)``: ``G(f_d) = gamma(f_d)/gamma`` and ``f_m`` of
   :func:`._hydro_drive.drive_friction` (Tolic-Norrelykke et al. 2006 eqs. D3, D6);
3. nothing else: ``Rd = sinc(f_d W) |H(f_d)| |T(f_d)| / |r|`` and the passive fit's values
   (``k_V``, ``gamma_V``, ...) give every reported number.

The fit's optimum ``q(R)`` moves with ``R`` by the implicit function theorem,
``dq/dR = -H_qq^{-1} d(grad_q nll)/dR`` (``H_qq^{-1}`` the fit's covariance without the radius
error, ``grad_q nll`` the Whittle likelihood's exact (autodiff) gradient at the optimum, its
``R``-derivative by central differences over both routes of item 1, the model rebuilt at
``R +- h``). The reported outputs ``y = g(q, |r|, R)`` then have
``dy/dR = dg/dq dq/dR + dg/dR`` (the second term: item 2), and the radius adds
``(dy/dR)(dy/dR)^T s_R^2`` to their covariance, in quadrature with the fit's and the drive
ratio's errors (first order; as ``blurtrap.inference._fixed`` for a held input, which by
itself would miss ``gamma_b`` of item 1 and all of item 2).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope

__all__ = ["radius_error_applies", "model_at", "base_covariance", "fit_radius_derivative",
           "input_covariance", "radius_note"]

_REL_STEP = 1e-4


def _nll_grad(p, args):
    from ._problems import spectral_nll

    return jax.grad(spectral_nll)(p, args)


_GRAD = eqx.filter_jit(_nll_grad)


def _effect(model):
    return next((e for e in model.extra if e.name == "hydrodynamics"), None)


def radius_error_applies(plan) -> bool:
    """An active calibration in volts with the known bead's hydrodynamics and a radius
    error (the case this module handles)."""
    return (plan.volts and plan.drive is not None and _effect(plan.model) is not None
            and plan.fixed.get("hydro_radius", (0.0, 0.0))[1] > 0)


def model_at(model, rec, radius, nominal):
    """``model`` with the bead's inertia friction ``gamma_b`` (the effect's ``bead_friction``,
    when it has one) rescaled from the bead of radius ``nominal`` to one of ``radius`` [m]
    (Stokes x Faxen at the effect's distance)."""
    from ._hydro_known import _bead_gamma

    eff = _effect(model)
    if eff is None or eff.bead_friction is None:
        return model
    scale = _bead_gamma(eff, radius, rec) / _bead_gamma(eff, nominal, rec)
    new = dataclasses.replace(eff, bead_friction=eff.bead_friction * scale)
    return dataclasses.replace(model, extra=tuple(new if e is eff else e for e in model.extra))


def _layout(recs, names, model):
    """The fit's parameter layout (the k mode whose names are the fit's)."""
    from ._problems import make_layout

    extra = tuple(p.name for p in model.extra_params)
    for mode in ("shared", "per_recording", "per_power", "linear_power"):
        try:
            lay = make_layout(recs, mode, model.noise, extra)
        except ValueError:
            continue
        if tuple(lay.names) == tuple(names):
            return lay
    raise ValueError(f"no parameter layout gives the fit's parameters {list(names)}")


def base_covariance(cov, names, fixed):
    """The fit's covariance without the radius error that the held-input propagation
    (:func:`._fixed.propagate`) put in: it added ``J V J^T`` to the free block, ``J V`` to
    the cross terms and ``V`` for the radius, with ``J = cross / V``."""
    cov = np.where(np.isfinite(cov), np.asarray(cov, float), np.nan)
    ir = list(names).index("hydro_radius")
    v = fixed["hydro_radius"][1] ** 2
    free = [i for i, n in enumerate(names) if n not in fixed]
    j = np.nan_to_num(cov[free, ir]) / v
    out = cov.copy()
    out[np.ix_(free, free)] -= np.outer(j, j) * v
    out[free, ir] = out[ir, free] = 0.0
    out[ir, ir] = 0.0
    return out


@float64_scope
def fit_radius_derivative(res, plan, cov_base, rel_step=_REL_STEP):
    """``dq/dR`` of the fit's values (volts units) by the implicit function theorem (module
    docstring): 1 for ``hydro_radius``, 0 for the other held ones; None when the fit is not
    a spectral one (no periodogram weights in ``res.extras``)."""
    from ._spectral import _spectral_args

    if "weight" not in res.extras:
        return None
    names = list(res.param_names)
    recs = plan.recordings
    rad = plan.fixed["hydro_radius"][0]
    ir = names.index("hydro_radius")
    layout = _layout(recs, names, plan.model)
    n_blocks = int(res.extras.get("n_blocks", 1))
    values = np.asarray(res.values, float)
    h = rel_step * rad
    grads = []
    for step in (h, -h):
        mdl = model_at(plan.model, recs[plan.drive[4]], rad + step, rad)
        args = _spectral_args(recs, layout, mdl, n_blocks, plan.f_range, plan.excluded)
        # the fit's own weights (excluded ranges, spikes left out by the robust fit)
        w = np.zeros(args.weight.shape)
        given = np.asarray(res.extras["weight"], float)
        w[:, : given.shape[1]] = given
        args = dataclasses.replace(args, weight=jnp.asarray(w))
        p = values.copy()
        p[ir] = rad + step
        grads.append(np.asarray(_GRAD(jnp.asarray(p), args)))
    dgrad = (grads[0] - grads[1]) / (2.0 * h)
    free = [i for i, n in enumerate(names) if n not in plan.fixed]
    c_ff = cov_base[np.ix_(free, free)]
    c_ff = np.where(np.isfinite(c_ff), c_ff, 0.0)  # a parameter at its bound stays there
    out = np.zeros(len(names))
    out[free] = -c_ff @ dgrad[free]
    out[ir] = 1.0
    return out


def input_covariance(res, plan):
    """``(cov, u)``: the fit's covariance with the radius error propagated through the
    whole passive fit (module docstring, item 1) and ``u = dq/dR`` (None, and the fit's
    covariance as it is, when :func:`fit_radius_derivative` does not apply)."""
    cov = np.asarray(res.covariance, float)
    names = list(res.param_names)
    base = base_covariance(cov, names, plan.fixed)
    u = fit_radius_derivative(res, plan, base)
    if u is None:
        return cov, None
    s2 = plan.fixed["hydro_radius"][1] ** 2
    return base + np.outer(u, u) * s2, u


def radius_note(grad_out, out_names, values, cov, plan):
    """The note that says how much of each reported error the radius contributes:
    ``grad_out`` = dy/dR of the reported ``values`` (names ``out_names``, covariance
    ``cov`` with the radius in it)."""
    rad, se = plan.fixed["hydro_radius"]
    show = {"displacement_sensitivity": "Rd", "gamma": "gamma", "k": "k",
            "force_sensitivity": "Rf"}
    parts = []
    for name, label in show.items():
        if name in out_names:
            i = out_names.index(name)
            rel = 100.0 / abs(values[i])
            parts.append(f"{label} +-{abs(grad_out[i]) * se * rel:.2g} % of "
                         f"+-{np.sqrt(max(cov[i, i], 0.0)) * rel:.2g} %")
    return (f"bead radius: R = {rad * 1e6:.4g} +- {se * 1e6:.2g} um ({se / rad * 100:.2g} %) "
            "propagated through the passive fit's hydrodynamic spectrum and the drive "
            "response G(f_d) (first order, in quadrature); the radius's part of each error: "
            + ", ".join(parts))
