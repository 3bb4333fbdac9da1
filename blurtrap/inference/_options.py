"""Validation of ``calibrate``'s options: nothing given is ignored silently, and a bad value
is named with what was expected."""

from __future__ import annotations

import math
import numbers

import numpy as np

_K_MODES = (None, "shared", "per_recording", "per_power", "linear_power")
#: D of a 1 nm sphere in water is ~2e-10 m^2/s: anything above this is a unit slip.
_MAX_PLAUSIBLE_DIFFUSION = 1e-8
#: D of a 50 um bead in glycerol near 0 C (12 Pa s) is ~4e-19 m^2/s: anything below this
#: is a unit slip (m^2/s given to the CLI's um^2/s option: 1.5e-13 "um^2/s" = 1.5e-25 m^2/s)
_MIN_PLAUSIBLE_DIFFUSION = 1e-19


def _check_options(recs, method, likelihood, k, n_blocks, f_range, diffusion, pade, start,
                   strict):
    """Validate calibrate's options; nothing given is ignored silently."""
    if k not in _K_MODES:
        raise ValueError(f"k must be one of {_K_MODES[1:]} (or None for the default); "
                         f"got k = {k!r}")
    if not isinstance(strict, (bool, np.bool_)):
        raise ValueError(f"strict must be True or False; got strict = {strict!r}")
    if not isinstance(pade, (bool, np.bool_)):
        raise ValueError(f"pade must be True or False; got pade = {pade!r}")
    n_blocks = _check_n_blocks(method, n_blocks)
    if f_range is not None:
        f_range = _check_f_range(recs, method, likelihood, f_range)
    _check_diffusion(method, diffusion, pade)
    if start is not None:
        _check_start(start)
    return n_blocks, f_range


def _check_n_blocks(method, n_blocks):
    """``n_blocks`` as an int (None when not given); only with method='psd'."""
    if n_blocks is not None:
        if isinstance(n_blocks, bool) or not isinstance(n_blocks, numbers.Integral) \
                or n_blocks < 1:
            raise ValueError(f"n_blocks must be an integer >= 1 (number of non-overlapping "
                             f"blocks); got n_blocks = {n_blocks!r}")
        if method != "psd":
            raise ValueError(f"n_blocks = {n_blocks!r} applies only to method='psd'; got "
                             f"method = {method!r}")
        n_blocks = int(n_blocks)
    return n_blocks


def _check_f_range(recs, method, likelihood, f_range):
    """``f_range`` as ``(f_min, f_max)`` floats [Hz] within (0, fs/2]; spectral fits only."""
    if method in ("equipartition", "variance_vs_exposure", "variance_vs_power") or \
            (method in ("auto", "likelihood") and likelihood == "exact"):
        raise ValueError(f"f_range = {f_range!r} applies only to the spectral methods "
                         "(method='psd', or the Whittle likelihood); got method = "
                         f"{method!r}, likelihood = {likelihood!r}")
    lo, hi = frequency_pair(f_range, "f_range")
    nyq = max(0.5 / float(r.frame_interval) for r in recs)
    if lo >= nyq:
        raise ValueError(f"f_range = ({lo:g}, {hi:g}) Hz starts above the Nyquist "
                         f"frequency {nyq:g} Hz of the recordings (f_range is in Hz, not kHz)")
    if hi > nyq * (1.0 + 1e-9):
        raise ValueError(f"f_range = ({lo:g}, {hi:g}) Hz: f_max = {hi:g} Hz is above the "
                         f"Nyquist frequency fs/2 = {nyq:g} Hz of the recordings, where "
                         "there are no ordinates; expected f_max <= fs/2 (f_range is in "
                         "Hz, not kHz)")
    _check_band_ordinates(recs, lo, hi)
    return (lo, hi)


#: a spectral fit over fewer periodogram ordinates than this (all recordings, at the full
#: record's spacing 1/T) is refused: three or four parameters cannot be fitted from them
_MIN_BAND_ORDINATES = 16


def _check_band_ordinates(recs, lo: float, hi: float) -> None:
    """``f_range`` keeps at least :data:`_MIN_BAND_ORDINATES` ordinates (an independent
    pass: ``--f-range 0.1 0.5`` meant in kHz kept 2 ordinates and ended in "did not
    converge ... check the data")."""
    count = 0
    for r in recs:
        t = r.n_frames * float(r.frame_interval)
        count += max(0, math.floor(hi * t) - math.ceil(lo * t) + 1)
    if count >= _MIN_BAND_ORDINATES:
        return
    t_max = max(r.n_frames * float(r.frame_interval) for r in recs)
    nyq = max(0.5 / float(r.frame_interval) for r in recs)
    khz = (f"; f_range is in Hz: did you mean ({lo * 1e3:g}, {hi * 1e3:g}) Hz?"
           if hi * 1e3 <= nyq * (1.0 + 1e-9) else "")
    raise ValueError(f"f_range = ({lo:g}, {hi:g}) Hz keeps only {count} periodogram "
                     f"ordinate(s) of the recordings (spacing 1/T = {1.0 / t_max:.3g} Hz at "
                     f"best), too few to fit the trap's parameters: expected at least "
                     f"{_MIN_BAND_ORDINATES}{khz}")


