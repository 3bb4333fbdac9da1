r"""Physical effects: composable pieces of a trap model, by their canonical names.

A model is the harmonic trap plus effects (DESIGN section 3). Each effect has a canonical
``name``, its own parameters (:class:`Param`: unit, lab unit, typical scale, bounds) and one
hook into the signal chain:

=================  ==========  ==============================================================
name               kind        what it changes
=================  ==========  ==============================================================
motion_blur        flag        rectangular exposure average (closed form)
aliasing           flag        folding at fs (closed form)
tracking_noise     flag        white noise ``tracking_var`` (m^2)
drift              additive    random-walk drift PSD, ``drift_diffusion`` (m^2/s)
line_noise         additive    narrow line at a fixed frequency, ``line_amplitude`` (m)
exposure_kernel    transfer    trapezoidal exposure, ``rise_fraction`` (of W, 0-0.5)
detector_filter    transfer    photodiode filter, ``f3db`` (Hz) and ``diode_alpha`` (0-1)
hydrodynamics      friction    frequency-dependent Stokes friction, ``hydro_radius`` (m)
power_offset       relation    ``k = c (P - P0)``, ``power_offset`` (W)
laser_heating      relation    ``T = T0 + b P``, gamma follows water viscosity, ``heating`` (K/W)
anharmonicity      histogram   quartic term: non-Gaussian frame histogram (kurtosis test)
timing_jitter      timestamps  irregular frame times (from the recording's time stamps)
=================  ==========  ==============================================================

Transfer and friction effects make the model spectrum a folded sum (explicit |n| <= N plus
the exact sum of the 1/f^2 tail); flags and additive effects keep the closed form.

Detectability at realistic sizes (documented per effect below) matters: an effect that is too
weak to be seen in the data is reported as such by ``diagnose`` rather than guessed.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from ..physics._constants import BOLTZMANN
from ..physics._effects import (
    drift_psd,
    hydro_lorentzian,
    line_psd,
    photodiode_transfer,
    water_viscosity,
)

RHO_WATER = 997.0  # kg/m^3
RHO_POLYSTYRENE = 1050.0  # kg/m^3


@dataclasses.dataclass(frozen=True)
class Param:
    name: str
    unit: str
    lab_factor: float
    lab_unit: str
    description: str
    upper: float = float("inf")


class AbstractEffect(eqx.Module):
    """An effect: canonical ``name``, ``kind``, ``params`` and hooks used by the model."""

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    signature: ClassVar[str] = ""

    # additive discrete PSD term (R, M)
    def psd_add(self, f, dt, extras):
        return 0.0

    # multiplicative continuous transfer |H|^2 and its value at f -> infinity
    def transfer(self, f, w, extras):
        return 1.0

    def transfer_inf(self, extras):
        return 1.0


class MotionBlur(AbstractEffect):
    """Rectangular exposure average over W (paper eq. 1). Signature: PSD deficit rising
    toward fs/2; variance falls with W. A single blurred record looks like an unblurred one
    with a *negative* white-noise variance: with eps^2 >= 0 the naive model fails clearly."""

    name: ClassVar[str] = "motion_blur"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "PSD deficit rising toward fs/2"


class Aliasing(AbstractEffect):
    """Folding of the spectrum at the sampling rate. Signature: excess near Nyquist."""

    name: ClassVar[str] = "aliasing"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "excess near Nyquist vs the unfolded model"


class TrackingNoise(AbstractEffect):
    """White tracking error of variance eps^2. Signature: flat excess floor in the PSD."""

    name: ClassVar[str] = "tracking_noise"
    kind: ClassVar[str] = "flag"
    params: ClassVar = (Param("tracking_var", "m^2", 1e18, "nm^2", "tracking-error variance"),)
    signature: ClassVar[str] = "flat excess floor at high frequency"


class Drift(AbstractEffect):
    """Random-walk drift of diffusion ``drift_diffusion`` [m^2/s] (stage/laser).

    Signature: excess at the lowest frequencies (P ~ 1/f^2). Detectable when the drift power
    at the lowest Fourier frequency exceeds the trap plateau by a few 1/sqrt(M) standard
    errors: for a 65 536-frame camera record of a 0.01 pN/nm trap, D_d >~ 1e-4 nm^2/s...
    1e-3 nm^2/s (about 1 nm of wander over the 44 s record)."""

    name: ClassVar[str] = "drift"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("drift_diffusion", "m^2/s", 1e18, "nm^2/s", "drift diffusion"),)
    signature: ClassVar[str] = "excess power at the lowest frequencies (~1/f^2)"

    def psd_add(self, f, dt, extras):
        return drift_psd(f, dt, extras["drift_diffusion"])


class LineNoise(AbstractEffect):
    """A narrow spectral line (mains hum, vibration) at ``frequency`` [Hz] (fixed; diagnose
    finds it as the most significant isolated spike), amplitude ``line_amplitude`` [m].
    Detectable when A^2/2 exceeds ~10 x the PSD at f0 times the frequency resolution."""

    name: ClassVar[str] = "line_noise"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("line_amplitude", "m", 1e9, "nm", "line amplitude"),)
    signature: ClassVar[str] = "isolated spectral spike"
    frequency: float = eqx.field(static=True, default=50.0)
    width: float = eqx.field(static=True, default=0.0)

    def psd_add(self, f, dt, extras):
        return line_psd(f, self.frequency, extras["line_amplitude"], self.width)


class ExposureKernel(AbstractEffect):
    """Trapezoidal exposure: linear rise and fall, each ``rise_fraction`` x W (0-0.5),
    replacing the rectangle (|H|^2 = sinc^2(pi f W (1-r)) sinc^2(pi f W r)).

    Identifiability (measured): with W <= dt the frames stay *exactly* ARMA(1,1) for any
    exposure kernel (same rho = exp(-dt/tau)); the kernel only changes S and B, which k, gamma
    and eps^2 absorb. From a single recording the shape is therefore not detectable (a
    triangular exposure, r = 0.5, on 65 536 camera frames at k = 0.05 pN/nm: likelihood gain
    0.00, yet k biased by +1 to +3.5 SE with an acceptable fit). It becomes identifiable with an
    exposure series or an independent eps^2 (stuck-bead prior); ``diagnose`` only proposes it
    when the recordings have several exposures."""

    name: ClassVar[str] = "exposure_kernel"
    kind: ClassVar[str] = "transfer"
    params: ClassVar = (Param("rise_fraction", "1", 1.0, "", "rise/fall time / W", 0.5),)
    signature: ClassVar[str] = "high-frequency spectral shape unlike sinc^2"

    def transfer(self, f, w, extras):
        r = extras["rise_fraction"]
        # the rectangle's sinc^2 is applied by the model; this is the extra factor
        return (jnp.sinc(f * w * (1.0 - r)) * jnp.sinc(f * w * r) / jnp.sinc(f * w)) ** 2

    def rect_replacement(self, f, w, extras):
        r = extras["rise_fraction"]
        return (jnp.sinc(f * w * (1.0 - r)) * jnp.sinc(f * w * r)) ** 2


class DetectorFilter(AbstractEffect):
    """Photodiode low-pass (Berg-Sorensen et al. 2003): ``f3db`` [Hz] and ``diode_alpha``
    (fraction of instantaneous response). Signature: high-frequency deficit with the filter
    shape. Detectable with fast (>= 20 kHz) sampling when f3db is below ~fs/2."""

    name: ClassVar[str] = "detector_filter"
    kind: ClassVar[str] = "transfer"
    params: ClassVar = (
        Param("f3db", "Hz", 1.0, "Hz", "photodiode 3 dB frequency"),
        Param("diode_alpha", "1", 1.0, "", "fast-response fraction", 1.0),
    )
    signature: ClassVar[str] = "high-frequency deficit with a low-pass shape"

    def transfer(self, f, w, extras):
        return photodiode_transfer(f, extras["f3db"], extras["diode_alpha"])

    def transfer_inf(self, extras):
        return extras["diode_alpha"] ** 2


class Hydrodynamics(AbstractEffect):
    """Frequency-dependent friction of a sphere of hydrodynamic radius ``hydro_radius`` [m]
    (Berg-Sorensen & Flyvbjerg 2004; fluid inertia + Basset force, water viscosity at T).
    Faxen's law near a surface only rescales gamma (which stays free). Signature: small
    excess at high frequency; needs fast sampling (f >~ f_nu/100, f_nu = nu/(pi R^2) ~ 140 kHz
    for R = 1.5 um): detectable with photodiode data at >= 50 kHz and ~1e6 samples, not with
    camera data."""

    name: ClassVar[str] = "hydrodynamics"
    kind: ClassVar[str] = "friction"
    params: ClassVar = (Param("hydro_radius", "m", 1e6, "um", "hydrodynamic radius"),)
    signature: ClassVar[str] = "small high-frequency excess over the Lorentzian"

    def lorentzian(self, f, sigma2, tau, temp, extras):
        radius = extras["hydro_radius"]
        eta = water_viscosity(temp)
        k = BOLTZMANN * temp / sigma2
        gamma = tau * k
        d = BOLTZMANN * temp / gamma
        fc = k / (2.0 * jnp.pi * gamma)
        f_nu = eta / RHO_WATER / (jnp.pi * radius**2)
        m_star = (4.0 / 3.0 * RHO_POLYSTYRENE + 2.0 / 3.0 * RHO_WATER) * jnp.pi * radius**3
        f_m = gamma / (2.0 * jnp.pi * m_star)
        return hydro_lorentzian(f, d, fc, f_nu, f_m)


class PowerOffset(AbstractEffect):
    """``k = c (P - P0)``: the stiffness-vs-power line misses the origin by ``power_offset``
    [W] (a power threshold or a calibration offset of the power meter)."""

    name: ClassVar[str] = "power_offset"
    kind: ClassVar[str] = "relation"
    params: ClassVar = (Param("power_offset", "W", 1e3, "mW", "power offset P0"),)
    signature: ClassVar[str] = "k-vs-power line misses the origin"


class LaserHeating(AbstractEffect):
    """Heating ``T = T0 + b P`` at the focus (``heating`` b [K/W]); gamma follows the water
    viscosity eta(T) and kT rises. Signature: curvature in variance-vs-power fits and gamma
    falling with power. Typical b ~ 10-20 K/W at 1064 nm: detectable across >= 4 powers up to
    ~1 W."""

    name: ClassVar[str] = "laser_heating"
    kind: ClassVar[str] = "relation"
    params: ClassVar = (Param("heating", "K/W", 1.0, "K/W", "heating coefficient b"),)
    signature: ClassVar[str] = "gamma falls with laser power"


class Anharmonicity(AbstractEffect):
    """Quartic term in the potential (U = k x^2/2 + k4 x^4/4). Signature: non-Gaussian frame
    histogram (negative excess kurtosis). Not part of the Gaussian (spectral/exact)
    likelihood: ``diagnose`` tests it with the kurtosis of the frames against its
    correlated-sample standard error; detectable when |excess kurtosis| >~ 5 sqrt(24/N_eff)."""

    name: ClassVar[str] = "anharmonicity"
    kind: ClassVar[str] = "histogram"
    signature: ClassVar[str] = "non-Gaussian position histogram (kurtosis)"


class TimingJitter(AbstractEffect):
    """Irregular frame times. Its spectral signature (extra white noise) is degenerate with
    tracking noise, so ``diagnose`` identifies it from the recording's time stamps."""

    name: ClassVar[str] = "timing_jitter"
    kind: ClassVar[str] = "timestamps"
    signature: ClassVar[str] = "uneven time stamps"


EFFECTS: dict[str, type[AbstractEffect]] = {
    cls.name: cls
    for cls in (MotionBlur, Aliasing, TrackingNoise, Drift, ExposureKernel, DetectorFilter,
                Hydrodynamics, Anharmonicity, LaserHeating, PowerOffset, LineNoise,
                TimingJitter)
}


def make_effect(effect, **config) -> AbstractEffect:
    """An effect instance from a canonical name (or pass an instance through)."""
    if isinstance(effect, AbstractEffect):
        return effect
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; canonical names: {sorted(EFFECTS)}")
    return EFFECTS[effect](**config)
