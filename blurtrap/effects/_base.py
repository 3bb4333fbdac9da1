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
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx


@dataclasses.dataclass(frozen=True)
class StartContext:
    """What a start rule may use: medians over the recordings of the frame variance [m^2],
    the record duration [s], the sampling rate [Hz] and the temperature [K]; the laser powers
    [W] (empty when unknown) and the friction of the trap fit the effect is added to [N s/m]."""

    variance: float
    duration: float
    sampling_rate: float
    temperature: float
    powers: tuple[float, ...]
    gamma: float


@dataclasses.dataclass(frozen=True)
class Param:
    """Everything about one parameter (or derived quantity), in one place: ``name``, SI
    ``unit``, lab units (value in lab units = ``lab_factor`` x SI value, ``lab_unit``), a
    ``description``, the largest value a fit may take (``upper``, SI) and ``bounds``, the
    physically plausible range that is the support of the default prior (``None`` for
    quantities that are not fitted) and ``start``, the rule for a rough positive start value
    of a fit (:class:`StartContext` -> SI value; refined by the fit)."""

    name: str
    unit: str
    lab_factor: float
    lab_unit: str
    description: str
    upper: float = float("inf")
    bounds: tuple[float, float] | None = None
    start: Callable[[StartContext], float] | None = dataclasses.field(default=None,
                                                                       compare=False)


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
