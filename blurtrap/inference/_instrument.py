r"""The instrument around a calibration: detector model, known friction, positions in volts,
an active-calibration stage drive, lines in the spectrum, fitted and excluded bands.

:func:`prepare_instrument` reads the instrument settings of the recordings (the manifest keys
of DESIGN section 5, ``blurtrap.data.instrument_settings``; the calibrate arguments win)
and returns a :class:`Plan`: the model, the held parameters, the cleaned recordings and the
band to fit. :func:`finish_instrument` turns the fit into the reported result: for positions
in volts the displacement sensitivity ``Rd`` [m/V] and the force sensitivity ``Rf = k Rd``
[N/V], with the friction known (``friction="stokes"``: ``gamma = 6 pi eta R``, Faxen's factor
near a surface) or measured by the drive; every input error propagated to first order. With
the bead known, the frequency-dependent (hydrodynamic) friction of :mod:`._hydro_known` joins
the model when ``hydrodynamics`` asks for it or ("auto") when ignoring it would bias the fit.

**Volts.** A trace in volts ``x_V = x / Rd`` is the trap process scaled: fitted as if it were
in metres it gives ``k_V = k Rd^2``, ``gamma_V = gamma Rd^2`` (``tau`` and ``f_c`` are scale
free), ``eps_V^2 = eps^2 / Rd^2``. A known ``gamma`` gives ``Rd = sqrt(gamma_V / gamma)``.

**Active calibration** (Tolic-Norrelykke et al. 2006). A stage (fluid) drive
``x_s = A sin(2 pi f_d t)`` moves the bead relative to the trap by ``H(f_d) x_s``,
``H(f) = i f / (f_c + i f)``; the detector averages over the exposure (``sinc(f_d W)``) and
a photodiode filter multiplies by ``|T(f_d)|``. The measured ratio of the response to the
recorded stage amplitude is ``|r| = sinc(f_d W) |H(f_d)| |T(f_d)| / Rd``, so ``Rd`` follows
from ``r`` and the passive fit's ``f_c`` alone (no Stokes), and then ``gamma = gamma_V / Rd^2``
and ``k = k_V / Rd^2``. With the known bead's hydrodynamics in the model ``H`` is that of
Tolic-Norrelykke et al. (2006) eq. D3 (:mod:`._drive_fit`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._drive_fit import (
    check_drive_frequency,
    check_drive_response,
)
from ._models import TrapModel
from ._options import frequency_ranges

#: the photodiode-with-anti-aliasing fit band ends here (fraction of fs) unless given: a
#: decimating instrument's anti-alias filter starts to cut in above ~0.4-0.45 fs
AA_BAND = 0.4


@dataclasses.dataclass
class Plan:
    recordings: list
    model: TrapModel
    fixed: dict  # {name: (value, se)} held in the fit
    f_range: tuple | None
    excluded: list  # [(a, b)] Hz
    notes: list
    volts: bool = False
    #: known friction (value, se) [N s/m] for the volts transform (volts + stokes)
    gamma_known: tuple | None = None
    #: active calibration: (|r|, se, f_d, exposure, index of the driven recording)
    drive: tuple | None = None
    unit: str = "m"
    #: "camera", "photodiode" or None: the detector the argument or the recordings declare
    detector: str | None = None
    #: the model was given (not implied by the detector settings)
    model_given: bool = False


def _settings(rec) -> dict:
    from ..data import instrument_settings

    return instrument_settings(rec)


def _same(values, what):
    vals = [v for v in values]
    first = vals[0]
    for i, v in enumerate(vals[1:], 1):
        if v != first:
            raise ValueError(f"recordings disagree on {what}: recording 0 has {first!r}, "
                             f"recording {i} has {v!r}; calibrate them separately")
    return first


def _detector_model(st, detector, anti_aliasing, notes) -> TrapModel:
    """The default model from the detector settings (standard for a camera or an
    integrating photodiode; unblurred, unfolded for an anti-aliased photodiode)."""
    det = detector if detector is not None else st["detector"]
    aa = anti_aliasing if anti_aliasing is not None else st["anti_aliasing"]
    if det not in (None, "camera", "photodiode"):
        raise ValueError(f"detector must be 'camera' or 'photodiode' (or None); got "
                         f"detector = {det!r}")
    if aa and det != "photodiode":
        raise ValueError(f"anti_aliasing applies to detector='photodiode'; got detector = "
                         f"{det!r}")
    if aa:
        notes.append("detector: photodiode with anti-aliasing (oversampled and filtered by "
                     "the instrument): no exposure average and no folding in the model")
        return TrapModel(blur=False, alias=False, noise=True, name="photodiode_aa")
    if det == "camera":
        notes.append("detector: camera (exposure average over W, folding at fs)")
    elif det == "photodiode":
        notes.append("detector: photodiode sampled by an integrating ADC (average over the "
                     "exposure W, folding at fs); set anti_aliasing if the instrument "
                     "oversamples and filters")
    return TrapModel(blur=True, alias=True, noise=True, name="standard")


def default_model(settings) -> TrapModel:
    """The model a recording's detector settings imply (as calibrate without `model`)."""
    mdl = _detector_model(settings, None, None, [])
    if settings.get("diode_filter") not in (None, "none"):
        mdl = mdl.add("detector_filter")
    return mdl


