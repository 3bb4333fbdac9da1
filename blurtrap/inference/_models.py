r"""Trap models for inference: what a parameter set predicts for one or more recordings.

A model is the harmonic trap plus effects (:mod:`._effects`). Three flags carry the paper's
core (``motion_blur``, ``aliasing``, ``tracking_noise``); further effects are appended with
``model + "drift"`` or ``model.add("drift", "line_noise")``. Named starting models
(DESIGN section 3):

- ``naive``: instantaneous sampling, no blur, no aliasing, no tracking noise (PSD: the
  Lorentzian; time domain: AR(1));
- ``naive_aliased``: the Lorentzian folded at fs (no blur, no noise);
- ``blur``: naive + ``motion_blur`` + ``aliasing`` (the paper's core, exact closed form);
- ``standard``: blur + ``tracking_noise`` (eps^2 >= 0), the default.

The model predicts

- ``moments``: (C(0), C(1), rho) of the frame process, for the exact likelihood (closed-form
  models only);
- ``psd``: the two-sided discrete PSD, for Whittle / blocked fits (all effects);
- ``variance``: the frame variance C(0).

Folded models (no closed form) evaluate the folded part of a long record's PSD on
log-spaced nodes and interpolate it (:mod:`._nodes`; ``fold_nodes=0`` for the exact sum).
"""

from __future__ import annotations

import dataclasses
from functools import partial

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN
from ..effects import EFFECTS, AbstractEffect, make_effect
from ..physics import blur_factor_unchecked as _blur_factor
from ..physics import expected_block_periodogram_unchecked as _expected_block_periodogram
from ..physics import fold_sum, water_viscosity
from ..physics import psd_coeffs_unchecked as _psd_coeffs
from ..physics import rho_b_unchecked as _rho_b
from ._nodes import N_NODES, folded_on_nodes, node_plan, use_nodes

_FLAGS = {"motion_blur": "blur", "aliasing": "alias", "tracking_noise": "noise"}
_GL_X, _GL_W = np.polynomial.legendre.leggauss(12)


