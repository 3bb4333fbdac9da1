r"""Trap models for inference: what a parameter set predicts for one recording.

A model turns physical parameters (``k`` [N/m], ``gamma`` [N s/m], ``tracking_var`` [m^2])
and a recording's acquisition settings (frame interval, exposure, temperature) into

- ``moments``: (C(0), C(1), rho) of the frame process, for the exact likelihood;
- ``psd``: the two-sided discrete PSD at given frequencies, for Whittle / blocked fits;
- ``variance``: the frame variance C(0), for variance-based methods.

Three named starting models (DESIGN section 3):

- ``naive``: instantaneous sampling, no blur, no aliasing, no tracking noise (PSD: the
  Lorentzian; time domain: AR(1));
- ``blur``: naive + ``motion_blur`` + ``aliasing`` (the paper's core, exact closed form);
- ``standard``: blur + ``tracking_noise`` (eps^2 >= 0), the default.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from ..physics._blur import _blur_factor, _rho_b
from ..physics._constants import BOLTZMANN
from ..physics._spectra import _psd_coeffs

MODEL_NAMES = ("naive", "naive_aliased", "blur", "standard")


class TrapModel(eqx.Module):
    """Harmonic trap seen through a detector. Flags are static configuration."""

    blur: bool = eqx.field(static=True, default=True)
    alias: bool = eqx.field(static=True, default=True)
    noise: bool = eqx.field(static=True, default=True)
    name: str = eqx.field(static=True, default="standard")

    @property
    def effects(self) -> tuple[str, ...]:
        out = []
        if self.blur:
            out.append("motion_blur")
        if self.alias:
            out.append("aliasing")
        if self.noise:
            out.append("tracking_noise")
        return tuple(out)

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("k", "gamma", "tracking_var") if self.noise else ("k", "gamma")

    def _w(self, exposure):
        return exposure if self.blur else jnp.zeros_like(exposure)

    def moments(self, k, gamma, eps2, frame_interval, exposure, temperature):
        """(C0, C1, rho) of the frames; eps2 is ignored unless the model has noise."""
        sigma2 = BOLTZMANN * temperature / k
        tau = gamma / k
        a = self._w(exposure) / tau
        r = frame_interval / tau
        c0 = sigma2 * _blur_factor(a) + (eps2 if self.noise else 0.0)
        c1 = sigma2 * _rho_b(a, r)
        return c0, c1, jnp.exp(-r)

    def psd(self, f, k, gamma, eps2, frame_interval, exposure, temperature, s2=None):
        """Discrete two-sided PSD at frequencies ``f`` (shape (R, M)) of R recordings whose
        settings ``k``, ``frame_interval``, ``exposure``, ``temperature`` have shape (R,).
        Per-recording coefficients are computed once and broadcast (no gathers, so the
        gradient and Hessian stay cheap). ``s2 = sin^2(pi f dt)`` may be precomputed."""
        sigma2 = BOLTZMANN * temperature / k
        tau = gamma / k
        e2 = (eps2 if self.noise else 0.0) * jnp.ones_like(sigma2)
        w = self._w(exposure)
        if self.alias:
            dt, omr, rho, c_a, c_b, e2 = (c[:, None] for c in
                                          _psd_coeffs(sigma2, tau, w, frame_interval, e2))
            if s2 is None:
                s2 = jnp.sin(jnp.pi * f * dt) ** 2
            return dt * ((c_a - s2 * c_b) / (omr**2 + 4.0 * rho * s2) + e2)
        s2_, t2, w2, dt2, e22 = (c[:, None] for c in (sigma2, tau, w, frame_interval, e2))
        lor = 2.0 * s2_ * t2 / (1.0 + (2.0 * jnp.pi * f * t2) ** 2)
        return lor * jnp.sinc(f * w2) ** 2 + e22 * dt2

    def variance(self, k, gamma, eps2, exposure, temperature):
        sigma2 = BOLTZMANN * temperature / k
        a = self._w(exposure) * k / gamma
        return sigma2 * _blur_factor(a) + (eps2 if self.noise else 0.0)


def get_model(model) -> TrapModel:
    """Resolve a model given by name (``naive``, ``naive_aliased``, ``blur``, ``standard``)."""
    if isinstance(model, TrapModel):
        return model
    if model is None:
        model = "standard"
    table = {
        "naive": TrapModel(blur=False, alias=False, noise=False, name="naive"),
        "naive_aliased": TrapModel(blur=False, alias=True, noise=False, name="naive_aliased"),
        "blur": TrapModel(blur=True, alias=True, noise=False, name="blur"),
        "standard": TrapModel(blur=True, alias=True, noise=True, name="standard"),
    }
    if model not in table:
        raise ValueError(f"model must be one of {sorted(table)}; got model = {model!r}")
    return table[model]
