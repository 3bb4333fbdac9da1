"""What the frames themselves show before any fit: temporal information (lag-1 correlation),
outliers, saturation (clipping) and coarse quantisation."""

from __future__ import annotations

import math

import numpy as np

from ._chi2 import f_sf
from ._glitches import glitch_note
from ._variance import empirical_variance_se


def temporal_information(rec, z_min=5.0):
    """Whether frames carry information on the relaxation time: the lag-1 autocorrelation
    is significantly positive, ``r1 sqrt(N) > z_min`` (under white frames r1 sqrt(N) is
    standard normal). Frames lose it when dt >> tau (and W << dt), or when the tracking noise
    swamps the motion. Returns ``(informative, z)``."""
    y = np.asarray(rec.positions, dtype=float)
    y = y - y.mean()
    n = y.size
    if n < 8:
        return False, 0.0
    c0 = float(np.mean(y * y))
    c1 = float(np.mean(y[1:] * y[:-1]))
    z = c1 / c0 * math.sqrt(n) if c0 > 0 else 0.0
    return bool(z > z_min), z


#: a frame this many robust SDs (1.4826 x median absolute deviation) from the median is an
#: outlier (a Gaussian trace of 1e7 frames reaches ~5.5)
_OUTLIER_Z = 8.0


def _outliers(rec):
    """``(count, index, value, robust SDs)`` of frames more than ``_OUTLIER_Z`` robust SDs
    from the median (count 0 when there are none)."""
    y = np.asarray(rec.positions, dtype=float)
    med = float(np.median(y))
    mad = 1.4826 * float(np.median(np.abs(y - med)))
    if not mad > 0:
        return 0, 0, float(y[0]), 0.0
    dev = np.abs(y - med) / mad
    j = int(np.argmax(dev))
    return int(np.sum(dev > _OUTLIER_Z)), j, float(y[j]), float(dev[j])


def _robust_temporal_z(rec) -> float:
    """The lag-1 statistic of :func:`temporal_information` with the frames clipped to the
    median +- ``_OUTLIER_Z`` robust SDs: a few outliers dominate the variance and hide the
    correlation of all other frames (identical to the plain statistic without outliers)."""
    y = np.asarray(rec.positions, dtype=float)
    med = float(np.median(y))
    mad = 1.4826 * float(np.median(np.abs(y - med)))
    if mad > 0:
        y = np.clip(y, med - _OUTLIER_Z * mad, med + _OUTLIER_Z * mad)
    y = y - y.mean()
    if y.size < 8:
        return 0.0
    c0 = float(np.mean(y * y))
    return float(np.mean(y[1:] * y[:-1])) / c0 * math.sqrt(y.size) if c0 > 0 else 0.0


def _outlier_sentence(recs, z_min=5.0) -> str:
    """A sentence on outliers that hide the lag correlation ('' when there are none)."""
    for i, r in enumerate(recs):
        n_out, j, val, dev = _outliers(r)
        if n_out:
            zr = _robust_temporal_z(r)
            hides = (f"with them clipped the lag-1 correlation is {zr:.1f} standard errors "
                     "above 0, so the frames do resolve the relaxation: remove the outliers "
                     "(or the stretch around them) and fit again" if zr > z_min else
                     "remove them (or the stretch around them)")
            return (f"outliers: recording {i} has {n_out} frame(s) more than {_OUTLIER_Z:g} "
                    f"robust SDs from its median (frame {j}: {val:.4g} m, {dev:.3g} SDs); "
                    + hides)
    return ""


#: mean-shift test: segments, the most sub-blocks per segment, the sub-block length in
#: relaxation times (batch means need blocks much longer than the correlation time), the
#: significance and the smallest spread of the segment means (x the frames' std) noted
_SHIFT_SEGMENTS = 16
_SHIFT_SUB = 8
_SHIFT_SUB_TAU = 20.0
_SHIFT_ALPHA = 1e-6
_SHIFT_MIN_SPREAD = 0.25