class TrapModel(eqx.Module):
    """Harmonic trap seen through a detector, plus effects. All configuration is static,
    except a line's frequency and width (leaves, traced inside a fit's arguments)."""

    blur: bool = eqx.field(static=True, default=True)
    alias: bool = eqx.field(static=True, default=True)
    noise: bool = eqx.field(static=True, default=True)
    name: str = eqx.field(static=True, default="standard")
    # not static: a line's frequency and width are leaves (``effects.line_noise``); every
    # other effect's configuration is static inside it, its values are None in a model
    extra: tuple = ()
    n_alias: int = eqx.field(static=True, default=8)
    #: log-spaced nodes for the folded spectrum of long records (:mod:`._nodes`); 0: exact
    #: folded sum at every ordinate
    fold_nodes: int = eqx.field(static=True, default=N_NODES)

    # ---- composition -----------------------------------------------------------------
    def add(self, *effects, **config) -> TrapModel:
        """A new model with the given effects (canonical names, classes or instances) added.
        An instance's parameter values are dropped (the model holds structure; the fit starts
        from each parameter's start rule: pass ``start=`` or ``fixed=`` to ``calibrate`` to use
        them); its configuration (``LineNoise(frequency=...)``) is kept. ``config`` goes to
        the effects given by name or class that have such a setting (``add("drift",
        "line_noise", frequency=50.0)``); a setting that none of them has is an error."""
        model = self
        used: set[str] = set()
        names = []
        for e in effects:
            name = e.name if isinstance(e, AbstractEffect) or isinstance(e, type) else e
            names.append(str(name))
            if name in _FLAGS:
                model = dataclasses.replace(model, blur=model.blur or name == "motion_blur",
                                            alias=model.alias or name == "aliasing",
                                            noise=model.noise or name == "tracking_noise",
                                            name=f"{model.name}+{name}")
                continue
            cls = e if isinstance(e, type) else EFFECTS.get(name)
            own = {}
            if cls is not None and not isinstance(e, AbstractEffect):
                fields = {f.name for f in dataclasses.fields(cls)}
                own = {k: v for k, v in config.items() if k in fields}
                used |= own.keys()
            eff = make_effect(e, **own).without_values()
            if any(x.name == eff.name for x in model.extra):
                raise ValueError(f"effect {eff.name!r} is already in the model")
            if eff.kind in ("histogram", "timestamps"):
                raise ValueError(
                    f"effect {eff.name!r} ({eff.kind}) is not part of the Gaussian likelihood; "
                    "diagnose() tests it from the frame histogram / time stamps"
                )
            if eff.kind == "input":
                raise ValueError(
                    f"effect {eff.name!r} is a known input, not part of the model: calibrate "
                    "fits it from the recording's instrument setting (e.g. drive)"
                )
            model = dataclasses.replace(model, name=f"{model.name}+{eff.name}",
                                        extra=model.extra + (eff,))
        unused = sorted(set(config) - used)
        if unused:
            raise ValueError(
                f"{', '.join(unused)} is not a setting of the effect(s) added by name or "
                f"class ({', '.join(names)}); an effect instance keeps its own settings "
                "(for example LineNoise(frequency=50.0), settings of line_noise: frequency, "
                "width)")
        return model

    def __add__(self, effect) -> TrapModel:
        if isinstance(effect, (list, tuple)):
            return self.add(*effect)
        return self.add(effect)

    @property
    def effects(self) -> tuple[str, ...]:
        out = [n for n, flag in _FLAGS.items() if getattr(self, flag)]
        return tuple(out) + tuple(e.name for e in self.extra)

    def has(self, name: str) -> bool:
        return name in self.effects

    @property
    def extra_params(self):
        return tuple(p for e in self.extra for p in e.params)

    @property
    def param_names(self) -> tuple[str, ...]:
        core = ("k", "gamma", "tracking_var") if self.noise else ("k", "gamma")
        return core + tuple(p.name for p in self.extra_params)

    @property
    def closed_form(self) -> bool:
        return all(e.kind in ("additive", "relation") for e in self.extra)

    def _w(self, exposure):
        return exposure if self.blur else jnp.zeros_like(exposure)

    # ---- relations across recordings ---------------------------------------------------
    def relations(self, k_rec, gamma, temperature, power, extras):
        """Apply relation effects: returns per-recording (k, gamma, temperature)."""
        gamma_rec = gamma * jnp.ones_like(k_rec)
        temp = temperature
        for e in self.extra:
            if e.name == "power_offset":
                k_rec = k_rec * (1.0 - extras["power_offset"] / power)
            elif e.name == "laser_heating":
                temp = temperature + extras["heating"] * power
                gamma_rec = gamma_rec * water_viscosity(temp) / water_viscosity(temperature)
        return k_rec, gamma_rec, temp

    # ---- predictions -----------------------------------------------------------------
    def moments(self, k, gamma, eps2, frame_interval, exposure, temperature):
        """(C0, C1, rho) of the frames (closed-form models); eps2 ignored without noise."""
        sigma2 = BOLTZMANN * temperature / k
        tau = gamma / k
        a = self._w(exposure) / tau
        r = frame_interval / tau
        c0 = sigma2 * _blur_factor(a) + (eps2 if self.noise else 0.0)
        c1 = sigma2 * _rho_b(a, r)
        return c0, c1, jnp.exp(-r)

    def _per_recording(self, k, gamma, eps2, frame_interval, exposure, temperature):
        """(sigma2, tau, e2, w, dt) per recording, each of shape (R,)."""
        sigma2 = BOLTZMANN * temperature / k
        tau = gamma / k * jnp.ones_like(sigma2)
        e2 = (eps2 if self.noise else 0.0) * jnp.ones_like(sigma2)
        w = self._w(exposure) * jnp.ones_like(sigma2)
        dt = frame_interval * jnp.ones_like(sigma2)
        return sigma2, tau, e2, w, dt

    def node_logp(self, f, k, gamma, frame_interval, exposure, temperature, extras=None):
        """``log`` of the folded part of :meth:`psd` at the log-spaced nodes spanning each
        row of ``f`` (shape (R, K), :func:`._nodes.node_plan`): what :meth:`psd` interpolates
        where the folded spectrum goes through nodes (``nodes``)."""
        sigma2, tau, _, w, dt = self._per_recording(k, gamma, 0.0, frame_interval, exposure,
                                                    temperature)
        nodes = node_plan(f, self.fold_nodes)[0]
        return jnp.log(self._psd_folded(nodes, sigma2, tau, w, dt, temperature, extras or {}))

    def psd(self, f, k, gamma, eps2, frame_interval, exposure, temperature, s2=None,
            extras=None, block_len=None, nodes=None):
        """Discrete two-sided PSD at frequencies ``f`` (shape (R, M)) of R recordings whose
        ``k``, ``gamma``, ``frame_interval``, ``exposure``, ``temperature`` have shape (R,)
        (or broadcast). Per-recording coefficients are computed once and broadcast.
        ``s2 = sin^2(pi f dt)`` may be precomputed. With ``block_len`` (frames per block,
        shape (R,)) a closed-form aliased model returns the exact *expected periodogram* of a
        block of that length (finite-block leakage included) instead of P_d(f). With
        ``nodes`` (:class:`._nodes.NodeValues`: :meth:`node_logp` and the ordinates' place
        between the nodes, given only where the folded spectrum goes through nodes) the
        folded part is interpolated from them."""
        extras = extras or {}
        sigma2, tau, e2, w, dt = self._per_recording(k, gamma, eps2, frame_interval, exposure,
                                                     temperature)
        col = lambda x: x[:, None]  # noqa: E731
        if nodes is not None and not (self.alias and not self.closed_form
                                      and use_nodes(f, self.fold_nodes)):
            raise ValueError("node values are given but this model's spectrum does not go "
                             "through nodes at these frequencies")
        if self.closed_form and self.alias and block_len is not None:
            out = _expected_block_periodogram(f, col(block_len), col(sigma2), col(tau), col(w),
                                              col(dt), col(e2))
        elif self.closed_form:
            if self.alias:
                dt_, omr, rho, c_a, c_b, e2_ = (col(c) for c in _psd_coeffs(sigma2, tau, w, dt, e2))
                if s2 is None:
                    s2 = jnp.sin(jnp.pi * f * dt_) ** 2
                out = dt_ * ((c_a - s2 * c_b) / (omr**2 + 4.0 * rho * s2) + e2_)
            else:
                lor = 2.0 * col(sigma2) * col(tau) / (1.0 + (2.0 * jnp.pi * f * col(tau)) ** 2)
                out = lor * jnp.sinc(f * col(w)) ** 2 + col(e2) * col(dt)
        elif self.alias and use_nodes(f, self.fold_nodes):
            # long record: the folded part on log-spaced nodes, interpolated; additive
            # terms (tracking noise below, drift, lines) stay exact at every ordinate
            folded = partial(self._psd_folded, sigma2=sigma2, tau=tau, w=w, dt=dt,
                             temperature=temperature, extras=extras)
            out = folded_on_nodes(folded, f, self.fold_nodes, nodes) + col(e2 * dt)
        else:
            out = self._psd_folded(f, sigma2, tau, w, dt, temperature, extras) + col(e2 * dt)
        return out + self.additive_psd(f, col(dt), extras)

    def additive_psd(self, f, dt, extras):
        """The summed spectrum of the additive effects (drift, lines) at ``f`` (0 without
        any): what :meth:`psd` adds to every model, and what the fused Whittle pass
        differentiates (``_whittle_pass._additive_spectrum``)."""
        return sum((e.psd_add(f, dt, extras) for e in self.extra if e.kind == "additive"),
                   0.0)

    def _psd_folded(self, f, sigma2, tau, w, dt, temperature, extras):
        hydro = next((e for e in self.extra if e.kind == "friction"), None)
        kernel = next((e for e in self.extra if e.name == "exposure_kernel"), None)
        filters = [e for e in self.extra if e.name == "detector_filter"]
        temp = temperature * jnp.ones_like(sigma2)
        c3 = lambda x: x[:, None, None]  # noqa: E731

        def cont(ff):
            if hydro is not None:
                p = hydro.lorentzian(ff, c3(sigma2), c3(tau), c3(temp), extras)
            else:
                p = 2.0 * c3(sigma2) * c3(tau) / (1.0 + (2.0 * jnp.pi * ff * c3(tau)) ** 2)
            if self.blur:
                if kernel is not None:
                    p = p * kernel.rect_replacement(ff, c3(w), extras)
                else:
                    p = p * jnp.sinc(ff * c3(w)) ** 2
            for e in filters:
                p = p * e.transfer(ff, c3(w), extras)
            return p

        if not self.alias:
            return cont(f[..., None])[..., 0]
        fs = (1.0 / dt)[:, None]
        if not self.blur and hydro is None:
            # exact sum of the A/f^2 tail of the (filtered) Lorentzian
            d = sigma2 / tau  # kT/gamma
            tail = d / (2.0 * jnp.pi**2)
            for e in filters:
                tail = tail * e.transfer_inf(extras)
            return fold_sum(cont, f, fs, self.n_alias, tail[:, None])
        # Aliases beyond n_alias (Euler-Maclaurin, midpoint form):
        # sum_{n>N} g(n) = int_{N+1/2}^inf g(t) dt + g'(N+1/2)/24 + O(third derivative),
        # g(t) = cont(f + t fs) + cont(t fs - f); the integral by Gauss-Legendre in u = a/s^2,
        # g' by the difference g(N+1) - g(N). With the default n_alias = 8 the relative error
        # of the folded PSD is < 3e-5 for any exposure (largest at W = dt, where sinc^2
        # sampled at the aliases is not its running average), including a nearly
        # instantaneous one (photodiode, W << dt) whose tail carries ~1/N of the power and was
        # lost before (0.7 % near Nyquist with a detector filter at n_alias = 25, no tail).
        n = self.n_alias
        a = (n + 0.5) * fs[..., None]
        s = jnp.asarray((_GL_X + 1.0) / 2.0)
        u = a / s**2
        wq = jnp.asarray(_GL_W / 2.0) * 2.0 * a / s**3
        fe = f[..., None]
        tail = jnp.sum(wq * (cont(fe + u) + cont(u - fe)), axis=-1) / fs
        edge = jnp.stack([n * fs, (n + 1) * fs], axis=-1) * jnp.ones_like(fe)
        g = cont(fe + edge) + cont(edge - fe)
        tail = tail + (g[..., 1] - g[..., 0]) / 24.0
        return fold_sum(cont, f, fs, n) + tail

    def variance(self, k, gamma, eps2, exposure, temperature):
        sigma2 = BOLTZMANN * temperature / k
        a = self._w(exposure) * k / gamma
        return sigma2 * _blur_factor(a) + (eps2 if self.noise else 0.0)


