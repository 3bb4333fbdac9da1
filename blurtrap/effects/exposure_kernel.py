"""The ``exposure_kernel`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from . import injections
from ._base import AbstractEffect, DataContext, Param, value_field


class ExposureKernel(AbstractEffect):
    """Trapezoidal exposure: linear rise and fall, each ``rise_fraction`` x W (0-0.5),
    replacing the rectangle (|H|^2 = sinc^2(pi f W (1-r)) sinc^2(pi f W r)). Simulate it with
    ``simulate(..., method="exact", exposure_profile=TrapezoidProfile(r))``.

    Identifiability (measured): with W <= dt the frames stay *exactly* ARMA(1,1) for any
    exposure kernel (same rho = exp(-dt/tau)); the kernel only changes S and B, which k, gamma
    and eps^2 absorb. From a single recording the shape is therefore not detectable (a
    triangular exposure, r = 0.5, on 65 536 camera frames at k = 0.05 pN/nm: likelihood gain
    0.00, yet k biased by +1 to +3.5 SE with an acceptable fit); ``diagnose`` only proposes it
    when the recordings have several exposures. With an exposure series it is detectable when
    the exposure is a sizeable fraction of tau: 4 exposures (0.25-1 dt, 1500 fps,
    k = 0.05 pN/nm, alpha = W/tau up to 1.24, 16 384 frames each) -- a triangle (r = 0.5) was
    ranked first and significant in 10/10 records (p 1e-5 to 2e-3, so near the limit; refit
    adequate with k, gamma within 3 SE in 10/10), r = 0.25 in 8/10; it becomes reliably
    detectable at r ~ 0.5 with this series (longer records or exposures nearer tau
    for smaller r). Detected or not, the rectangular-exposure fit had k or gamma > 3 SE off in
    every one of these records (benchmarks/RESULTS_diagnose.md, section 4);
    at dt >> tau (k = 0.1 pN/nm, 3 x 8192 frames) a triangle was missed in 2/2 records while
    biasing k by ~2.8 SE.

    Value: ``rise_fraction`` (in [0, 0.5], scalar to simulate); ``simulate(...,
    effects=[ExposureKernel(rise_fraction=r)])`` uses ``exposure_profile=TrapezoidProfile(r)``
    (substep methods)."""

    name: ClassVar[str] = "exposure_kernel"
    kind: ClassVar[str] = "transfer"
    params: ClassVar = (Param("rise_fraction", "1", 1.0, "", "rise/fall time / W", 0.5,
                              bounds=(1e-6, 0.5), start=lambda c: 0.1),)
    signature: ClassVar[str] = "high-frequency spectral shape unlike sinc^2"
    order: ClassVar[float] = 60.0

    rise_fraction: np.ndarray | None = value_field("1", (0.0, 0.5))

    @classmethod
    def applies(cls, ctx: DataContext) -> bool:
        # one exposure: the kernel shape is absorbed by k, gamma, eps^2 (exact ARMA(1,1))
        return ctx.blurred and ctx.n_exposures >= 2

    def to_injection(self) -> injections.TrapezoidProfile:
        return injections.TrapezoidProfile(self._value("rise_fraction", scalar=True))

    def transfer(self, f, w, extras):
        r = extras["rise_fraction"]
        # the rectangle's sinc^2 is applied by the model; this is the extra factor
        return (jnp.sinc(f * w * (1.0 - r)) * jnp.sinc(f * w * r) / jnp.sinc(f * w)) ** 2

    def rect_replacement(self, f, w, extras):
        r = extras["rise_fraction"]
        return (jnp.sinc(f * w * (1.0 - r)) * jnp.sinc(f * w * r)) ** 2