def _detrended_var(means: np.ndarray) -> np.ndarray:
    """Per row: the variance (ddof 2) of the sub-block means about their own straight line,
    so that a drift across the record leaves the within-segment scatter alone."""
    b = means.shape[1]
    t = np.arange(b) - 0.5 * (b - 1)
    centred = means - means.mean(axis=1, keepdims=True)
    slope = centred @ t / float(t @ t)
    resid = centred - slope[:, None] * t
    return np.sum(resid * resid, axis=1) / (b - 2)


def segment_tau(seg) -> float | None:
    """The correlation time [frames] of the detrended segments ``seg`` (n_seg, m): the first
    lag at which their autocovariance (median over segments, by FFT) falls below 1/e of its
    lag-1 value (white tracking or detector noise sits at lag 0 only, so lag 1 is the
    reference); None when it does not within m/4 lags."""
    m = seg.shape[1]
    spec = np.fft.rfft(seg, n=2 * m, axis=1)
    acov = np.median(np.fft.irfft(spec * np.conj(spec), axis=1)[:, : m // 4], axis=0) / m
    if not acov[1] > 0:
        return 0.0
    below = np.flatnonzero(acov[1:] < acov[1] / math.e)
    if below.size == 0:
        return None
    return float(below[0])  # lags from 1: the 1/e lag minus one, ~tau for a trap


def mean_shift(y) -> dict | None:
    """Whether the mean position moves across the record (a step, or a drift), by batch
    means: the record is cut into 16 segments; each segment's own scatter of sub-block means
    about their straight line (median over segments, so that a step inside one segment
    does not inflate it) estimates the long-run variance, hence the expected scatter of the
    segment means under stationarity; their observed scatter gives
    ``chi2 = sum (m_j - m)^2 / var_j`` with 15 degrees of freedom, referred to an F
    distribution (the denominator is estimated). Sub-blocks are >= 20 relaxation times long
    (tau: the lag where the autocovariance falls to 1/e of its lag-1 value, so that white
    noise does not shorten it), and the sub-block means must have levelled off (half-length
    ones give the same long-run variance within 50 %), else no test (``None``): stationary
    records with 5-30 % white noise and tau = 30-2000 frames gave 0 flags in 320. Returns ``{"chi2", "dof", "p",
    "spread" (max - min of the segment means), "std", "jump", "at" (the largest jump between
    neighbouring segments and the frame where it is), "step" (one jump carries most of the
    spread), "significant"}``."""
    y = np.asarray(y, dtype=float)
    n_seg = _SHIFT_SEGMENTS
    m = y.size // n_seg
    if m < 32:
        return None
    seg = y[: m * n_seg].reshape(n_seg, m)
    # each segment about its own straight line: a drift steep enough to dominate a segment
    # (a 30-std ramp) would otherwise stretch the autocovariance past m/4 lags (no test)
    t_seg = np.arange(m) - 0.5 * (m - 1)
    seg = seg - seg.mean(axis=1, keepdims=True)
    seg = seg - np.outer(seg @ t_seg / float(t_seg @ t_seg), t_seg)
    tau = segment_tau(seg)
    if tau is None:
        return None
    b = min(_SHIFT_SUB, int(m / (_SHIFT_SUB_TAU * max(tau, 1.0))))
    if b < 4:
        return None
    ms = m // b
    rows = y[: m * n_seg].reshape(n_seg, m)
    means = rows[:, : ms * b].reshape(n_seg, b, ms).mean(axis=2)
    within = _detrended_var(means)  # ~ lrv / ms x chi2_{b-2}/(b-2)
    # the batch means must have levelled off: sub-blocks half as long give the same long-run
    # variance (var x length) when they are long compared with the correlation time
    half = rows[:, : (ms // 2) * 2 * b].reshape(n_seg, 2 * b, ms // 2).mean(axis=2)
    lrv_half = float(np.median(_detrended_var(half))) * (ms // 2)
    lrv = float(np.median(within)) * ms
    if not (lrv > 0 and lrv < 1.5 * lrv_half):
        return None
    k = b - 2
    med_chi2 = k * (1.0 - 2.0 / (9.0 * k)) ** 3 / k  # median of chi2_k / k (Wilson-Hilferty)
    var_sub = float(np.median(within)) / med_chi2
    if not var_sub > 0:
        return None
    seg_means = means.mean(axis=1)
    chi2 = float(np.sum((seg_means - seg_means.mean()) ** 2) / (var_sub / b))
    dof = n_seg - 1
    # the denominator is itself estimated: chi2 / dof is ~F(dof, d2) with d2 the
    # denominator's degrees of freedom, n_seg (b - 1), times ~0.64 for a median's efficiency
    p = f_sf(chi2 / dof, dof, 0.64 * n_seg * k)
    spread = float(seg_means.max() - seg_means.min())
    jumps = np.abs(np.diff(seg_means))
    j = int(np.argmax(jumps))
    std = float(np.std(y))
    return {"chi2": chi2, "dof": dof, "p": p, "spread": spread, "std": std,
            "jump": float(jumps[j]), "at": (j + 1) * m, "step": bool(jumps[j] > 0.6 * spread),
            "significant": bool(p < _SHIFT_ALPHA and spread > _SHIFT_MIN_SPREAD * std)}


def mean_shift_sentence(recs, unit: str = "m", tests=None) -> str:
    """A sentence naming a step or drift of the mean position ('' when there is none);
    ``tests``: the recordings' :func:`mean_shift` results if the caller has them."""
    tests = tests if tests is not None else [mean_shift(r.positions) for r in recs]
    for i, t in enumerate(tests):
        if t is None or not t["significant"]:
            continue
        kind = (f"a step: the mean jumps by {t['jump']:.3g} {unit} near frame {t['at']}"
                if t["step"] else "a drift")
        return (f"the mean position of recording {i} is not stationary ({kind}): the means of "
                f"{t['dof'] + 1} segments spread over {t['spread']:.3g} {unit} "
                f"({t['spread'] / t['std']:.2g} x the frames' std), far beyond their expected "
                f"scatter (chi^2 = {t['chi2']:.4g}, {t['dof']} dof, p = {t['p']:.2g}); the "
                "trap models assume a stationary bead, and a step or drift can bias k and "
                "gamma: cut the record at the step, remove the drift, or add the drift "
                "effect (model='standard+drift')")
    return ""


#: saturation: a pile-up of at least this many frames at exactly the minimum or maximum value
#: that holds more than twice as many frames as the next value inwards (an unclipped tail
#: thins out towards the extreme: a continuous trace has each value once, a quantised one
#: fewer frames on its outermost level than on the next)
_SAT_MIN_FRAMES = 3
#: refuse above this fraction of saturated frames, or when the clipped tails lower the
#: variance by more than _SAT_MAX_BIAS_SE standard errors of the frame variance
_SAT_MAX_FRACTION = 0.005
_SAT_MAX_BIAS_SE = 0.5
#: quantisation: note a step above std/4 (it adds step^2/12 > 0.5 % of the variance); refuse a
#: step above the std. Below one std the rounding error is white noise of variance step^2/12,
#: uncorrelated with the motion to exp(-2 pi^2 std^2/step^2) (Sheppard; < 3e-9 at step = std),
#: which eps^2 absorbs: measured with the exact likelihood on 8192-frame AR(1) traces rounded
#: to steps of 0.25, 0.5 and 1 std, k and gamma moved by < 0.4 SE. At 1.5 and 2 std they were
#: 1.5 and 3-8 SE off (tau = 8 dt: the rounding error of neighbouring frames correlates).
_QUANT_NOTE_STEP = 0.25
_QUANT_MAX_STEP = 1.0


def _clipped_variance_deficit(p: float) -> float:
    """Relative variance lost when a Gaussian's tail beyond its upper p-quantile is moved onto
    the quantile: ``E[(Z - z)^2; Z > z] = (1 + z^2) Q(z) - z phi(z)``."""
    from statistics import NormalDist

    p = min(max(p, 1e-300), 0.5)
    z = NormalDist().inv_cdf(1.0 - p)
    phi = math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
    return max((1.0 + z * z) * p - z * phi, 0.0)


def _quantisation_step(values: np.ndarray, n: int) -> float:
    """The grid step of a trace whose values lie on a regular grid (else 0)."""
    if values.size < 2 or values.size > n // 2:
        return 0.0
    d = np.diff(values)
    q = float(d.min())
    if not q > 0:
        return 0.0
    m = d / q
    return q if bool(np.all(np.abs(m - np.round(m)) < 1e-3)) else 0.0


def _inspect_frames(recs, strict: bool, drift_modelled: bool = False) -> list:
    """Saturation (frames piled up at exactly the extreme values) and coarse quantisation.

    Clipping removes the tails of the position distribution and flattens the trace while the
    detector is saturated: k comes out high and the spectrum distorted, with no sign in the
    goodness of fit. Refused (``ValueError``) above ``_SAT_MAX_FRACTION`` of the frames or
    when the variance deficit it implies is not small compared with the variance's standard
    error; smaller pile-ups get a note. Quantisation adds white noise of variance step^2/12,
    which the tracking-noise term absorbs: a note above a step of std/4, refused above one
    std, where the rounding error is neither white nor independent of the motion. With
    ``strict=False`` the refusals become notes and the fit goes on. A mean position that
    moves (a step or drift, :func:`mean_shift`) gets a note unless the model has drift.
    Two recordings with identical positions (one file listed twice) are refused too.
    """
    notes, errors = [], []
    seen: dict = {}
    for i, r in enumerate(recs):
        y = np.asarray(r.positions, dtype=float)
        key = (y.size, hash(y.tobytes()))
        if key in seen and np.array_equal(np.asarray(recs[seen[key]].positions), y):
            errors.append(f"recordings {seen[key]} and {i} hold identical positions (the same "
                          "file listed twice, e.g. at two laser powers?): a joint fit would "
                          "count the same frames twice and halve their variance's error. "
                          "Remove the duplicate")
        seen.setdefault(key, i)
        u, counts = np.unique(y, return_counts=True)
        if u.size < 2:
            continue
        where = f"recording {i}" + (f" ({r.name})" if getattr(r, "name", None) else "")
        for msg, refused in histogram_checks(y, u, counts, where):
            (errors if refused else notes).append(msg)
        glitch = glitch_note(y, where)
        if glitch:
            notes.append(glitch)
    from ._variance_shift import variance_shift_sentence  # it imports this module

    tests = [mean_shift(r.positions) for r in recs]
    unit = str(getattr(recs[0], "position_unit", "m"))
    for found in ("" if drift_modelled else mean_shift_sentence(recs, unit, tests),
                  variance_shift_sentence(recs, tests)):
        if found:
            notes.append(found[0].upper() + found[1:])
    if errors:
        if strict:
            # (the duplicate's own message says what to do)
            detector = any("identical positions" not in e for e in errors)
            raise ValueError("; ".join(errors) + (
                ". Crop the saturated stretches or fix the detector range/resolution"
                if detector else "") + "; strict=False fits anyway (with a note; the result "
                "is then biased).")
        notes = [f"NOT TRUSTWORTHY (strict=False): {e}" for e in errors] + notes
    return notes


#: on quantised positions a few frames on the outermost level are chance (integer nm: 3 there
#: and 1 on the next level): a pile-up must then be significant, the outermost level holding
#: more frames than the next with binomial probability below this (an unclipped Gaussian
#: tail puts fewer frames on the outer level than on the next, so 1/2 is conservative)
_SAT_QUANTISED_P = 1e-3


def _binomial_half_tail(c: int, n: int) -> float:
    """P(X >= c) for X ~ Binomial(n, 1/2)."""
    return math.fsum(math.comb(n, j) for j in range(c, n + 1)) / 2.0**n if n <= 1000 else \
        float(0.5 * math.erfc((c - 0.5 - 0.5 * n) / math.sqrt(0.5 * n)))


def histogram_checks(y, u, counts, where) -> list[tuple[str, bool]]:
    """``(message, refused)`` of the saturation and the quantisation check of the frames
    ``y`` (``u, counts``: their distinct values), those that found something."""
    step = _quantisation_step(u, y.size)
    found = [_saturation(y, u, counts, where, step), _quantisation(y, u, where, step)]
    return [(msg, refused) for msg, refused in found if msg]


def _saturation(y, u, counts, where, step):
    """``(message, refused)`` on frames piled up at exactly the minimum or maximum value
    (``('', False)`` without a pile-up); ``u, counts`` are the distinct values of ``y``,
    ``step`` their grid step (0: not on a grid)."""
    n = y.size
    piles = []
    quantised = step > 0
    for side, j, jn in (("minimum", 0, 1), ("maximum", -1, -2)):
        c, cn = int(counts[j]), int(counts[jn])
        if c >= _SAT_MIN_FRAMES and c >= 2 * cn + 1 and (
                not quantised or _binomial_half_tail(c, c + cn) < _SAT_QUANTISED_P):
            piles.append((side, c, float(u[j])))
    if not piles:
        return "", False
    frac = sum(c for _, c, _ in piles) / n
    deficit = sum(_clipped_variance_deficit(c / n) for _, c, _ in piles)
    v, se = empirical_variance_se(y)
    rel_se = se / v if v > 0 else math.inf
    what = " and ".join(f"{c} frames ({100.0 * c / n:.2g} %) at exactly the {side} "
                        f"{val:.6g} m" for side, c, val in piles)
    msg = (f"{where} ({n} frames): {what}: the detector saturated (clipped). "
           "Clipping cuts the tails of the position distribution and flattens the "
           "trace while saturated, so k comes out too high (a Gaussian clipped there "
           f"loses ~{100.0 * deficit:.2g} % of its variance; the variance's standard "
           f"error is {100.0 * rel_se:.2g} %) and the spectrum is distorted")
    if frac > _SAT_MAX_FRACTION or deficit > _SAT_MAX_BIAS_SE * rel_se:
        return msg, True
    return msg + " - here too few frames to matter (fit kept)", False


def _quantisation(y, u, where, q):
    """``(message, refused)`` on positions quantised in steps above std/4 (``('', False)``
    otherwise); ``u`` are the distinct values of ``y``, ``q`` their grid step (0: none)."""
    sd = float(np.std(y))
    if not (q > 0 and sd > 0 and q > _QUANT_NOTE_STEP * sd):
        return "", False
    added = q * q / 12.0
    msg = (f"{where}: positions are quantised in steps of {q:.4g} m ({q / sd:.2g} x "
           f"their standard deviation {sd:.4g} m; {u.size} distinct values). Rounding "
           f"adds white noise of variance step^2/12 = {added:.3g} m^2 "
           f"({100.0 * added / sd**2:.2g} % of the frame variance)")
    if q > _QUANT_MAX_STEP * sd:
        return msg + (f"; with a step above {_QUANT_MAX_STEP:g} standard "
                      "deviation the rounding error is neither white nor independent "
                      "of the motion, and k and gamma are biased (by several SE at "
                      "1.5-2 std). Record with a finer position resolution"), True
    return msg + (", which the tracking-noise term eps^2 absorbs (its "
                  "fitted value includes it); models without tracking noise "
                  "(naive, blur) would put k that much too low"), False
