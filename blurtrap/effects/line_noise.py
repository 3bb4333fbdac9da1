"""The ``line_noise`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import numpy as np

from ..physics import line_psd
from . import injections
from ._base import AbstractEffect, Param, value_field


class LineNoise(AbstractEffect):
    """A narrow spectral line (mains hum, vibration) at ``frequency`` [Hz] (fixed; diagnose
    finds it as the most significant isolated spike), amplitude ``line_amplitude`` [m].
    Detectable when A^2/2 exceeds ~10 x the PSD at f0 times the frequency resolution.

    Value: ``line_amplitude`` [m] (>= 0); simulated as ``injections.SinusoidDrift`` of that
    amplitude at ``frequency`` with a random phase per trace (power A^2/2, as the model's
    line). ``diagnose`` searches the frequency (``diagnose_test = "line"``): the candidate's
    own ``frequency`` is not used there."""

    name: ClassVar[str] = "line_noise"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("line_amplitude", "m", 1e9, "nm", "line amplitude",
                              bounds=(1e-15, 1e-5),
                              start=lambda c: 0.1 * math.sqrt(c.variance)),)
    signature: ClassVar[str] = "isolated spectral spike"
    # not static: inside a fit's arguments they are float64 arrays (``traced_constants``),
    # so that a line at a new frequency or resolution compiles nothing new
    frequency: float = 50.0
    width: float = 0.0
    line_amplitude: np.ndarray | None = value_field("m", ">= 0")
    diagnose_test: ClassVar[str] = "line"
    order: ClassVar[float] = 50.0

    def __check_init__(self):
        for nm, v, low in (("frequency", self.frequency, 0.0), ("width", self.width, None)):
            if isinstance(v, np.ndarray) and v.ndim == 0 and v.dtype.kind == "f":
                v = float(v)  # a fit's traced copy (``traced_constants``)
            elif not isinstance(v, (int, float, np.ndarray)) and hasattr(v, "dtype"):
                continue  # a JAX value inside a transformation: checked when constructed
            ok = (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                  and (v > low if low is not None else v >= 0))
            if not ok:
                rule = "> 0" if low is not None else ">= 0"
                raise ValueError(f"{nm} must be a finite number {rule} Hz; got {nm} = {v!r}")

    def to_injection(self) -> injections.SinusoidDrift:
        return injections.SinusoidDrift(self._value("line_amplitude"), 1.0 / self.frequency)

    def psd_add(self, f, dt, extras):
        return line_psd(f, self.frequency, extras["line_amplitude"], self.width)


def traced_constants(model):
    """``model`` with the frequency and width of its line-noise effects as 0-d float64 numpy
    arrays (pytree leaves, traced by ``eqx.filter_jit``) instead of Python floats (static
    there): a fit's compiled programs then serve a line at any frequency and resolution
    (diagnose tries the most significant spike of every record). Idempotent."""
    extra = getattr(model, "extra", ())
    if not any(isinstance(e, LineNoise) for e in extra):
        return model

    def arr(v):
        return np.asarray(v, dtype=np.float64) if isinstance(v, (int, float)) else v

    new = tuple(eqx.tree_at(lambda e: (e.frequency, e.width), e,
                            (arr(e.frequency), arr(e.width)))
                if isinstance(e, LineNoise) else e for e in extra)
    return eqx.tree_at(lambda m: m.extra, model, new)
