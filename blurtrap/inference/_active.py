"""Active calibration: the response to a sinusoidal stage drive gives the detector's
displacement sensitivity ``Rd`` [m per detector unit] without assuming Stokes friction.

The sample stage (and with it the fluid) moves as ``x_s(t) = Re[S e^{2 pi i f_d t}]`` while the
trap stays fixed. The bead, relative to the trap, obeys ``gamma (x' - x_s') = -k x + noise``,
so with the ``e^{+2 pi i f t}`` convention its response is

    ``x = H(f_d) x_s``,  ``H(f) = i f / (f_c + i f)``,  ``f_c = k / (2 pi gamma)``.

A frame ending at ``t_n = n dt`` averages over ``[t_n - W, t_n]``, which multiplies a
sinusoid by ``sinc(f W) e^{-i pi f W}`` (``sinc(u) = sin(pi u)/(pi u)``); a detector with
its own transfer ``T(f)`` (photodiode low-pass) multiplies it by ``T(f_d)``; the detector
reports ``x / Rd``. Fitting cos and sin at ``f_d`` to the recorded stage (``S`` [m], sampled at
``t_n``) and to the positions (``X`` [detector unit]) gives

    ``X / S = sinc(f_d W) e^{-i pi f_d W} H(f_d) T(f_d) / Rd``,

hence ``Rd = sinc(f_d W) |H(f_d)| |T(f_d)| / |X/S|``.

**Hydrodynamic friction** (Tolic-Norrelykke et al. 2006, appendix D, eq. D3). A bead whose
friction depends on frequency, ``G(f) = gamma(f)/gamma`` relative to its zero-frequency
friction ``gamma`` (complex, in the sign convention of eqs. D4/D6 and of
``blurtrap.physics.complex_friction``, whose ``e^{-2 pi i f t}`` convention makes
``Im G < 0``; the fluid's added mass included), and with the bead's own inertia,
``f_m = gamma/(2 pi m_bead)``, responds with

    ``H(f) = i f G*/(f_c - f^2/f_m + i f G*)``,  ``|H| = f |G| / sqrt(a^2 + b^2)``,
    ``a = f_c + f Im G - f^2/f_m``,  ``b = f Re G``

(``G*`` the complex conjugate: this module's ``e^{+2 pi i f t}`` convention); ``G = 1``,
``f_m = inf`` give the Lorentzian ``H`` above. Then ``d ln|H|/d f_c = -a/(a^2 + b^2)`` and
``arg H = pi/2 - arg G - atan2(b, a)`` with ``d arg H/d f_c = b/(a^2 + b^2)``. The phase of ``X/S`` must equal
``arg H - pi f_d W + arg T = pi/2 - atan(f_d/f_c) - pi f_d W + arg T``; a mismatch means the
model is wrong: e.g. a trace that records the bead relative to the stage, ``(H - 1) x_s``
(off by +pi/2 at every f_d, since ``(H - 1)/H = i f_c/f_d``), an inverted detector (off by
pi) or a stage sampled elsewhere than at the end of the exposure.

**References:** Tolic-Norrelykke, Schaffer, Howard, Pavone, Julicher & Flyvbjerg (2006), Rev.
Sci. Instrum. 77, 103101 (eqs. 4-7: the response to a fluid drive; section IV: Rd from the
drive's spike; appendix D, eqs. D3, D4 and D6: the same with hydrodynamic friction).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._sinusoids import (
    check_frequency,
    check_positive,
    check_trace,
    component,
    fit_sinusoids,
    line_errors,
    periodogram,
    refine_frequency,
)

__all__ = ["DriveResponse", "DisplacementSensitivity", "drive_response", "displacement_sensitivity",
           "fluid_response"]

_GUARD_BINS = 2  # bins either side of the drive left out of the local noise estimate
_MIN_NOISE_BINS, _MAX_NOISE_BINS = 60, 4000
_MIN_STAGE_SNR = 10.0  # the stage's drive amplitude in units of its standard error


class DriveResponse(NamedTuple):
    """The response of a trace to a sinusoidal stage drive (:func:`drive_response`).

    Components are ``amplitude cos(2 pi frequency t_n + phase)`` with ``t_n = n dt``.

    - `frequency` [Hz] and `frequency_se` [Hz] (0 when the frequency was given).
    - `stage_amplitude` [m], `stage_phase` [rad]: the stage's sinusoid, ``S = A e^{i phase}``.
    - `response_amplitude` [detector unit], `response_phase` [rad]: the positions' one, ``X``.
    - `ratio`: ``X / S`` [detector unit per m], complex.
    - `ratio_se`: standard error of ``Re(ratio)`` and of ``Im(ratio)`` (each; the thermal noise
      is circular), so also of ``|ratio|``; ``ratio_se/|ratio|`` is the SE of its phase [rad].
    - `noise_psd`: the positions' two-sided thermal PSD near the drive [unit^2/Hz] and
      `noise_bins` the number of periodogram ordinates it is the mean of.
    - `exposure` [s] and `frame_interval` [s], as given.
    """

    frequency: float
    frequency_se: float
    stage_amplitude: float
    stage_phase: float
    response_amplitude: float
    response_phase: float
    ratio: complex
    ratio_se: float
    noise_psd: float
    noise_bins: int
    exposure: float
    frame_interval: float


class DisplacementSensitivity(NamedTuple):
    """``Rd`` from a drive response (:func:`displacement_sensitivity`).

    - `value` [m per detector unit] and `se` (delta method: the ratio's and f_c's errors).
    - `phase_mismatch` [rad]: measured ``arg(X/S)`` minus the predicted phase, in (-pi, pi];
      `phase_mismatch_se` its SE. ``|mismatch| >> SE`` flags a wrong model or drive mode.
    - `transfer`: the predicted ``sinc(f_d W) e^{-i pi f_d W} H(f_d) T(f_d)`` (complex), so that
      ``X/S = transfer / Rd``.
    """

    value: float
    se: float
    phase_mismatch: float
    phase_mismatch_se: float
    transfer: complex


def _local_psd(resid, dt: float, freq: float):
    """Mean periodogram of ``resid`` over the ordinates nearest ``freq`` (+-10 % of it, at least
    60 ordinates), leaving out +-2 bins around it and the Nyquist ordinate: ``(psd, n_bins)``."""
    n = resid.size
    f, power = periodogram(resid, dt)
    j0 = freq * n * dt
    j = np.arange(1, f.size + 1)
    ok = np.abs(j - j0) > _GUARD_BINS
    if n % 2 == 0:
        ok[-1] = False
    want = int(np.clip(round(0.2 * j0), _MIN_NOISE_BINS, _MAX_NOISE_BINS))
    pick = np.argsort(np.abs(j[ok] - j0), kind="stable")[:want]
    if pick.size < 10:
        raise ValueError(f"positions: only {pick.size} periodogram ordinates near the drive at "
                         f"{freq:.6g} Hz to estimate the thermal noise; record at least 64 frames.")
    return float(np.mean(power[ok][pick])), int(pick.size)


def _sinusoid(y, dt: float, freq: float):
    """Complex amplitude (about t = 0, the first frame) of the sinusoid at ``freq`` and the residual."""
    part, coef = fit_sinusoids(y, dt, [freq])
    t_mid = 0.5 * (y.size - 1) * dt
    amp = complex(coef[1], -coef[2]) * np.exp(-2j * np.pi * freq * t_mid)
    return amp, y - part - coef[0], coef


def drive_response(positions, stage, frame_interval, exposure, *, frequency=None) -> DriveResponse:
    """The complex response ``X/S`` of a trace to a recorded sinusoidal stage drive.

    **Arguments:**

    - `positions`: 1-D trace of the bead [detector unit, e.g. V], frames ending at ``t_n = n dt``.
    - `stage`: the stage position [m] sampled at the same ``t_n`` (same length).
    - `frame_interval`: dt [s]; `exposure`: W [s], ``0 <= W <= dt`` (kept for
      :func:`displacement_sensitivity`; the fit itself does not depend on it).
    - `frequency`: the drive frequency [Hz] in (0, Nyquist); when None it is found from the
      stage (the largest ordinate of its periodogram, refined by least squares) with its SE.

    Both traces are fitted with the mean, cos and sin at the drive frequency. The ratio's SE is
    the thermal noise's: with ``P_x`` the positions' two-sided PSD near f_d (mean of about
    ``0.2 f_d N dt`` periodogram ordinates of the residual, +-2 bins left out, so its own relative
    error is below 13 % and that of the SE below 7 %) and ``T = N dt``, each quadrature of ``X``
    has variance ``2 P_x / T``; the stage's noise enters likewise:
    ``ratio_se^2 = (2 P_x/T + |X/S|^2 2 P_s/T) / |S|^2``.

    **Returns:** a :class:`DriveResponse`.

    **Raises:** ``ValueError`` for traces that are not 1-D and finite or differ in length, a
    non-positive frame interval, an exposure outside [0, frame_interval], a frequency outside
    (0, Nyquist), or a stage without a clear sinusoid (amplitude below 10 standard errors).
    """
    x, dt = check_trace(positions, frame_interval, "positions", min_frames=64)
    s, _ = check_trace(stage, dt, "stage", min_frames=64)
    if s.size != x.size:
        raise ValueError(f"stage must have one sample per frame of positions ({x.size}); got {s.size}.")
    try:
        w = float(exposure)
    except (TypeError, ValueError):
        w = np.nan
    if not (np.isfinite(w) and 0.0 <= w <= dt * (1 + 1e-12)):
        raise ValueError(f"exposure must be in [0, frame_interval = {dt:.6g}] s; got {exposure!r}.")
    n, dur = x.size, x.size * dt
    if frequency is None:
        f_stage, p_stage = periodogram(s, dt)
        top = f_stage.size - 1 if n % 2 == 0 else f_stage.size
        j = int(np.argmax(p_stage[:top]))
        freq = refine_frequency(s, dt, float(f_stage[j]), 0.6 / dur)
    else:
        freq = check_frequency(frequency, dt, "frequency")
    s_amp, s_res, s_coef = _sinusoid(s, dt, freq)
    x_amp, x_res, _ = _sinusoid(x, dt, freq)
    psd_s, _ = _local_psd(s_res, dt, freq)
    psd_x, n_bins = _local_psd(x_res, dt, freq)
    s_se = np.sqrt(2 * psd_s / dur)
    if not abs(s_amp) > _MIN_STAGE_SNR * s_se:
        raise ValueError(f"stage shows no clear drive at {freq:.6g} Hz: amplitude {abs(s_amp):.3g} m "
                         f"against a standard error of {s_se:.3g} m (need > {_MIN_STAGE_SNR:g}x).")
    f_se = 0.0
    if frequency is None:
        f_se = line_errors(s_res + component(n, dt, freq, s_coef[1], s_coef[2]), dt, freq, psd_s)[0]
    ratio = x_amp / s_amp
    ratio_se = np.sqrt((2 * psd_x / dur + abs(ratio) ** 2 * 2 * psd_s / dur) / abs(s_amp) ** 2)
    return DriveResponse(float(freq), float(f_se), float(abs(s_amp)), float(np.angle(s_amp)),
                         float(abs(x_amp)), float(np.angle(x_amp)), complex(ratio), float(ratio_se),
                         psd_x, n_bins, w, dt)


def _transfer_value(detector_transfer, freq: float) -> complex:
    if detector_transfer is None:
        return 1.0 + 0.0j
    t = detector_transfer(freq) if callable(detector_transfer) else detector_transfer
    try:
        t = complex(np.asarray(t).item())
    except (TypeError, ValueError):
        raise ValueError("detector_transfer must be a complex number or a callable f -> T(f); "
                         f"got {detector_transfer!r}.") from None
    if not (np.isfinite(t.real) and np.isfinite(t.imag) and t != 0):
        raise ValueError(f"detector_transfer at the drive frequency {freq:.6g} Hz must be finite and "
                         f"non-zero; got {t!r}.")
    return t


def fluid_response(drive_frequency, corner_frequency, friction: complex = 1.0,
                   dissipation_frequency=None):
    """The bead's response ``H(f_d)`` to a fluid (stage) drive and the two slopes the errors need.

    ``H = i f G*/(f_c - f^2/f_m + i f G*)`` (module docstring; TN 2006 eq. D3 in this module's
    sign convention). `friction` is ``G(f_d) = gamma(f_d)/gamma`` in the sign convention of
    ``blurtrap.physics.complex_friction`` (1: frequency-independent); `dissipation_frequency`
    ``f_m = gamma/(2 pi m_bead)`` [Hz] (None: no inertia).

    **Returns:** ``(H, dln|H|/df_c, darg H/df_c)``, the slopes ``-a/(a^2 + b^2)`` and
    ``b/(a^2 + b^2)`` [1/Hz] with ``a = f_c + f Im G - f^2/f_m``, ``b = f Re G``.
    """
    fd, fc, g = float(drive_frequency), float(corner_frequency), complex(friction)
    inertia = 0.0 if dissipation_frequency is None else fd * fd / float(dissipation_frequency)
    a = fc + fd * g.imag - inertia
    b = fd * g.real
    h = 1j * fd * g.conjugate() / complex(a, b)
    d2 = a * a + b * b
    return h, -a / d2, b / d2


def displacement_sensitivity(ratio, ratio_se, corner_frequency, corner_frequency_se, drive_frequency,
                             exposure, detector_transfer=None, *, friction=1.0,
                             dissipation_frequency=None) -> DisplacementSensitivity:
    """Displacement sensitivity ``Rd`` [m per detector unit] from the drive response ``X/S``.

    ``Rd = sinc(f_d W) |H(f_d)| |T(f_d)| / |X/S|`` with :func:`fluid_response`'s ``H``
    (``|H| = f_d / sqrt(f_c^2 + f_d^2)`` without hydrodynamics; module docstring). Delta
    method, the ratio and f_c independent:
    ``(se/Rd)^2 = (ratio_se/|X/S|)^2 + (dln|H|/df_c)^2 corner_frequency_se^2``.
    Phase check: ``mismatch = arg(X/S) - [arg H - pi f_d W + arg T]`` wrapped to (-pi, pi],
    ``se^2 = (ratio_se/|X/S|)^2 + (darg H/df_c)^2 corner_frequency_se^2``.

    **Arguments:** `ratio` (complex ``X/S`` [unit/m]) and `ratio_se` (SE of each quadrature, as
    :class:`DriveResponse`); `corner_frequency` f_c [Hz] (from a passive fit; it carries no length
    unit) and its SE; `drive_frequency` f_d [Hz]; `exposure` W [s]; `detector_transfer`: None, the
    complex ``T(f_d)``, or a callable ``f -> T(f)`` (e.g. a photodiode's low-pass);
    `friction`: the complex ``G(f_d) = gamma(f_d)/gamma`` (TN 2006 eqs. D4/D6, the sign
    convention of ``blurtrap.physics.complex_friction``; default 1) and
    `dissipation_frequency` ``f_m = gamma/(2 pi m_bead)`` [Hz] (default None: no inertia), for
    a bead with hydrodynamic friction (``blurtrap.inference._hydro_drive.drive_friction``).

    **Returns:** a :class:`DisplacementSensitivity`. With ``Rd``, the passive fit's diffusion in
    detector units gives ``D = Rd^2 D_unit``, ``gamma = kT/D`` and ``k = 2 pi gamma f_c``.

    **Raises:** ``ValueError`` for a zero or non-finite ratio, negative SEs, non-positive
    frequencies, a negative exposure, a zero transfer, a non-finite friction with
    ``Re G <= 0``, or a non-positive dissipation frequency.
    """
    try:
        r = complex(np.asarray(ratio).item())
    except (TypeError, ValueError):
        raise ValueError(f"ratio must be a complex number X/S [unit/m]; got {ratio!r}.") from None
    if not (np.isfinite(r.real) and np.isfinite(r.imag) and r != 0):
        raise ValueError(f"ratio must be finite and non-zero; got {ratio!r}.")
    r_se = _non_negative(ratio_se, "ratio_se", "unit/m")
    fc = check_positive(corner_frequency, "corner_frequency", "Hz")
    fc_se = _non_negative(corner_frequency_se, "corner_frequency_se", "Hz")
    fd = check_positive(drive_frequency, "drive_frequency", "Hz")
    w = _non_negative(exposure, "exposure", "s")
    t = _transfer_value(detector_transfer, fd)
    g = _friction_value(friction)
    fm = None if dissipation_frequency is None else check_positive(
        dissipation_frequency, "dissipation_frequency", "Hz")
    h, dlog_fc, darg_fc = fluid_response(fd, fc, g, fm)
    transfer = np.sinc(fd * w) * np.exp(-1j * np.pi * fd * w) * h * t
    rd = abs(transfer) / abs(r)
    rel_r = r_se / abs(r)
    se = rd * np.hypot(rel_r, dlog_fc * fc_se)
    mismatch = float(np.angle(r / transfer))
    return DisplacementSensitivity(float(rd), float(se), mismatch,
                                   float(np.hypot(rel_r, darg_fc * fc_se)), complex(transfer))


def _friction_value(friction) -> complex:
    try:
        g = complex(np.asarray(friction).item())
    except (TypeError, ValueError):
        g = complex(np.nan)
    if not (np.isfinite(g.real) and np.isfinite(g.imag) and g.real > 0):
        raise ValueError("friction must be the complex friction ratio gamma(f_d)/gamma, finite "
                         f"with a positive real part (dimensionless); got friction = {friction!r}.")
    return g


def _non_negative(value, name: str, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number >= 0 [{unit}]; got {value!r}.") from None
    if not (np.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be a finite number >= 0 [{unit}]; got {value!r}.")
    return v
