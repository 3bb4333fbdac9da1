"""Calibration results: immutable, on the host, JSON-able in SI units."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from .._constants import BOLTZMANN
from ..effects import QUANTITIES
from ._intervals import merge, wald_intervals

#: lab units (reports, plots, CLI): name -> (factor from SI, lab unit), from the one table
#: of quantities in :mod:`blurtrap.effects`
LAB = {n: (q.lab_factor, q.lab_unit) for n, q in QUANTITIES.items()}


def _json_float(v):
    """A float for JSON: NaN and infinities become None (JSON has neither)."""
    v = float(v)
    return v if math.isfinite(v) else None


#: SI unit and description of every quantity (lab units: LAB)
DESCRIBE = {n: (q.unit, q.description) for n, q in QUANTITIES.items()}


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One fitted parameter, by name (``result["k"]``): value and standard error in SI
    (``unit``) and in lab units (``lab_value``, ``lab_error``, ``lab_unit``), its 95 % interval
    (SI; NaN ends when unknown) and a description. From a ``Posterior``: the median, half
    the central 68 % width and the central 95 % credible interval."""

    name: str
    value: float
    error: float
    unit: str
    description: str
    lab_value: float
    lab_error: float
    lab_unit: str
    interval: tuple[float, float]

    def __repr__(self) -> str:
        return (f"{self.name} = {self.lab_value:.5g} +- {self.lab_error:.2g} {self.lab_unit}"
                f" ({self.description})")


class FitError(RuntimeError):
    """A fit did not converge or its Fisher matrix is singular; the message says which."""


