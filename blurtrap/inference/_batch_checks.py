"""Per-item checks of :func:`calibrate_batch`: the validation, refusals and goodness of fit
of :func:`calibrate`, applied to every row of a batch without aborting the others.

Host side (numpy): data checks and the lag-1 temporal information of each row, taken in the
same pass over the frames as the periodograms. Device side (in the vmapped fit): the binned
spectral goodness-of-fit statistic of :func:`blurtrap.inference._spectral.spectral_gof`.
"""

from __future__ import annotations

import inspect
import math

import jax.numpy as jnp
import numpy as np

from ..data.internal import MIN_PLAUSIBLE_POSITION_STD_M
from ._fit import chi2_sf
from ._frames import histogram_checks, temporal_information

# The unit-slip thresholds of ``Recording`` (blurtrap/data/_recording.py; a test holds them
# equal): a batch row is checked like a Recording built from it.
MAX_POSITION_STD_M = 1e-5
MAX_INTERVAL_S = 0.1
MIN_TEMPERATURE_K = 100.0
#: lag-1 correlation (in standard errors) below which the frames carry no temporal
#: information, the threshold of ``calibrate`` (``temporal_information``)
Z_MIN = float(inspect.signature(temporal_information).parameters["z_min"].default)
#: ordinates pooled per bin of the goodness-of-fit test (``spectral_gof``'s ``min_dof``)
GOF_MIN_DOF = 64


def check_shared(dt: float, w: float, t: float, check_units: bool) -> None:
    """The checks ``Recording`` makes on frame interval, exposure and temperature (shared by
    every row, so a failure concerns the whole batch and raises ``ValueError``)."""
    if not (dt > 0 and 0 < w <= dt * (1 + 1e-12) and t > 0):
        raise ValueError(
            f"need frame_interval > 0, 0 < exposure <= frame_interval, temperature > 0; got "
            f"frame_interval = {dt} s, exposure = {w} s, temperature = {t} K"
        )
    if not check_units:
        return
    for name, v in (("frame_interval", dt), ("exposure", w)):
        if v >= MAX_INTERVAL_S:
            raise ValueError(f"{name} = {v!r} s is at least 0.1 s: this looks like ms, not s "
                             f"(did you mean {v * 1e-3!r} s?). Pass seconds, or "
                             "check_units=False")
    if t < MIN_TEMPERATURE_K:
        raise ValueError(f"temperature = {t!r} K is below 100 K: this looks like Celsius; pass "
                         f"kelvin (e.g. {t + 273.15:.2f} K), or check_units=False")


def row_stats(rows: np.ndarray) -> np.ndarray:
    """Per row of ``rows`` (R, N): ``[n_nonfinite, first_nonfinite, first is NaN (else
    inf), constant, std, z]`` (R, 6), with ``std`` the population standard deviation (as ``np.std``) and ``z`` the lag-1
    temporal information of :func:`temporal_information` (``r1 sqrt(N)``, 0 when the variance
    is 0). Rows with NaN/inf get NaN std and z."""
    out = np.empty((rows.shape[0], 6))
    n = rows.shape[1]
    with np.errstate(all="ignore"):
        bad = ~np.isfinite(rows)
        nbad = bad.sum(axis=1)
        out[:, 0] = nbad
        first = bad.argmax(axis=1)
        out[:, 1] = np.where(nbad > 0, first, -1)
        out[:, 2] = np.isnan(rows[np.arange(rows.shape[0]), first])
        out[:, 3] = np.max(rows, axis=1) == np.min(rows, axis=1)
        y = rows - rows.mean(axis=1, keepdims=True)
        c0 = np.mean(y * y, axis=1)
        c1 = np.mean(y[:, 1:] * y[:, :-1], axis=1)
        out[:, 4] = np.sqrt(c0)
        out[:, 5] = np.where(c0 > 0, c1 / np.where(c0 > 0, c0, 1.0) * math.sqrt(n), 0.0)
    out[nbad > 0, 4:] = np.nan
    return out


