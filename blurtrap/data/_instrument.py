"""Instrument settings of a recording: detector, bead and fluid, friction model, stage drive,
and the frequency ranges of a spectral fit (DESIGN section 6).

They live in ``Recording.metadata`` under the manifest's key names, so a manifest entry, a
Python ``Recording(metadata={...})`` and a saved file carry them the same way.
:func:`instrument_settings` validates them and fills in the defaults; :func:`load_manifest`
uses the same validator, so a bad value is reported when the manifest is read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ._values import thaw

#: the instrument keys, in the order the manifest documents them
INSTRUMENT_KEYS = (
    "detector",
    "anti_aliasing",
    "diode_filter",
    "bead_radius_m",
    "viscosity_Pa_s",
    "distance_to_surface_m",
    "bead_density_kg_per_m3",
    "fluid_density_kg_per_m3",
    "friction",
    "hydrodynamics",
    "drive",
    "fit_range_Hz",
    "excluded_ranges_Hz",
    "bead_radius_err_m",
    "viscosity_err_Pa_s",
    "temperature_err_K",
)
#: standard errors of the Stokes inputs (propagated into the calibration's errors)
INPUT_ERROR_KEYS = {"bead_radius_err_m": "m", "viscosity_err_Pa_s": "Pa s",
                    "temperature_err_K": "K"}
DETECTORS = ("camera", "photodiode")
FRICTIONS = ("free", "stokes")
DIODE_FILTERS = ("fit", "none")
_MAX_BEAD_RADIUS_M = 1e-3
# Densities of the beads and fluids of trapping experiments: water 1000, polystyrene 1050,
# silica 2000, gold 19300 kg/m^3. Below 100: g/cm^3 (1.05); above 30000: a typo or g/L*1e3.
_MIN_PLAUSIBLE_DENSITY = 100.0
_MAX_PLAUSIBLE_DENSITY = 3e4


def _real(where: str, key: str, value, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where}: {key} must be a number [{unit}]; got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{where}: {key} must be finite [{unit}]; got {value!r}")
    return v


def _positive(where: str, key: str, value, unit: str) -> float:
    v = _real(where, key, value, unit)
    if not v > 0:
        raise ValueError(f"{where}: {key} must be > 0 [{unit}]; got {key} = {v!r}")
    return v


def _choice(where: str, key: str, value, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        shown = " or ".join(repr(a) for a in allowed)
        raise ValueError(f"{where}: {key} must be {shown}; got {value!r}")
    return value


def _exact_keys(where: str, key: str, value, keys: tuple[str, ...], example: str) -> Mapping:
    if not isinstance(value, Mapping) or set(value) != set(keys):
        got = sorted(value) if isinstance(value, Mapping) else value
        raise ValueError(
            f"{where}: {key} must be an object with exactly the keys {list(keys)} ({example}); "
            f"got {got!r}"
        )
    return value


def _range(where: str, key: str, value, nyquist: float | None) -> tuple[float, float]:
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(f"{where}: {key} must be a pair [fmin, fmax] in Hz; got {value!r}")
    lo = _real(where, key, value[0], "Hz")
    hi = _real(where, key, value[1], "Hz")
    if not 0 <= lo < hi:
        raise ValueError(f"{where}: {key} = [{lo!r}, {hi!r}] Hz: need 0 <= fmin < fmax")
    if nyquist is not None and lo >= nyquist:
        raise ValueError(
            f"{where}: {key} = [{lo!r}, {hi!r}] Hz starts at or above the Nyquist frequency "
            f"{nyquist:.6g} Hz (1 / (2 frame_interval)): no frequencies of the recording are in it"
        )
    return lo, hi


def check_instrument(
    values: Mapping[str, Any],
    where: str,
    *,
    has_stage: bool | None = None,
    nyquist: float | None = None,
    check_units: bool = True,
) -> dict[str, Any]:
    """Validate the instrument keys present in `values` (other keys are ignored; a value of
    None counts as absent).

    **Arguments:**

    - `where`: prefix of every error message (the manifest, entry and file; or the recording).
    - `has_stage`: whether the recording has stage positions (None: unknown, not checked).
    - `nyquist`: ``1 / (2 frame_interval)`` [Hz] when known: fit ranges and the drive must
      lie below it.
    - `check_units`: also reject densities that look like g/cm^3.

    **Returns:** the validated values, JSON-compatible (floats, strings, lists, dicts), for
    the keys given.

    **Raises:** ``ValueError`` naming `where`, the key and the value.
    """
    v = {k: values[k] for k in INSTRUMENT_KEYS if values.get(k) is not None}
    out: dict[str, Any] = {}
    _check_detector(v, where, out)
    _check_bead(v, where, out, check_units)
    _check_drive(v, where, out, has_stage, nyquist)
    _check_inputs_and_ranges(v, where, out, nyquist)
    return out


def _check_detector(v: dict, where: str, out: dict) -> None:
    """``detector``, ``anti_aliasing`` and ``diode_filter`` (validated into `out`)."""
    if "detector" in v:
        out["detector"] = _choice(where, "detector", v["detector"], DETECTORS)
    detector = out.get("detector")
    if "anti_aliasing" in v:
        aa = v["anti_aliasing"]
        if not isinstance(aa, bool):
            raise ValueError(f"{where}: anti_aliasing must be true or false; got {aa!r}")
        if aa and detector != "photodiode":
            raise ValueError(
                f"{where}: anti_aliasing = true needs detector 'photodiode' (an anti-aliasing "
                f"filter sits in front of a photodiode's ADC); detector = {detector!r}. Set "
                '"detector": "photodiode", or remove anti_aliasing'
            )
        out["anti_aliasing"] = aa
    if "diode_filter" in v:
        df = v["diode_filter"]
        if isinstance(df, Mapping):
            _exact_keys(where, "diode_filter", df, ("alpha", "f3db_Hz"),
                        'e.g. {"alpha": 0.3, "f3db_Hz": 8000}')
            alpha = _real(where, "diode_filter alpha", df["alpha"], "1")
            if not 0 <= alpha <= 1:
                raise ValueError(
                    f"{where}: diode_filter alpha = {alpha!r} must lie in [0, 1] (the fraction "
                    "of the signal the diode passes instantly)"
                )
            f3db = _positive(where, "diode_filter f3db_Hz", df["f3db_Hz"], "Hz")
            out["diode_filter"] = {"alpha": alpha, "f3db_Hz": f3db}
        else:
            if not isinstance(df, str) or df not in DIODE_FILTERS:
                raise ValueError(
                    f"{where}: diode_filter must be 'fit', 'none' or an object "
                    f'{{"alpha": a, "f3db_Hz": f}}; got {df!r}'
                )
            out["diode_filter"] = df
        if out["diode_filter"] != "none" and detector != "photodiode":
            raise ValueError(
                f"{where}: diode_filter = {thaw(out['diode_filter'])!r} needs detector "
                f"'photodiode' (the filtering of a silicon photodiode); detector = {detector!r}. "
                'Set "detector": "photodiode", or diode_filter "none"'
            )


def _check_bead(v: dict, where: str, out: dict, check_units: bool) -> None:
    """The bead and its fluid, and ``friction`` (validated into `out`)."""
    radius = None
    if "bead_radius_m" in v:
        radius = _positive(where, "bead_radius_m", v["bead_radius_m"], "m")
        if radius >= _MAX_BEAD_RADIUS_M:
            raise ValueError(
                f"{where}: bead_radius_m = {radius!r} m is not below 1e-3 m: this looks like um "
                "or nm, not metres (a 1 um bead has bead_radius_m = 5e-7)"
            )
        out["bead_radius_m"] = radius
    if "viscosity_Pa_s" in v:
        out["viscosity_Pa_s"] = _positive(where, "viscosity_Pa_s", v["viscosity_Pa_s"], "Pa s")
    if "distance_to_surface_m" in v:
        h = _positive(where, "distance_to_surface_m", v["distance_to_surface_m"], "m")
        if radius is not None and not h > radius:
            raise ValueError(
                f"{where}: distance_to_surface_m = {h!r} m must exceed bead_radius_m = "
                f"{radius!r} m (it is the distance from the surface to the bead's centre)"
            )
        out["distance_to_surface_m"] = h
    for key in ("bead_density_kg_per_m3", "fluid_density_kg_per_m3"):
        if key in v:
            rho = _positive(where, key, v[key], "kg/m^3")
            if check_units and not _MIN_PLAUSIBLE_DENSITY <= rho <= _MAX_PLAUSIBLE_DENSITY:
                hint = (
                    f"this looks like g/cm^3 (did you mean {rho * 1e3:.6g} kg/m^3?)"
                    if rho < _MIN_PLAUSIBLE_DENSITY
                    else "denser than any bead (gold: 19300 kg/m^3)"
                )
                raise ValueError(
                    f"{where}: {key} = {rho!r} kg/m^3 is outside 100..30000 kg/m^3: {hint}. "
                    "Pass kg/m^3 (water 1000, polystyrene 1050), or check_units=false"
                )
            out[key] = rho
    if "hydrodynamics" in v:
        hd = v["hydrodynamics"]
        if isinstance(hd, np.bool_):
            hd = bool(hd)  # e.g. read from HDF5 attributes
        if not (hd is True or hd is False or hd == "auto"):
            raise ValueError(f"{where}: hydrodynamics must be \"auto\", true or false (the "
                             f"known bead's frequency-dependent friction); got {hd!r}")
        out["hydrodynamics"] = hd
    if "friction" in v:
        out["friction"] = _choice(where, "friction", v["friction"], FRICTIONS)
        if out["friction"] == "stokes" and radius is None:
            raise ValueError(
                f"{where}: friction 'stokes' fixes the friction from the bead (6 pi eta r, with "
                "Faxen's correction where distance_to_surface_m is given) and needs "
                "bead_radius_m [m]"
            )


def _check_drive(v: dict, where: str, out: dict, has_stage, nyquist) -> None:
    """``drive`` (validated into `out`): below the Nyquist frequency, with stage positions."""
    if "drive" in v:
        d = _exact_keys(where, "drive", v["drive"], ("frequency_Hz",), 'e.g. {"frequency_Hz": 32}')
        f = _positive(where, "drive frequency_Hz", d["frequency_Hz"], "Hz")
        if nyquist is not None and f >= nyquist:
            raise ValueError(
                f"{where}: drive frequency_Hz = {f!r} Hz is not below the Nyquist frequency "
                f"{nyquist:.6g} Hz (1 / (2 frame_interval))"
            )
        if has_stage is False:
            raise ValueError(
                f"{where}: drive (active calibration at {f!r} Hz) needs the stage positions: a "
                "stage_nm (or stage_um, stage_m) column in the CSV, or Recording(stage=...) [m]"
            )
        out["drive"] = {"frequency_Hz": f}


def _check_inputs_and_ranges(v: dict, where: str, out: dict, nyquist) -> None:
    """The standard errors of the inputs and the frequency ranges (validated into `out`)."""
    for key, unit in INPUT_ERROR_KEYS.items():
        if key in v:
            err = _real(where, key, v[key], unit)
            if err < 0:
                raise ValueError(f"{where}: {key} is a standard error and must be >= 0 "
                                 f"[{unit}]; got {key} = {err!r}")
            out[key] = err
    if "fit_range_Hz" in v:
        out["fit_range_Hz"] = list(_range(where, "fit_range_Hz", v["fit_range_Hz"], nyquist))
    if "excluded_ranges_Hz" in v:
        ex = v["excluded_ranges_Hz"]
        if isinstance(ex, (str, bytes, Mapping)) or not hasattr(ex, "__iter__"):
            raise ValueError(
                f"{where}: excluded_ranges_Hz must be a list of pairs [[a, b], ...] in Hz; got "
                f"{ex!r}"
            )
        out["excluded_ranges_Hz"] = [
            list(_range(where, f"excluded_ranges_Hz[{i}]", r, None)) for i, r in enumerate(ex)
        ]


def instrument_settings(recording) -> dict[str, Any]:
    """The instrument settings of a :class:`Recording`, validated, with the defaults filled in.

    Read from ``recording.metadata`` (where :func:`load_manifest` stores the manifest's keys
    and where Python users may put them: ``Recording(..., metadata={"detector":
    "photodiode"})``).

    **Returns:** a dict with every key of :data:`INSTRUMENT_KEYS`:

    - ``detector``: ``"camera"``, ``"photodiode"``, or None (unknown).
    - ``anti_aliasing``: bool (default False; True only with a photodiode).
    - ``diode_filter``: ``"fit"``, ``"none"``, ``{"alpha": a, "f3db_Hz": f}``, or None (not
      given); a camera's default is ``"none"``.
    - ``bead_radius_m`` [m], ``viscosity_Pa_s`` [Pa s], ``distance_to_surface_m`` [m],
      ``bead_density_kg_per_m3``, ``fluid_density_kg_per_m3`` [kg/m^3]: floats or None.
    - ``friction``: ``"free"`` (default: fitted) or ``"stokes"`` (fixed from the bead).
    - ``hydrodynamics``: ``"auto"`` (default), True or False: the known bead's
      frequency-dependent friction in the model (``calibrate(hydrodynamics=...)``).
    - ``drive``: ``{"frequency_Hz": f}`` or None; with a drive the recording has ``stage``.
    - ``fit_range_Hz``: ``(fmin, fmax)`` or None.
    - ``excluded_ranges_Hz``: a tuple of ``(a, b)`` pairs, or None.
    - ``bead_radius_err_m``, ``viscosity_err_Pa_s``, ``temperature_err_K``: standard errors
      of the Stokes inputs (propagated by ``calibrate``), or None.

    **Raises:** ``ValueError`` naming the recording and the key for an invalid value (the
    checks of :func:`load_manifest`, plus: fit range and drive below the Nyquist frequency, a
    drive needs ``recording.stage``).
    """
    meta = thaw(recording.metadata)
    assert isinstance(meta, dict)  # thaw maps a mapping to a dict
    where = f"recording {recording.name!r}" if recording.name is not None else "recording"
    got = check_instrument(
        meta,
        f"{where}: metadata",
        has_stage=recording.stage is not None,
        nyquist=0.5 / recording.frame_interval,
        check_units=recording.check_units,
    )
    out: dict[str, Any] = {
        "detector": None,
        "anti_aliasing": False,
        "diode_filter": None,
        "bead_radius_m": None,
        "viscosity_Pa_s": None,
        "distance_to_surface_m": None,
        "bead_density_kg_per_m3": None,
        "fluid_density_kg_per_m3": None,
        "friction": "free",
        "hydrodynamics": "auto",
        "drive": None,
        "fit_range_Hz": None,
        "excluded_ranges_Hz": None,
        "bead_radius_err_m": None,
        "viscosity_err_Pa_s": None,
        "temperature_err_K": None,
    }
    if got.get("detector") == "camera":
        out["diode_filter"] = "none"
    out.update(got)
    if out["fit_range_Hz"] is not None:
        out["fit_range_Hz"] = tuple(out["fit_range_Hz"])
    if out["excluded_ranges_Hz"] is not None:
        out["excluded_ranges_Hz"] = tuple(tuple(r) for r in out["excluded_ranges_Hz"])
    return out
