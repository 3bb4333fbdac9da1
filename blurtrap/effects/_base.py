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

**Values.** An effect may carry values of its parameters as array fields (SI, default
``None``: unknown, to be fitted), e.g. ``Drift(drift_diffusion=2e-16)``; they are checked
when the object is made (:func:`value_field`). ``simulate(..., effects=[...])`` simulates the
effect at those values (:meth:`AbstractEffect.to_injection`); ``diagnose`` uses them as the
start of the candidate's screening fit. A model (``TrapModel``, ``calibrate(model=...)``)
keeps only the effect's structure: it drops the values and fits every parameter from its start
rule (``calibrate(..., start=effect.values())`` or ``fixed=effect.values()`` use them).

**Diagnose.** ``diagnose_test`` says how ``diagnose`` tests an effect (``"likelihood"``: a
screening refit with the effect added and a likelihood-ratio test; ``"line"``: the same at the
most significant isolated spike; ``"kurtosis"``: the frame histogram; ``"timestamps"``: the
recordings' time stamps; ``""``: never a default candidate), ``applies`` whether it applies
to given recordings and model (:class:`DataContext`), and ``order`` its place in the default
candidate list (the signal chain's order).

Detectability at realistic sizes (documented per effect below) matters: an effect that is too
weak to be seen in the data is reported as such by ``diagnose`` rather than guessed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import numpy as np


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

    def outside(self, value: float) -> bool:
        """Whether ``value`` (SI) lies outside the plausible range ``bounds`` (False without
        bounds; NaN is outside)."""
        return self.bounds is not None and not self.bounds[0] <= value <= self.bounds[1]

    def range_text(self, lab: bool = True) -> str:
        """The plausible range as text, ``"1e-10..1 N/m (1e-07..1000 pN/nm)"`` (SI only
        without ``lab``)."""
        if self.bounds is None:
            return "any"
        lo, hi = self.bounds
        si = f"{lo:g}..{hi:g} {self.unit}"
        return si + (f" ({lo * self.lab_factor:g}..{hi * self.lab_factor:g} {self.lab_unit})"
                     if lab else "")


@dataclasses.dataclass(frozen=True)
class DataContext:
    """What ``applies`` may use to decide whether an effect is a candidate for given
    recordings and model: the median sampling rate [Hz], the number of distinct exposures,
    whether the model blurs (``motion_blur``), the stiffness sharing of the fit (``k_mode``),
    whether the recordings span >= 3 laser powers and whether any has time stamps."""

    sampling_rate: float
    n_exposures: int
    blurred: bool
    k_mode: str
    multi_power: bool
    has_times: bool


_VALUE = "effect_value"


def _as_value(v):
    """Converter of a value field: ``None`` stays, anything numeric becomes a float64 numpy
    array (checked by ``AbstractEffect.__check_init__``, which names the field)."""
    if v is None:
        return None
    try:
        return np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        return v  # reported with its name by __check_init__


def value_field(unit: str, rule: str | tuple[float, float]) -> Any:
    """A parameter value of an effect: SI ``unit``, ``rule`` one of ``">= 0"``, ``"> 0"`` or
    a closed interval ``(lo, hi)``; default ``None`` (unknown, to be fitted)."""
    return eqx.field(default=None, converter=_as_value, metadata={_VALUE: (unit, rule)})


def _check_value(owner: str, name: str, v, unit: str, rule) -> None:
    if isinstance(rule, tuple):
        expect = f"in [{rule[0]:g}, {rule[1]:g}]"
    else:
        expect = rule
    ok = isinstance(v, np.ndarray) and v.dtype == np.float64 and bool(np.all(np.isfinite(v)))
    if ok:
        if isinstance(rule, tuple):
            ok = bool(np.all((v >= rule[0]) & (v <= rule[1])))
        else:
            ok = bool(np.all(v >= 0)) if rule == ">= 0" else bool(np.all(v > 0))
    if not ok:
        unit_s = f" {unit}" if unit != "1" else ""
        shown = v.tolist() if isinstance(v, np.ndarray) else repr(v)
        raise ValueError(f"{owner}: {name} must be finite and {expect}{unit_s} (or None: to be "
                         f"fitted); got {name} = {shown}")


class AbstractEffect(eqx.Module):
    """An effect: canonical ``name``, ``kind``, ``params``, optional parameter values (array
    fields, see the module docstring) and the hooks used by the model, the simulator and
    ``diagnose``."""

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    signature: ClassVar[str] = ""
    #: how diagnose tests it ("likelihood", "line", "kurtosis", "timestamps"; "": never)
    diagnose_test: ClassVar[str] = "likelihood"
    #: place in the default candidate list (signal-chain order)
    order: ClassVar[float] = 1000.0
    #: why ``to_injection`` cannot simulate it (effects that cannot be simulated)
    simulate_note: ClassVar[str] = "it has no simulator injection"

    def __check_init__(self):
        for f in dataclasses.fields(self):
            if _VALUE in f.metadata and getattr(self, f.name) is not None:
                _check_value(type(self).__name__, f.name, getattr(self, f.name),
                             *f.metadata[_VALUE])

    # ---- values ------------------------------------------------------------------------
    def values(self) -> dict[str, Any]:
        """The given parameter values by name, SI (a float for a scalar, else a float64 array;
        unknown ones left out): ``calibrate(..., start=e.values())`` or ``fixed=e.values()``."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if _VALUE in f.metadata and v is not None:
                out[f.name] = float(v) if np.ndim(v) == 0 else v
        return out

    def without_values(self) -> AbstractEffect:
        """The same effect with every value unknown (what a model keeps: its structure)."""
        unknown = {f.name: None for f in dataclasses.fields(self) if _VALUE in f.metadata}
        return dataclasses.replace(self, **unknown) if unknown else self

    def _value(self, field: str, scalar: bool = False):
        """A value the simulator needs: an error naming the effect when it is unknown."""
        v = getattr(self, field)
        if v is None:
            raise ValueError(f"{type(self).__name__}({field}=None) cannot be simulated: give "
                             f"{field} (the {self.name} effect's value to simulate)")
        if scalar and np.ndim(v) != 0:
            raise ValueError(f"{type(self).__name__}: {field} must be a scalar to simulate "
                             f"the {self.name} effect; got shape {np.shape(v)}")
        return float(v) if scalar else v

    # ---- simulator ---------------------------------------------------------------------
    def to_injection(self) -> Any:
        """The simulator's injection for these values (``blurtrap.effects.injections``), an
        exposure profile, or ``None`` when the simulator always has the effect. Raises a
        ``ValueError`` naming the effect when it cannot be simulated or a value is unknown."""
        raise ValueError(f"effect {self.name!r} ({type(self).__name__}) cannot be simulated by "
                         f"simulate(..., effects=...): {self.simulate_note}")

    # ---- diagnose ----------------------------------------------------------------------
    @classmethod
    def applies(cls, ctx: DataContext) -> bool:
        """Whether ``diagnose`` tries the effect by default for these recordings/model."""
        return True

    # ---- model hooks -------------------------------------------------------------------
    # additive discrete PSD term (R, M)
    def psd_add(self, f, dt, extras):
        return 0.0

    # multiplicative continuous transfer |H|^2 and its value at f -> infinity
    def transfer(self, f, w, extras):
        return 1.0

    def transfer_inf(self, extras):
        return 1.0