def _stokes_gamma(recs, sts):
    """(gamma, se) of the known bead for every recording (Stokes x Faxen); one value."""
    from ..physics import faxen_factor, water_viscosity

    out = []
    for i, (r, st) in enumerate(zip(recs, sts)):
        rad = st["bead_radius_m"]
        if rad is None:
            raise ValueError(f"friction='stokes' needs the bead radius: recording {i} has no "
                             "bead_radius_m (manifest key or metadata)")
        temp = float(r.temperature)

        def gamma_of(radius, eta_given, temperature, st=st):
            eta = eta_given if eta_given is not None else float(water_viscosity(temperature))
            h = st["distance_to_surface_m"]
            fax = 1.0 if h is None else float(faxen_factor(radius, h))
            return 6.0 * math.pi * eta * radius * fax

        eta0 = st["viscosity_Pa_s"]
        g = gamma_of(rad, eta0, temp)
        var = 0.0
        errs = (st["bead_radius_err_m"], st["viscosity_err_Pa_s"], st["temperature_err_K"])
        for which, err in enumerate(errs):
            if not err or (which == 1 and eta0 is None) or (which == 2 and eta0 is not None):
                continue
            args = [rad, eta0, temp]
            args[which] = args[which] + err
            up = gamma_of(*args)
            args[which] = args[which] - 2 * err
            dn = gamma_of(*args)
            var += (0.5 * (up - dn)) ** 2
        out.append((g, math.sqrt(var)))
    g0 = out[0][0]
    if any(abs(g - g0) > 1e-9 * g0 for g, _ in out):
        raise ValueError("friction='stokes': the recordings' beads give different friction "
                         f"({[g for g, _ in out]} N s/m); the fit shares one gamma, so "
                         "calibrate them separately")
    return out[0]


def _clean_lines(recs, sts, lines, notes, excluded):
    """Find strong lines (and the drive) in every recording and subtract them; returns the
    cleaned recordings and the drive response ``(|r|, se, f_d, exposure, i)`` or None."""
    out, drive = [], None
    if lines == "keep" and not any((s["drive"] or {}) for s in sts):
        return list(recs), None
    from ._lines import find_lines, remove_lines

    for i, (r, st) in enumerate(zip(recs, sts)):
        x = np.asarray(r.positions, dtype=float)
        dt = float(r.frame_interval)
        f_d = (st["drive"] or {}).get("frequency_Hz")
        stage = getattr(r, "stage", None)
        if f_d is not None:
            if stage is None:
                raise ValueError(f"recording {i}: a drive at {f_d:g} Hz needs the stage "
                                 "positions (Recording(stage=...) or a stage_nm column)")
            if drive is not None:
                raise ValueError("active calibration from more than one driven recording is "
                                 "not supported yet: calibrate each driven recording alone")
            from ._active import drive_response

            stage = np.asarray(stage, dtype=float)
            resp = drive_response(x, stage, dt, float(r.exposure), frequency=f_d)
            check_drive_frequency(stage, dt, f_d, i)
            check_drive_response(resp, i, str(getattr(r, "position_unit", "m")))
            drive = (abs(resp.ratio), resp.ratio_se, resp.frequency, float(r.exposure), i,
                     resp.ratio)
            notes.append(f"drive: response at {resp.frequency:.6g} Hz to the stage amplitude "
                         f"{resp.stage_amplitude * 1e9:.4g} nm: |x/x_stage| = "
                         f"{abs(resp.ratio):.5g} +- {resp.ratio_se:.2g} "
                         f"{getattr(r, 'position_unit', 'm')} per m (active "
                         "calibration; the line is removed before the passive fit)")
        if lines == "keep":  # other lines kept; the declared drive is removed all the same
            drv = tuple(ln for ln in find_lines(x, dt, known=(resp.frequency,), max_lines=0)
                        if ln.known) if f_d is not None else ()
            out.append(r.replace(positions=remove_lines(x, dt, drv)) if drv else r)
            continue
        from ._frames import _outliers

        if _outliers(r)[0]:
            # isolated spikes (even periodic ones) are not sinusoids: subtracting "lines"
            # would smear them over the trace; the fit's checks name the outliers instead
            out.append(r)
            continue
        known = () if f_d is None else (resp.frequency,)
        found = find_lines(x, dt, known=known)
        if not found:
            out.append(r)
            continue
        desc = ", ".join(f"{ln.frequency:.6g} Hz ({ln.power_ratio:.3g} x the local spectrum)"
                         for ln in found)
        notes.append(f"lines: recording {i} has {len(found)} strong narrow line(s) at {desc}; "
                     "subtracted (least-squares sinusoids, 2 degrees of freedom each) before "
                     "the fit so that they do not bias it (lines='keep' to keep them)")
        out.append(r.replace(positions=remove_lines(x, dt, found)))
    return out, drive


