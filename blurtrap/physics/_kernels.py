r"""Detection kernels and the general-kernel variance / discrete spectrum (DESIGN item 11).

A detection kernel h(t) (normalised, integral 1) turns the true position into the measured
one, ``X_m = h * X``; it enters the spectra only through ``|H(f)|^2`` replacing ``sinc^2``.
For kernels without a closed form the variance is the integral of the filtered PSD,
``var = 2 int_0^inf P(f) |H(f)|^2 df``, and the discrete PSD is the folded sum
``sum_n P(f + n fs) |H(f + n fs)|^2``.

Kernels are ``eqx.Module`` pytrees: their times are array leaves (differentiable, vmappable).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._checks import as_float, check_count, check_finite, check_nonnegative, check_positive
from ._constants import BOLTZMANN, DEFAULT_TEMPERATURE


class AbstractKernel(eqx.Module):
    """A normalised detection kernel, described by its power transfer ``|H(f)|^2``."""

    @abc.abstractmethod
    def transfer(self, f: ArrayLike) -> Float[Array, ...]:
        """``|H(f)|^2`` (dimensionless, 1 at f = 0)."""

    @abc.abstractmethod
    def width(self) -> Float[Array, ""]:
        """Characteristic duration [s]: sets the frequency resolution of numerical integrals."""


class RectKernel(AbstractKernel):
    """Rectangular exposure of length ``exposure`` [s]: ``|H|^2 = sinc^2(pi f W)``."""

    exposure: Float[Array, ""]

    def __init__(self, exposure):
        self.exposure = check_positive("exposure", exposure, "s", what="exposure time W")

    def transfer(self, f):
        return jnp.sinc(as_float(f) * self.exposure) ** 2

    def width(self):
        return self.exposure


class TrapezoidKernel(AbstractKernel):
    """Exposure with linear rise and fall of duration ``rise`` each, total support ``exposure``.

    The trapezoid is the convolution of rectangles of lengths ``exposure - rise`` and
    ``rise``, so ``|H|^2 = sinc^2(pi f (W - r)) sinc^2(pi f r)``; ``rise = 0`` is the
    rectangle, ``rise = W/2`` a triangle.
    """

    exposure: Float[Array, ""]
    rise: Float[Array, ""]

    def __init__(self, exposure, rise):
        self.exposure = check_positive("exposure", exposure, "s", what="exposure time W")
        self.rise = check_nonnegative("rise", rise, "s", what="rise/fall time")
        if np.any(np.asarray(self.rise) > np.asarray(self.exposure) / 2 * (1 + 1e-12)):
            raise ValueError(
                f"rise must be <= exposure/2; got rise = {float(np.max(self.rise)):.6g} s, "
                f"exposure = {float(np.min(self.exposure)):.6g} s"
            )

    def transfer(self, f):
        f = as_float(f)
        return (jnp.sinc(f * (self.exposure - self.rise)) * jnp.sinc(f * self.rise)) ** 2

    def width(self):
        return self.exposure


class ExponentialKernel(AbstractKernel):
    """Exponential detector response ``h(t) = exp(-t/tau_d)/tau_d`` (single-pole low-pass):
    ``|H|^2 = 1 / (1 + (2 pi f tau_d)^2)``."""

    response_time: Float[Array, ""]

    def __init__(self, response_time):
        self.response_time = check_positive("response_time", response_time, "s")

    def transfer(self, f):
        return 1.0 / (1.0 + (2.0 * jnp.pi * as_float(f) * self.response_time) ** 2)

    def width(self):
        return self.response_time


class ProductKernel(AbstractKernel):
    """Convolution of kernels (transfers multiply), e.g. exposure followed by a detector."""

    kernels: tuple

    def __init__(self, *kernels):
        if not kernels:
            raise ValueError("ProductKernel needs at least one kernel")
        self.kernels = tuple(kernels)

    def transfer(self, f):
        out = 1.0
        for kern in self.kernels:
            out = out * kern.transfer(f)
        return out

    def width(self):
        # the finest time scale sets the frequency range to integrate over
        return jnp.min(jnp.stack([jnp.asarray(k.width()) for k in self.kernels]))


def _check_kernel(kernel):
    if not isinstance(kernel, AbstractKernel):
        raise TypeError(
            f"kernel must be a detection kernel (RectKernel, TrapezoidKernel, ExponentialKernel, "
            f"ProductKernel); got {type(kernel).__name__}"
        )


def _gauss_legendre(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return x, w


def variance_general(
    kernel: AbstractKernel,
    k,
    gamma,
    temperature=DEFAULT_TEMPERATURE,
    *,
    n_lorentz_panels: int = 64,
    n_linear_panels: int = 1600,
    periods: float = 400.0,
    n_nodes: int = 16,
):
    r"""Variance of the kernel-filtered position, ``2 int_0^inf P(f) |H(f)|^2 df``, numerically.

    Composite Gauss-Legendre in ``theta = arctan(f/f_c)`` (which maps the Lorentzian to a
    constant: ``P df = sigma2/pi dtheta``), on panels that are uniform in theta (resolving the
    corner) merged with panels uniform in f of width ``periods/(n_linear_panels width)``
    (resolving the kernel's oscillations) up to ``f_max = periods / width``. The neglected tail
    is below ``sigma2 (2/pi) f_c/f_max max_{f>f_max}|H|^2``.

    **Returns:** var [m^2] (without tracking noise).

    **Raises:** ``TypeError`` if `kernel` is not an :class:`AbstractKernel`; ``ValueError`` for
    non-positive parameters or panel/node counts.
    """
    _check_kernel(kernel)
    n_lorentz_panels = check_count("n_lorentz_panels", n_lorentz_panels, 1)
    n_linear_panels = check_count("n_linear_panels", n_linear_panels, 1)
    n_nodes = check_count("n_nodes", n_nodes, 1)
    periods = check_positive(  # pyright: ignore[reportAssignmentType]
        "periods", periods, what="kernel periods integrated")
    k = check_positive("k", k, "N/m", what="trap stiffness")
    gamma = check_positive("gamma", gamma, "N s/m", what="friction coefficient")
    t = check_positive("temperature", temperature, "K")
    sigma2 = BOLTZMANN * t / k
    fc = k / (2.0 * jnp.pi * gamma)
    f_max = periods / kernel.width()
    th_max = jnp.arctan(f_max / fc)
    u = jnp.linspace(0.0, 1.0, n_lorentz_panels + 1)
    b_theta = u * th_max
    b_lin = jnp.arctan(jnp.linspace(0.0, 1.0, n_linear_panels + 1) * f_max / fc)
    edges = jnp.sort(jnp.concatenate([b_theta, b_lin[1:-1]]))
    lo, hi = edges[:-1], edges[1:]
    x, wts = _gauss_legendre(n_nodes)
    mid = 0.5 * (lo + hi)[:, None]
    half = 0.5 * (hi - lo)[:, None]
    theta = mid + half * x
    h2 = kernel.transfer(fc * jnp.tan(theta))
    integral = jnp.sum(half * wts * h2)
    return 2.0 * sigma2 / jnp.pi * integral


def psd_folded(
    f,
    kernel: AbstractKernel,
    k,
    gamma,
    frame_interval,
    temperature=DEFAULT_TEMPERATURE,
    tracking_var=0.0,
    *,
    n_alias: int = 1000,
):
    r"""Discrete two-sided PSD for a general kernel by the truncated folding sum

    $$P_d(f) = \sum_{|n|\le N} P(f + n f_s)\,|H(f + n f_s)|^2 + \varepsilon^2 \Delta t.$$

    For a sinc^2-like kernel the truncation error falls as ``N^-3``.

    **Raises:** ``TypeError`` if `kernel` is not an :class:`AbstractKernel`; ``ValueError`` for
    a non-finite `f`, parameters out of range or a negative `n_alias`.
    """
    _check_kernel(kernel)
    n_alias = check_count("n_alias", n_alias, 0)
    f = check_finite("f", f, "Hz")
    k = check_positive("k", k, "N/m", what="trap stiffness")
    gamma = check_positive("gamma", gamma, "N s/m", what="friction coefficient")
    t = check_positive("temperature", temperature, "K")
    dt = check_positive("frame_interval", frame_interval, "s", what="frame interval dt")
    eps2 = check_nonnegative("tracking_var", tracking_var, "m^2", what="tracking-error variance")
    sigma2 = BOLTZMANN * t / k
    tau = gamma / k
    n = jnp.arange(-n_alias, n_alias + 1, dtype=f.dtype)
    ff = f[..., None] + n / dt
    p = 2.0 * sigma2 * tau / (1.0 + (2.0 * jnp.pi * ff * tau) ** 2) * kernel.transfer(ff)
    return jnp.sum(p, axis=-1) + eps2 * dt