def band_sentence(recs, f_range, excluded) -> str:
    """Names the band a failed spectral fit was confined to by the caller's `f_range` and
    `excluded` ranges [Hz] (a narrow band away from the corner frequency leaves k and gamma
    unidentified, which the frames alone cannot show); empty without either."""
    if f_range is None and not excluded:
        return ""
    kept = total = 0
    for r in recs:
        t = r.n_frames * float(r.frame_interval)
        f = np.arange(1, r.n_frames // 2 + 1) / t
        keep = np.ones(f.size, bool) if f_range is None else (f >= f_range[0]) & (f <= f_range[1])
        for a, b in excluded or ():
            keep &= ~((f >= a) & (f <= b))
        kept, total = kept + int(keep.sum()), total + f.size
    band = [f"f_range = ({f_range[0]:g}, {f_range[1]:g}) Hz"] if f_range is not None else []
    band += [f"excluded_ranges = {[(float(a), float(b)) for a, b in excluded]} Hz"] if excluded else []
    return (f" The fit was confined to {' and '.join(band)}: {kept} of the {total} periodogram "
            "ordinates. k and gamma are identified by the band around the corner frequency "
            "k/(2 pi gamma) and eps^2 by the highest frequencies: widen f_range (or leave "
            "it out) and exclude only narrow bands.")


def _check_diffusion(method, diffusion, pade):
    """A given D [m^2/s] is finite, > 0 and plausible, and only for equipartition/auto;
    ``pade=True`` needs it."""
    if diffusion is not None:
        if method not in ("equipartition", "auto"):
            raise ValueError(f"diffusion = {diffusion!r} is used only by method='equipartition' "
                             f"(and by 'auto' when frames carry no temporal information); got "
                             f"method = {method!r}")
        d = float(diffusion) if isinstance(diffusion, numbers.Real) and not isinstance(
            diffusion, bool) else math.nan
        if not (math.isfinite(d) and d > 0):
            raise ValueError(f"diffusion (diffusion coefficient D) must be finite and > 0 "
                             f"m^2/s; got diffusion = {diffusion!r}")
        if d < _MIN_PLAUSIBLE_DIFFUSION:
            raise ValueError(
                f"diffusion = {d:g} m^2/s ({d * 1e12:g} um^2/s) is implausibly small (a 50 um "
                "bead in glycerol has D ~ 4e-19 m^2/s; a 1 um bead in water 2e-13 m^2/s): "
                "check its unit. D is in m^2/s in Python (1 um^2/s = 1e-12 m^2/s); the CLI's "
                "--diffusion takes um^2/s")
        if d > _MAX_PLAUSIBLE_DIFFUSION:
            raise ValueError(
                f"diffusion = {d:g} m^2/s is implausibly large (a 1 nm sphere in water has "
                f"D ~ 2e-10 m^2/s): it looks like um^2/s. D is in SI units: 1 um^2/s = 1e-12 m^2/s"
            )
    elif pade:
        raise ValueError("pade=True selects the Pade inversion of blur-corrected equipartition "
                         "and needs diffusion=D; got diffusion=None")


def _check_start(start):
    """Start values: a dict of finite numbers > 0 (SI) by parameter name."""
    if not isinstance(start, dict):
        raise ValueError(f"start must be a dict of start values by parameter name; got "
                         f"{type(start).__name__}")
    for name, v in start.items():
        ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v) \
            and v > 0  # pyright: ignore[reportOperatorIssue]  # numbers.Real orders
        if not ok:
            raise ValueError(f"start[{name!r}] must be a finite number > 0 (SI units); got "
                             f"{v!r}")


def _flag(name, value) -> bool:
    """A True/False option as a bool; anything else is a ValueError naming it."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False; got {name} = {value!r}")
    return bool(value)


def frequency_ranges(value, what):
    """``[(f_low, f_high), ...]`` [Hz] from a list of pairs (``what`` names the argument in
    errors); each needs 0 <= f_low < f_high."""
    try:
        pairs = list(value or ())
    except TypeError:
        raise ValueError(f"{what} must be a list of [f_low, f_high] pairs in Hz; got "
                         f"{value!r}") from None
    return [frequency_pair(pair, f"{what}[{i}]") for i, pair in enumerate(pairs)]


def frequency_pair(pair, what):
    """``(f_low, f_high)`` floats [Hz] from two numbers with 0 <= f_low < f_high (finite);
    errors name ``what`` and the value."""
    try:
        lo, hi = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be two numbers (f_low, f_high) in Hz; got "
                         f"{what} = {pair!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise ValueError(f"{what} must satisfy 0 <= f_low < f_high (finite, Hz); got "
                         f"{what} = ({lo!r}, {hi!r})")
    return lo, hi


def _default_k_mode(recs):
    """One k per laser power when the recordings' powers differ, else one shared k."""
    powers = [r.laser_power for r in recs]
    missing = [i for i, p in enumerate(powers) if p is None]
    if missing and len(missing) < len(recs):  # a slip: the declared powers would be dropped
        raise ValueError(f"laser_power is given on recordings {[i for i in range(len(recs)) if i not in missing]} "
                         f"but missing on recordings {missing}: give every recording's laser_power (one k "
                         "per power), or fit one k to all (k='shared'; --k-mode shared on the command line)")
    if not missing and len({float(p) for p in powers}) > 1:
        return "per_power"
    return "shared"
