r"""Priors for :func:`blurtrap.inference.sample_posterior`.

Every prior is an immutable ``eqx.Module`` (a pytree: its numbers are traced arrays, so new
prior values never trigger a recompilation) with one method, ``log_prob(value)``: the log
density **with respect to the natural SI parameter** ``p`` (``k`` [N/m], ``gamma`` [N s/m],
``tracking_var`` [m^2], ``c`` [N/m/W]), up to an additive constant.

The sampler works in ``theta = log p`` and adds the Jacobian ``log |dp/dtheta| = theta``
itself, so a prior written here as a density in ``p`` means exactly that. In particular the
default :class:`LogUniform` prior, ``p(p) = 1/(p log(high/low))`` on ``[low, high]``, is
uniform in ``log p``. The default for ``tracking_var`` is :class:`Uniform` on ``[0, 1e-10]``
m^2 (eps^2 can be consistent with 0, where a log-uniform prior depends on its cut-off).

Physics-based priors:

- :func:`stokes_gamma_prior`: Gaussian on ``gamma = 6 pi eta r`` (optionally with Faxen's
  correction at height ``h`` above a surface), from the bead radius, the viscosity (or the
  temperature, through the viscosity of water) and their uncertainties, by linear error
  propagation.
- :func:`stuck_bead_prior`: the tracking-error variance measured on a stuck bead (sample
  variance ``s^2`` of ``N`` frames): ``(N - 1) s^2 / eps^2 ~ chi^2_{N-1}``; with a Jeffreys
  prior before that measurement this is an inverse-gamma density
  ``InverseGamma((N - 1)/2, (N - 1) s^2 / 2)`` for ``eps^2``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope, x64_context
from ..effects import QUANTITIES
from ..physics import faxen_factor, stokes_friction, water_viscosity

# Wide physical bounds of the default priors (SI), core and effect parameters: log-uniform,
# except ``tracking_var`` (uniform on [0, 1e-10] m^2; see :class:`Uniform`).
DEFAULT_BOUNDS = {n: q.bounds for n, q in QUANTITIES.items() if q.bounds is not None}


class Prior(eqx.Module):
    """Base class: ``log_prob(p)`` is the log density in the natural SI parameter ``p``."""

    def log_prob(self, value):  # pragma: no cover - abstract
        raise NotImplementedError

    def support_contains(self, value) -> bool:
        """Whether ``value`` [SI] has finite log density (host-side check)."""
        with x64_context(True):
            return bool(jnp.isfinite(self.log_prob(jnp.asarray(float(value)))))


class LogUniform(Prior):
    """Log-uniform (scale-invariant) prior on ``[low, high]`` (uniform in ``log p``)."""

    low: jax.Array | np.ndarray
    high: jax.Array | np.ndarray

    def __init__(self, low, high):
        low, high = float(low), float(high)
        if not (0.0 < low < high) or not math.isfinite(high):
            raise ValueError(
                f"LogUniform needs 0 < low < high < inf; got low = {low!r}, high = {high!r}"
            )
        self.low = np.asarray(low, dtype=np.float64)
        self.high = np.asarray(high, dtype=np.float64)

    def log_prob(self, value):
        inside = (value >= self.low) & (value <= self.high)
        safe = jnp.where(value > 0, value, 1.0)
        lp = -jnp.log(safe) - jnp.log(jnp.log(self.high / self.low))
        return jnp.where(inside, lp, -jnp.inf)


class Uniform(Prior):
    """Uniform prior on ``[low, high]`` in the natural parameter (``0 <= low < high``).

    The default for ``tracking_var``: the data often cannot exclude eps^2 = 0 (the ML
    estimate then sits on that bound), and a log-uniform prior would put posterior mass
    proportional to ``L(0) x log(eps^2_typical / low)`` near eps^2 ~ low, i.e. on an
    arbitrary lower cut-off, dragging the correlated k and gamma with it."""

    low: jax.Array | np.ndarray
    high: jax.Array | np.ndarray

    def __init__(self, low, high):
        low, high = float(low), float(high)
        if not (0.0 <= low < high) or not math.isfinite(high):
            raise ValueError(
                f"Uniform needs 0 <= low < high < inf; got low = {low!r}, high = {high!r}"
            )
        self.low = np.asarray(low, dtype=np.float64)
        self.high = np.asarray(high, dtype=np.float64)

    def log_prob(self, value):
        inside = (value >= self.low) & (value <= self.high) & (value > 0)
        return jnp.where(inside, -jnp.log(self.high - self.low), -jnp.inf)


class Normal(Prior):
    """Gaussian prior ``N(mean, sd^2)`` on the natural parameter (restricted to ``p > 0``)."""

    mean: jax.Array | np.ndarray
    sd: jax.Array | np.ndarray

    def __init__(self, mean, sd):
        mean, sd = float(mean), float(sd)
        if not (sd > 0.0 and math.isfinite(sd) and math.isfinite(mean)):
            raise ValueError(f"Normal needs a finite mean and sd > 0; got mean = {mean!r}, "
                             f"sd = {sd!r}")
        self.mean = np.asarray(mean, dtype=np.float64)
        self.sd = np.asarray(sd, dtype=np.float64)

    def log_prob(self, value):
        z = (value - self.mean) / self.sd
        return jnp.where(value > 0, -0.5 * z * z - jnp.log(self.sd), -jnp.inf)


class LogNormal(Prior):
    """Log-normal prior: ``log p ~ N(log median, sigma^2)``."""

    median: jax.Array | np.ndarray
    sigma: jax.Array | np.ndarray

    def __init__(self, median, sigma):
        median, sigma = float(median), float(sigma)
        if not (median > 0.0 and sigma > 0.0):
            raise ValueError(f"LogNormal needs median > 0 and sigma > 0; got median = "
                             f"{median!r}, sigma = {sigma!r}")
        self.median = np.asarray(median, dtype=np.float64)
        self.sigma = np.asarray(sigma, dtype=np.float64)

    def log_prob(self, value):
        safe = jnp.where(value > 0, value, 1.0)
        z = (jnp.log(safe) - jnp.log(self.median)) / self.sigma
        return jnp.where(value > 0, -0.5 * z * z - jnp.log(safe), -jnp.inf)


class InverseGamma(Prior):
    """Inverse-gamma prior ``p(v) ~ v^(-shape-1) exp(-scale / v)`` (``v > 0``)."""

    shape: jax.Array | np.ndarray
    scale: jax.Array | np.ndarray

    def __init__(self, shape, scale):
        shape, scale = float(shape), float(scale)
        if not (shape > 0.0 and scale > 0.0):
            raise ValueError(f"InverseGamma needs shape > 0 and scale > 0; got shape = "
                             f"{shape!r}, scale = {scale!r}")
        self.shape = np.asarray(shape, dtype=np.float64)
        self.scale = np.asarray(scale, dtype=np.float64)

    def log_prob(self, value):
        safe = jnp.where(value > 0, value, 1.0)
        lp = -(self.shape + 1.0) * jnp.log(safe) - self.scale / safe
        return jnp.where(value > 0, lp, -jnp.inf)


# ------------------------------------------------------------------------------------------
# physics-based priors
# ------------------------------------------------------------------------------------------
# water_viscosity (IAPWS 2008 at 0.1 MPa) and faxen_factor (parallel to a wall) are
# blurtrap.physics's, imported above; the names stay importable from here.


@float64_scope
def stokes_gamma(radius, viscosity, height=None):
    """Stokes friction ``6 pi eta r`` [N s/m], times Faxen's factor when ``height`` is given
    (``blurtrap.physics.stokes_friction`` and ``faxen_factor``, in float64)."""
    g = stokes_friction(radius, viscosity)
    if height is not None:
        g = g * faxen_factor(radius, height)
    return g


def stokes_gamma_prior(
    radius: float,
    radius_err: float,
    *,
    viscosity: float | None = None,
    viscosity_err: float = 0.0,
    temperature: float | None = None,
    temperature_err: float = 0.0,
    height: float | None = None,
    height_err: float = 0.0,
) -> Normal:
    r"""Gaussian prior on ``gamma`` from the bead and the medium.

    ``gamma = 6 pi eta r`` (Stokes), divided by Faxen's factor
    ``1 - 9/16 (r/h) + 1/8 (r/h)^3 - 45/256 (r/h)^4 - 1/16 (r/h)^5`` when the bead centre is at
    ``height`` above the surface. Uncertainties are propagated linearly (first order) and
    assumed independent.

    **Arguments:**

    - `radius`, `radius_err`: bead radius and its standard uncertainty [m].
    - `viscosity`, `viscosity_err`: medium viscosity [Pa s]; if ``viscosity`` is None the
      viscosity of water at ``temperature`` is used (:func:`water_viscosity`).
    - `temperature`, `temperature_err`: [K], only used when ``viscosity`` is None.
    - `height`, `height_err`: bead-centre height above the surface [m] (optional, must exceed
      the radius).

    **Returns:** a :class:`Normal` prior on ``gamma`` [N s/m].
    """
    if not radius > 0:
        raise ValueError(f"radius must be > 0 [m]; got {radius!r}")
    if radius_err < 0 or viscosity_err < 0 or temperature_err < 0 or height_err < 0:
        raise ValueError("uncertainties must be >= 0")
    if viscosity is None:
        if temperature is None:
            raise ValueError("give the viscosity [Pa s] or the temperature [K] (water)")
    elif not viscosity > 0:
        raise ValueError(f"viscosity must be > 0 [Pa s]; got {viscosity!r}")
    if height is not None and not height > radius:
        raise ValueError(
            f"height (bead centre above the surface) must exceed the radius; got height = "
            f"{height!r} m, radius = {radius!r} m"
        )

    def gamma_of(x):
        r, eta_or_t, h = x
        eta = water_viscosity(eta_or_t) if viscosity is None else eta_or_t
        g = stokes_friction(r, eta)
        if height is not None:
            g = g * faxen_factor(r, h)
        return g

    with x64_context(True):
        x0 = jnp.array([radius, temperature if viscosity is None else viscosity,
                        height if height is not None else 1.0])
        errs = jnp.array([radius_err, temperature_err if viscosity is None else viscosity_err,
                          height_err if height is not None else 0.0])
        g0 = float(gamma_of(x0))
        grad = jax.grad(gamma_of)(x0)
        sd = float(jnp.sqrt(jnp.sum((grad * errs) ** 2)))
    if not sd > 0:
        raise ValueError("the gamma prior needs a positive uncertainty (radius_err, "
                         "viscosity_err/temperature_err or height_err)")
    return Normal(g0, sd)


def stuck_bead_prior(sample_var: float, n_frames: int) -> InverseGamma:
    r"""Prior on ``tracking_var`` from a stuck-bead measurement.

    With frames ``x_i = x_0 + e_i``, ``e_i ~ N(0, eps^2)`` white, the sample variance ``s^2``
    (``ddof = 1``) of ``N`` frames obeys ``(N - 1) s^2 / eps^2 ~ chi^2_{N-1}``. Combined with a
    Jeffreys prior ``1/eps^2`` this gives
    ``eps^2 ~ InverseGamma((N - 1)/2, (N - 1) s^2 / 2)`` (mean ``s^2 (N-1)/(N-3)``,
    relative SD ``~ sqrt(2/N)``).

    **Arguments:** `sample_var` [m^2], `n_frames` (N >= 4).
    """
    if not sample_var > 0:
        raise ValueError(f"sample_var must be > 0 [m^2]; got {sample_var!r}")
    if int(n_frames) < 4:
        raise ValueError(f"n_frames must be >= 4; got {n_frames!r}")
    nu = float(int(n_frames) - 1)
    return InverseGamma(0.5 * nu, 0.5 * nu * float(sample_var))