def get_model(model) -> TrapModel:
    """Resolve a model: a ``TrapModel``, a name (``naive``, ``naive_aliased``, ``blur``,
    ``standard``, or ``photodiode_aa``: tracking noise without exposure average or folding, the
    model calibrate gives an anti-aliased photodiode) or a name with effects
    (``"standard+drift+line_noise"``)."""
    if isinstance(model, TrapModel):
        return model
    if model is None:
        model = "standard"
    base, *more = str(model).split("+")
    table = {
        "naive": TrapModel(blur=False, alias=False, noise=False, name="naive"),
        "naive_aliased": TrapModel(blur=False, alias=True, noise=False, name="naive_aliased"),
        "blur": TrapModel(blur=True, alias=True, noise=False, name="blur"),
        "standard": TrapModel(blur=True, alias=True, noise=True, name="standard"),
        "photodiode_aa": TrapModel(blur=False, alias=False, noise=True, name="photodiode_aa"),
    }
    if base not in table:
        raise ValueError(f"model must be one of {sorted(table)} (optionally '+effect'); "
                         f"got model = {model!r}")
    out = table[base]
    for name in more:
        if name not in EFFECTS:
            raise ValueError(f"unknown effect {name!r} in model {model!r}; canonical names: "
                             f"{sorted(EFFECTS)}")
        out = out.add(name)
    return out