def frame_status(rows: np.ndarray, first: int = 0) -> np.ndarray:
    """Per row of ``rows`` (R, N): ``""``, or the refusal ``calibrate`` gives its frames
    (saturated/clipped, or quantised in steps above their standard deviation; see
    :func:`blurtrap.inference._frames._inspect_frames`). A vectorised screen (a pile-up of
    >= 3 frames at the extreme values, or at most N/2 distinct values) picks the few rows
    that get the full checks; ``first`` numbers the rows in the messages."""
    out = np.full(rows.shape[0], "", dtype=object)
    n = rows.shape[1]
    with np.errstate(all="ignore"):
        srt = np.sort(rows, axis=1)
        at_min = np.sum(srt == srt[:, :1], axis=1)
        at_max = np.sum(srt == srt[:, -1:], axis=1)
        distinct = 1 + np.sum(np.diff(srt, axis=1) > 0, axis=1)
        finite = np.all(np.isfinite(srt[:, [0, -1]]), axis=1)
    cand = finite & ((at_min >= 3) | (at_max >= 3) | (distinct <= n // 2))
    for i in np.flatnonzero(cand):
        y = rows[i]
        u, counts = np.unique(y, return_counts=True)
        if u.size < 2:
            continue
        for msg, refused in histogram_checks(y, u, counts, f"item {first + i}"):
            if refused:
                out[i] = "refused: " + msg
                break
    return out


def prefit_status(stats: np.ndarray, check_units: bool) -> np.ndarray:
    """Status of each row before any fit: ``""`` (to be fitted) or why it is not fitted, in
    the order ``calibrate`` would find it: the Recording checks (non-finite values, constant
    trace, unit slip), then the refusal of frames without temporal information."""
    status = np.full(stats.shape[0], "", dtype=object)
    nbad, first, isnan, const, std, z = stats.T
    flagged = (nbad > 0) | (const > 0) | ~(z > Z_MIN)
    if check_units:
        flagged |= (std > MAX_POSITION_STD_M) | (std < MIN_PLAUSIBLE_POSITION_STD_M)
    for i in np.flatnonzero(flagged):  # strings only for the (few) rows not fitted
        if nbad[i] > 0:
            more = f" ({int(nbad[i])} non-finite values)" if nbad[i] > 1 else ""
            status[i] = f"invalid: {'NaN' if isnan[i] else 'inf'} at frame {int(first[i])}{more}"
        elif const[i]:
            status[i] = "constant trace"
        elif check_units and std[i] > MAX_POSITION_STD_M:
            status[i] = (f"invalid: positions look like nm or pixels, not m (std {std[i]:.3g} m "
                         "> 10 um)")
        elif check_units and std[i] < MIN_PLAUSIBLE_POSITION_STD_M:
            status[i] = (f"invalid: positions far too small for metres (std {std[i]:.3g} m < "
                         f"{MIN_PLAUSIBLE_POSITION_STD_M:g} m, less than any trapped bead moves): "
                         "check the position unit")
        else:
            status[i] = (f"refused: no temporal information (lag-1 correlation {z[i]:.1f} SE "
                         "above 0: dt >> tau, or tracking noise swamps the motion); gamma not "
                         "identifiable from one exposure")
    return status


def implausible_status(k: float, gamma: float) -> str:
    """calibrate's plausibility note per item: a k or gamma outside any trapped bead's range
    (``Param.bounds``) is almost always a position unit slip (an independent pass: positions
    in mm gave status "ok" with k 1e-6 x the truth). ``""`` when both are in range."""
    from ..effects import implausible

    bad = [f"{n} = {v:.3g} {q.unit}, expected {q.range_text(lab=False)}"
           for n, v in (("k", k), ("gamma", gamma)) if (q := implausible(n, v)) is not None]
    return ("implausible: " + "; ".join(bad) + " (a trapped bead lies within these ranges): "
            "check the position unit") if bad else ""


def no_information_status(z: float) -> str:
    """Status of a fit that ran tau past a third of the record on frames far less correlated
    than a freely diffusing bead's (``calibrate``'s ``_check_relaxation_resolved``)."""
    return (f"refused: dt >> tau, gamma not identifiable (the fit ran tau past a third of the "
            f"record, but the lag-1 correlation is only {z:.1f} SE above 0)")


def gof_bins(weight: np.ndarray) -> tuple[int, int]:
    """(ordinates per bin, number of bins) of ``spectral_gof`` for one record's weights."""
    per = max(1, int(math.ceil(GOF_MIN_DOF / float(np.median(weight)))))
    return per, len(weight) // per


def gof_stats(ratio, weight, per: int, nbin: int):
    """jnp: the binned statistic ``T = sum_b W_b (mean_b - 1)^2`` of ``spectral_gof`` for one
    record's periodogram/model ``ratio`` (M,), with what the status quotes about the misfit:
    ``(T, largest ratio, its ordinate, bin of the largest term, that bin's mean ratio)``."""
    if nbin == 0:
        nan = jnp.full((), jnp.nan, ratio.dtype)
        return nan, nan, jnp.asarray(0), jnp.asarray(0), nan
    qb = ratio[: nbin * per].reshape(nbin, per)
    wb = weight[: nbin * per].reshape(nbin, per)
    wsum = jnp.sum(wb, axis=1)
    means = jnp.sum(qb * wb, axis=1) / wsum
    terms = wsum * (means - 1.0) ** 2
    j = jnp.argmax(ratio)
    b = jnp.argmax(terms)
    return jnp.sum(terms), ratio[j], j, b, means[b]


def gof_p_values(stat: np.ndarray, dof: int) -> np.ndarray:
    return np.array([chi2_sf(s, dof) if np.isfinite(s) else np.nan for s in stat])


def inadequate_status(p, peak, j, b, bmean, f, per, n_blocks):
    """``inadequate: goodness of fit p = ...`` with what stands out: a single ordinate far
    above the model (a spectral line: its Bonferroni p < 1e-3 among the M ordinates, each
    Gamma(n_b, 1/n_b) distributed), else the frequency band with the largest misfit."""
    m = len(f)
    line_p = m * chi2_sf(2.0 * n_blocks * peak, 2 * n_blocks)
    if line_p < 1e-3:
        hint = f"line at {f[int(j)]:.4g} Hz? ordinate {peak:.3g}x the model"
    else:
        lo, hi = f[int(b) * per], f[min((int(b) + 1) * per, m) - 1]
        what = "excess" if bmean > 1 else "deficit"
        hint = f"{what} of {abs(bmean - 1) * 100:.2g} % at {lo:.4g}-{hi:.4g} Hz"
    pv = f"p = {p:.2g}" if p > 0 else "p < 1e-300"
    return f"inadequate: goodness of fit {pv} ({hint})"