def prepare_instrument(recs, model, model_given, method, *, fixed=None, friction=None,
                       detector=None, anti_aliasing=None, excluded_ranges=None, lines="auto",
                       f_range=None, hydrodynamics=None, likelihood="auto") -> Plan:
    """The plan of a calibration from the recordings' instrument settings and calibrate's
    arguments (which win over the settings); ``hydrodynamics``: the known bead's
    frequency-dependent friction (:mod:`._hydro_known`)."""
    from ._fixed import check_plausible, parse_fixed

    if lines not in ("auto", "keep"):
        raise ValueError(f"lines must be 'auto' (find and subtract strong lines) or 'keep'; "
                         f"got lines = {lines!r}")
    if friction not in (None, "free", "stokes"):
        raise ValueError(f"friction must be 'free' or 'stokes' (or None: the recordings' "
                         f"setting); got friction = {friction!r}")
    sts = [_settings(r) for r in recs]
    notes: list[str] = []
    st = {key: _same([s[key] for s in sts], key)
          for key in ("detector", "anti_aliasing", "diode_filter", "friction")}
    units = {str(getattr(r, "position_unit", "m")) for r in recs}
    if len(units) > 1:
        raise ValueError(f"recordings mix position units {sorted(units)}; calibrate them "
                         "separately")
    unit = units.pop()
    volts = unit == "V"
    mdl = model if model_given else _detector_model(st, detector, anti_aliasing, notes)
    held = parse_fixed(fixed, None)
    check_plausible(held, volts)
    dfilt = st["diode_filter"]
    if dfilt == "fit" and not mdl.has("detector_filter"):
        mdl = mdl.add("detector_filter")
    elif isinstance(dfilt, dict):
        if not mdl.has("detector_filter"):
            mdl = mdl.add("detector_filter")
        held.setdefault("f3db", (float(dfilt["f3db_Hz"]), 0.0))
        held.setdefault("diode_alpha", (float(dfilt["alpha"]), 0.0))
        notes.append(f"diode filter held at f3db = {dfilt['f3db_Hz']:g} Hz, alpha = "
                     f"{dfilt['alpha']:g} (from a previous characterisation)")
    fr = friction if friction is not None else st["friction"]
    gamma_known = None
    if fr == "stokes":
        if "gamma" in held:
            raise ValueError("friction='stokes' and fixed['gamma'] both set gamma; give one")
        g, se = _stokes_gamma(recs, sts)
        if volts:
            gamma_known = (g, se)
        else:
            held["gamma"] = (g, se)
        h = sts[0]["distance_to_surface_m"]
        notes.append(f"friction: Stokes 6 pi eta R = {g * 1e6:.5g} pN s/um from the bead "
                     f"(R = {sts[0]['bead_radius_m'] * 1e6:.4g} um"
                     + (f", Faxen factor at {h * 1e6:.4g} um from the surface" if h else "")
                     + (f"; +- {se / g * 100:.2g} % propagated" if se > 0 else "")
                     + (")" if volts else "), held in the fit"))
    if volts and "gamma" in held:
        gamma_known = held.pop("gamma")
    rng = f_range
    if rng is None and sts[0]["fit_range_Hz"] is not None:
        rng = tuple(_same([tuple(s["fit_range_Hz"] or ()) for s in sts], "fit_range_Hz"))
    aa = anti_aliasing if anti_aliasing is not None else st["anti_aliasing"]
    if rng is None and aa and not mdl.alias and method in ("auto", "likelihood", "psd"):
        rng = (0.0, AA_BAND * min(1.0 / float(r.frame_interval) for r in recs))
        notes.append(f"fit band 0-{rng[1]:.6g} Hz ({AA_BAND:g} fs: below the instrument's "
                     "anti-alias filter; fit_range_Hz to change it)")
    excluded = frequency_ranges(excluded_ranges, "excluded_ranges")
    for s in sts:
        excluded += [r for r in frequency_ranges(s["excluded_ranges_Hz"], "excluded_ranges_Hz")
                     if r not in excluded]
    cleaned, drive = _clean_lines(recs, sts, lines, notes, excluded)
    if volts and gamma_known is None and drive is None:
        raise ValueError("positions are in volts: the displacement sensitivity Rd (m/V) needs "
                         "the friction (friction='stokes' with the bead radius, or "
                         "fixed={'gamma': ...}) or an active calibration (a stage drive)")
    from ._hydro_known import plan_hydrodynamics

    mdl = plan_hydrodynamics(cleaned, sts, mdl, method, hydrodynamics, held, notes, volts=volts,
                             gamma_known=gamma_known, band=rng, excluded=excluded, drive=drive,
                             likelihood=likelihood)
    return Plan(recordings=cleaned, model=mdl, fixed=held, f_range=rng, excluded=excluded,
                notes=notes, volts=volts, gamma_known=gamma_known, drive=drive, unit=unit,
                detector=detector if detector is not None else st["detector"], model_given=model_given)