@dataclasses.dataclass(frozen=True)
class CalibrationResult:
    """Calibrated trap parameters with standard errors (SI units).

    ``params``/``errors`` map parameter names (``k`` or ``k[...]``/``c``, ``gamma``,
    ``tracking_var``) to values; ``covariance`` is in the order of ``param_names``.

    ``intervals`` maps every parameter name to its 95 % confidence interval ``(low, high)``
    (SI); ``interval_kinds`` says how each was made: ``"wald"`` (estimate +- 1.96 SE, where
    the likelihood is close to quadratic) or ``"profile"`` (likelihood-ratio interval: the
    profile negative log-likelihood 1.92 above its minimum, used at or near a bound and where
    a check finds the likelihood non-quadratic; a parameter whose profile at 0 is within 1.92
    of the minimum gets low = 0). Results of fits without a likelihood get Wald intervals
    (low = 0 and a NaN high end for a parameter at its bound). Both are computed on first
    access.
    """

    method: str
    model: str
    param_names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray
    temperature: float
    k_per_recording: np.ndarray
    k_per_recording_err: np.ndarray
    gof: dict
    n_recordings: int
    n_frames: int
    converged: bool = True
    at_bounds: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    extras: dict = dataclasses.field(default_factory=dict)
    #: callable ``source(result) -> (intervals, kinds)`` for the parameters whose Wald
    #: interval is not honest (profile likelihood, :mod:`blurtrap.inference._profile`);
    #: evaluated on first use of :attr:`intervals`
    interval_source: Any = dataclasses.field(default=None, repr=False, compare=False)
    _interval_cache: Any = dataclasses.field(default=None, init=False, repr=False,
                                             compare=False)
    #: :class:`~blurtrap.inference._fit_inputs.FitInputs` (recordings and model the fit
    #: used), by reference, for :meth:`plot`; not serialised (None when rebuilt from JSON)
    inputs: Any = dataclasses.field(default=None, repr=False, compare=False)

    # ---- access -----------------------------------------------------------------------
    @property
    def errors(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0, None))

    @property
    def params(self) -> dict[str, float]:
        return dict(zip(self.param_names, map(float, self.values)))

    def _get(self, name):
        i = self.param_names.index(name)
        return float(self.values[i]), float(self.errors[i])

    @property
    def k(self) -> float:
        """Stiffness [N/m] (the single k, or the first recording's when k varies)."""
        return float(self.k_per_recording[0])

    @property
    def k_err(self) -> float:
        return float(self.k_per_recording_err[0])

    @property
    def gamma(self) -> float:
        return self._get("gamma")[0] if "gamma" in self.param_names else math.nan

    @property
    def gamma_err(self) -> float:
        return self._get("gamma")[1] if "gamma" in self.param_names else math.nan

    @property
    def diffusion(self) -> float:
        return BOLTZMANN * self.temperature / self.gamma

    @property
    def diffusion_err(self) -> float:
        return self.diffusion * self.gamma_err / self.gamma

    @property
    def tracking_var(self) -> float:
        return self._get("tracking_var")[0] if "tracking_var" in self.param_names else 0.0

    @property
    def tracking_var_err(self) -> float:
        return self._get("tracking_var")[1] if "tracking_var" in self.param_names else 0.0

    @property
    def corner_frequency(self) -> float:
        """f_c = k / (2 pi gamma) [Hz] (the first recording's k when k varies)."""
        return self.k / (2.0 * math.pi * self.gamma)

    @property
    def corner_frequency_err(self) -> float:
        """Standard error of :attr:`corner_frequency` (delta method with the k-gamma
        covariance; NaN when either error is unknown)."""
        fc = self.corner_frequency
        names = self.param_names
        kname = next((n for n in names if n == "k" or n.startswith("k[")), None)
        if kname is None or "gamma" not in names or not math.isfinite(fc):
            return math.nan
        i, j = names.index(kname), names.index("gamma")
        c = self.covariance
        k, g = float(self.values[i]), self.gamma
        var = fc**2 * (c[i, i] / k**2 + c[j, j] / g**2 - 2.0 * c[i, j] / (k * g))
        if kname != "k" and not np.isclose(k, self.k):  # first recording's k is another one
            var = fc**2 * ((self.k_err / self.k) ** 2 + c[j, j] / g**2)
        return float(math.sqrt(var)) if var >= 0 else math.nan

    def _interval_table(self):
        if self._interval_cache is None:
            ivs, kinds = wald_intervals(self.param_names, self.values, self.errors,
                                        self.at_bounds, self.extras)
            if self.interval_source is not None:
                merge(ivs, kinds, *self.interval_source(self))
            object.__setattr__(self, "_interval_cache", (ivs, kinds))
            return ivs, kinds
        return self._interval_cache

    @property
    def intervals(self) -> dict[str, tuple[float, float]]:
        """95 % confidence interval ``(low, high)`` of every parameter (SI): Wald where the
        likelihood is close to quadratic, profile likelihood at or near a bound or where it
        is not (:attr:`interval_kinds`). Computed on first access."""
        return dict(self._interval_table()[0])

    @property
    def interval_kinds(self) -> dict[str, str]:
        """How each interval of :attr:`intervals` was made: ``"wald"``, ``"profile"``, or
        ``"log-wald"`` (a positive parameter whose Wald interval would reach below 0 where
        no profile is available: ``value exp(+-1.96 SE/value)``); ``"wald (profile did not
        converge)"`` (or ``"log-wald (...)"``) where a profile was wanted but one of its fits
        failed (k of a record ~10 relaxation times long), ``"profile (upper end wald: its
        profile did not converge)"`` where one end converged and is kept; ``"wald (cut at
        0)"``: eps^2 (a variance) whose Wald interval would reach below 0, no profile; ``"wald
        (at the bound 0)"``: a parameter at its bound 0 without a profile (method 'allan'):
        ``(0, 1.96 x its unconstrained SE)``."""
        return dict(self._interval_table()[1])

    @property
    def correlation(self) -> np.ndarray:
        s = self.errors
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(s, s)

    def with_inputs(self, recordings, model, f_range=None, excluded=()) -> CalibrationResult:
        """This result keeping a reference to the recordings and model it was fitted to
        (:class:`FitInputs`), which :meth:`plot` and :meth:`plot_residuals` need."""
        from ._fit_inputs import FitInputs

        inputs = FitInputs(tuple(recordings), model, None if f_range is None else
                           tuple(f_range), tuple(tuple(r) for r in excluded or ()))
        return dataclasses.replace(self, inputs=inputs)

    # ---- output -----------------------------------------------------------------------
    def plot(self, ax=None, *, n_blocks=None):
        """Blocked spectrum of the fitted recordings with the fitted model (and the naive
        Lorentzian where the model blurs or folds): :func:`blurtrap.plotting.fit_spectrum`.
        Returns the figure; ``ValueError`` for a result rebuilt from JSON (no recordings)."""
        from ..plotting import fit_spectrum

        return fit_spectrum(self, n_blocks=n_blocks, ax=ax)

    def plot_residuals(self, ax=None, *, n_blocks=None):
        """Data/model of the blocked spectrum with its expected 68 % and 95 % bands:
        :func:`blurtrap.plotting.fit_residuals`. Returns the figure."""
        from ..plotting import fit_residuals

        return fit_residuals(self, n_blocks=n_blocks, ax=ax)

    def __getitem__(self, name: str) -> Parameter:
        """A parameter by name, with unit and description: ``result["k"].value`` (SI),
        ``.error``, ``.unit``, ``.lab_value``; ``"D"`` (or ``"diffusion"``) is derived."""
        if name in ("D", "diffusion") and "gamma" in self.param_names:
            value, error, key, interval = self.diffusion, self.diffusion_err, "diffusion", None
        elif name in self.param_names:
            value, error = self._get(name)
            key, interval = name.split("[")[0], self.intervals.get(name)
        else:
            raise KeyError(f"no parameter {name!r} in this result; its parameters are "
                           f"{list(self.param_names)}" + (" and 'D'" if "gamma" in
                                                           self.param_names else ""))
        unit, what = DESCRIBE.get(key, ("SI", key.replace("_", " ")))
        fac, lab_unit = LAB.get(key, (1.0, unit))
        return Parameter(name, value, error, unit, what, value * fac, error * fac, lab_unit,
                         interval if interval is not None else (math.nan, math.nan))

    def __repr__(self) -> str:
        """Short, without arrays: method, model, each parameter +- SE in lab units."""
        ps = []
        for n, v, e in zip(self.param_names, self.values, self.errors, strict=True):
            fac, unit = LAB.get(n.split("[")[0], (1.0, "SI"))
            ps.append(f"{n} = {v * fac:.5g} +- {e * fac:.2g} {unit}")
        return (f"CalibrationResult({self.method}, model {self.model!r}: {'; '.join(ps)}; "
                f"{self.n_recordings} recording(s), {self.n_frames} frames)")

    def _repr_html_(self) -> str:
        """The lab-unit table of :meth:`summary` for notebooks."""
        import html

        return f"<pre>{html.escape(self.summary())}</pre>"

    def to_dataframe(self):
        """The parameters as a pandas DataFrame (one row each: SI and lab-unit value, error,
        unit, 95 % interval). Needs pandas (``pip install "blurtrap[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError('to_dataframe needs pandas: pip install "blurtrap[pandas]"'
                              ) from None
        names = list(self.param_names) + (["D"] if "gamma" in self.param_names else [])
        rows = [dataclasses.asdict(self[n]) for n in names]
        for r in rows:
            r["ci_low"], r["ci_high"] = r.pop("interval")
        return pd.DataFrame(rows).set_index("name")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict in SI units (keys per the public contract)."""
        many = len(self.k_per_recording) > 1 and not np.allclose(
            self.k_per_recording, self.k_per_recording[0]
        )
        out: dict[str, Any] = {
            "k": [float(v) for v in self.k_per_recording] if many else self.k,
            "k_err": [float(v) for v in self.k_per_recording_err] if many else self.k_err,
            "gamma": self.gamma,
            "gamma_err": self.gamma_err,
            "diffusion": self.diffusion,
            "diffusion_err": self.diffusion_err,
            "tracking_var": self.tracking_var,
            "tracking_var_err": self.tracking_var_err,
            "method": self.method,
            "model": self.model,
            "gof": {k: (float(v) if isinstance(v, (int, float, np.floating)) else v)
                    for k, v in self.gof.items()},
            "param_names": list(self.param_names),
            "values": [float(v) for v in self.values],
            "covariance": [[float(x) for x in row] for row in self.covariance],
            "temperature": self.temperature,
            "n_recordings": self.n_recordings,
            "n_frames": self.n_frames,
            "converged": self.converged,
            "at_bounds": list(self.at_bounds),
            "intervals": {n: [_json_float(lo), _json_float(hi)]
                          for n, (lo, hi) in self.intervals.items()},
            "interval_kinds": dict(self.interval_kinds),
            "notes": list(self.notes),
            "units": "SI",
        }
        if "c" in self.param_names:
            out["c"], out["c_err"] = self._get("c")
        if "gamma" in self.param_names:
            out["corner_frequency"] = _json_float(self.corner_frequency)
            out["corner_frequency_err"] = _json_float(self.corner_frequency_err)
        for name in ("displacement_sensitivity", "force_sensitivity"):
            if name in self.param_names:
                out[name], out[f"{name}_err"] = (_json_float(v) for v in self._get(name))
        if self.extras.get("per_recording"):
            out["per_recording"] = [
                {"name": label, "quantity": q, "value": _json_float(v), "error": _json_float(e)}
                for label, v, e, q in self.extras["per_recording"]]
        return out

    def summary(self) -> str:
        """A readable table in lab units (used by the CLI too): parameters with errors,
        derived D, tau, f_c and eps, per-recording k, goodness of fit and notes."""
        rows = []
        ivs = {}
        for name, v, e in zip(self.param_names, self.values, self.errors, strict=True):
            base = name.split("[")[0]
            fac, unit = LAB.get(base, (1.0, "SI"))
            rows.append((name, v * fac, e * fac, unit))
            if name in self.intervals:
                lo, hi = self.intervals[name]
                ivs[name] = (f"[{lo * fac:.4g}, {hi * fac:.4g}] "
                             f"{self.interval_kinds.get(name, '')}").rstrip()
        g = self.gamma
        if math.isfinite(g):
            fac, unit = LAB["diffusion"]
            rows.append(("D = kT/gamma", self.diffusion * fac, self.diffusion_err * fac, unit))
            k = self.k
            if "c" not in self.param_names:
                tau = g / k
                rows.append(("tau = gamma/k" + (" (first)" if len(set(map(float,
                              self.k_per_recording))) > 1 else ""), tau * 1e3, math.nan, "ms"))
                rows.append(("f_c = k/(2 pi gamma)", self.corner_frequency,
                             self.corner_frequency_err, "Hz"))
        if "tracking_var" in self.param_names:
            tv = max(self.tracking_var, 0.0)
            rows.append(("eps (tracking rms)", math.sqrt(tv) * 1e9, math.nan, "nm"))
        ks, es = self.k_per_recording, self.k_per_recording_err
        if "c" in self.param_names or len(set(map(float, ks))) > 1:
            for i, (kk, ee) in enumerate(zip(ks, es, strict=True)):
                rows.append((f"k (recording {i})", kk * 1e3, ee * 1e3, "pN/nm"))
        for label, v, e, q in self.extras.get("per_recording", ()):  # e.g. laser heating
            fac, unit = LAB.get(q, (1.0, "SI"))
            rows.append((label, v * fac, e * fac, unit))
        w = max(len(r[0]) for r in rows)
        lines = [f"method: {self.method}   model: {self.model}   recordings: "
                 f"{self.n_recordings}   frames: {self.n_frames}   T = "
                 f"{self.temperature:g} K (kT = {BOLTZMANN * self.temperature * 1e21:.4g} pN nm)"]
        wu = max(len(r[3]) for r in rows)
        lines.append(f"  {'parameter'.ljust(w)}  {'value':>12}  {'+- error':>10}  "
                     f"{'unit'.ljust(wu)}  95 % interval" if ivs else
                     f"  {'parameter'.ljust(w)}  {'value':>12}  {'+- error':>10}  unit")
        for name, v, e, unit in rows:
            err = f"{e:10.3g}" if math.isfinite(e) else " " * 10
            iv = f"  {ivs[name]}" if name in ivs else ""
            lines.append(f"  {name.ljust(w)}  {v:12.6g}  {err}  "
                         f"{unit.ljust(wu) if ivs else unit}{iv}".rstrip())
        gof = self.gof
        if gof:
            lines.append(f"  goodness of fit: {gof.get('test', '')}: statistic = "
                         f"{gof.get('statistic', math.nan):.4g}, dof = {gof.get('dof')}, "
                         f"p = {gof.get('p_value', math.nan):.3g}")
        for b in self.at_bounds:
            lines.append(f"  note: {b} is at its lower bound (0)")
        for n in self.notes:
            lines.append(f"  note: {n}")
        return "\n".join(lines)

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.summary()
