"""Checks of an x/y calibration against its model (:mod:`blurtrap.inference._xy`): the
eigenvalue gap of the frame covariance and the error of phi, the lag-1 coupling of the
motions along the principal axes, and the wording of a disagreement between them on gamma or
eps^2 (the joint fit's pooling note).

Every statistic compares like with like: the model autocovariances are in metres (the joint
fit reports k, gamma and eps^2 in SI), so the data enter in metres too. Positions in metres
(the loaders turn nm, um and px with ``pixel_size_m`` into metres) are taken as they are;
positions in volts are turned into metres with the joint fit's displacement sensitivity Rd
[m/V] (:func:`metres_per_unit`). An :class:`~blurtrap.data.XYRecording` has one position
unit on both axes and the joint fit one Rd for both principal axes: equal gains on x and y
are part of the model, and unequal gains are what the coupling note (principal axes away
from the detector's) and the pooling note (principal axes along them: each axis's apparent
gamma and eps^2 change by the gain) detect. An independent pass found volts compared with
metres: the coupling note fired at z ~ 1e13 on correct data and an isotropic trap came back
'resolved' (gap ~ 1e13 SE, i.e. 1/Rd^2 too large).
"""

from __future__ import annotations

import math

import numpy as np

from ..data import XYRecording
from ..physics import frame_autocovariance


def metres_per_unit(joint, xy: XYRecording) -> float:
    """Metres per unit of `xy`'s positions: 1 for metres, the joint fit's displacement
    sensitivity Rd [m/V] (shared by both axes) for volts; NaN when a fit in volts has no Rd
    (every statistic from the positions is then NaN: nothing is claimed)."""
    if xy.position_unit != "V":
        return 1.0
    names = list(joint.param_names)
    if "displacement_sensitivity" not in names:
        return math.nan
    return float(joint.values[names.index("displacement_sensitivity")])


def _autocov(k, gamma, eps2, xy: XYRecording):
    """``(C(0), C(1), rho)`` [m^2] of the frames along an axis with stiffness `k`."""
    args = (k, gamma, xy.exposure, xy.frame_interval, xy.temperature, max(eps2, 0.0))
    c0 = float(frame_autocovariance(0, *args))
    c1 = float(frame_autocovariance(1, *args))
    return c0, c1, math.exp(-xy.frame_interval * k / gamma)


def _cross_sums(k1, k2, gamma, eps2, xy: XYRecording) -> tuple[float, float]:
    """``(S0, S1) = (sum_n C1(n) C2(n), sum_n C1(n) C2(n+1))`` [m^4] of the two axes' frame
    autocovariances (``C(n) = c1 r^(|n|-1)`` for ``n != 0``): N times the variance of a
    sample cross-covariance and the covariance of neighbouring lags' (Bartlett)."""
    a0, a1, ra = _autocov(k1, gamma, eps2, xy)
    b0, b1, rb = _autocov(k2, gamma, eps2, xy)
    return (a0 * b0 + 2.0 * a1 * b1 / (1.0 - ra * rb),
            a0 * b1 + a1 * b0 + a1 * b1 * (ra + rb) / (1.0 - ra * rb))


def _angle_stats(k1, k2, gamma, eps2, xy: XYRecording, l1, l2):
    """``(phi_err, anisotropy_z)`` from the exact frame autocovariances (module docstring of
    :mod:`._xy`); `l1`, `l2`: the eigenvalues of the frame covariance in **m^2** (positions
    in volts: times Rd^2, :func:`metres_per_unit`)."""
    n = xy.n_frames
    a0, a1, ra = _autocov(k1, gamma, eps2, xy)
    b0, b1, rb = _autocov(k2, gamma, eps2, xy)
    cross = _cross_sums(k1, k2, gamma, eps2, xy)[0]
    sq = a0**2 + 2.0 * a1**2 / (1.0 - ra**2) + b0**2 + 2.0 * b1**2 / (1.0 - rb**2)
    gap_model = abs(a0 - b0)
    phi_err = math.sqrt(cross / n) / gap_model if gap_model > 0 else math.inf
    z = (l1 - l2) / math.sqrt(2.0 * sq / n)
    return phi_err, z


#: the principal-axis motions count as coupled when a lag-1 cross-covariance exceeds this
#: many standard errors (two lags tested: a false note in ~1e-5 of fits)
COUPLING_Z = 4.5


def _coupling_note(pu, pv, k1, k2, gamma, eps2, xy: XYRecording) -> str | None:
    """A note when the traces along the principal axes, `pu` and `pv` (arrays in **m**:
    positions in volts times Rd), are correlated at lag +-1: in the model the two axes are
    independent OU sequences (one isotropic friction), so their sample cross-covariances
    ``c(h)`` have mean 0 and covariances (Bartlett) ``cov(c(h), c(h')) = (1/N) sum_n C1(n)
    C2(n + h' - h)``: ``S0 = sum C1(n) C2(n)`` (as ``c12`` at lag 0, :func:`_angle_stats`)
    and ``S1 = sum C1(n) C2(n+1) = a0 b1 + a1 b0 + a1 b1 (ra + rb) / (1 - ra rb)`` (``C(n) =
    c1 r^(|n|-1)`` for ``n != 0``). The principal axes make ``c(0) = 0``, so ``c(+-1)`` is
    referred to its variance given that, ``(S0 - S1^2/S0)/N``. Unequal detector
    sensitivities along x and y, cross-talk between the channels or an anisotropic friction
    couple them."""
    s0, s1 = _cross_sums(k1, k2, gamma, eps2, xy)
    se = math.sqrt(max(s0 - s1 * s1 / s0, 0.0) / xy.n_frames) if s0 > 0 else 0.0
    if not se > 0:
        return None
    x = np.asarray(pu, float) - float(np.mean(pu))
    y = np.asarray(pv, float) - float(np.mean(pv))
    z = [float(np.mean(x[1:] * y[:-1])) / se, float(np.mean(y[1:] * x[:-1])) / se]
    zs = _mixing_z(x, y)
    if not (max(abs(t) for t in z) > COUPLING_Z or abs(zs) > MIXING_Z):
        return None
    return (f"the motions along the two principal axes are coupled (lag-1 correlations "
            f"{z[0]:+.1f} and {z[1]:+.1f} standard errors; their cross-spectrum shows a "
            f"non-orthogonal mixing of the two axes at {zs:+.1f} standard errors), which a trap with one isotropic "
            "friction cannot produce: unequal x and y detector sensitivities (a per-axis gain; the positions "
            "must be in one length unit on both axes), unequal tracking noise on x and y "
            "(it tilts the principal axes of the frames away from the trap's), cross-talk "
            "between the channels, an anisotropic friction (a non-spherical particle) or a "
            "drift common to both axes couple them, and k1, k2, gamma and phi are then "
            "biased. Calibrate each axis's sensitivity separately, remove the drift, or fit x "
            "and y alone (calibrate on each axis: its own eps^2)")


#: the principal-axis motions count as mixed when the cross-spectral score exceeds this
#: many standard errors (one statistic, N(0, 1) for orthogonal axes: a false note in < 3e-3
#: of fits; measured SD 0.88 and 0.51 over 40 fits each, none above 3)
MIXING_Z = 3.0


#: ordinates per band of the smoothed periodograms of :func:`_mixing_z`
_MIX_BAND = 32


def _smoothed(p: np.ndarray) -> np.ndarray:
    """The periodogram ``p`` averaged over bands of :data:`_MIX_BAND` ordinates, per ordinate."""
    m = len(p) // _MIX_BAND * _MIX_BAND
    out = np.empty_like(p)
    out[:m] = np.repeat(p[:m].reshape(-1, _MIX_BAND).mean(axis=1), _MIX_BAND)
    out[m:] = p[m:].mean() if m < len(p) else 0.0
    return out


def _mixing_z(x, y) -> float:
    """Score statistic for mixed principal axes (cross-talk, non-orthogonal detector axes).

    Traces ``x = a u + b v``, ``y = c u + d v`` of independent axis motions u, v (spectra
    S_u, S_v) have the cross-spectrum ``E Re I12 = alpha S_u + beta S_v`` with ``alpha =
    a c``, ``beta = b d``. A rotation (the principal-axis angle, or its estimation error,
    large where the two variances are close) gives ``alpha + beta = 0``; a non-orthogonal
    mixing does not (with the principal axes' zero lag-0 cross-covariance, ``alpha + beta =
    a c (1 - V_u/V_v)``). ``Re I12(w_j)`` has variance ``S_u S_v / 2``: alpha and beta by
    weighted least squares over every frequency against the traces' own smoothed
    periodograms, and ``(alpha + beta) / SE`` is N(0, 1) for orthogonal axes at any angle
    error. An independent pass found 8 % cross-talk biasing k1 by 3.5-7.6 SE with the lag-1
    test silent; a fixed-angle version of this test mistook a poorly determined angle (unequal
    gains making the two variances close) for mixing."""
    n = len(x)
    j = np.arange(1, (n - 1) // 2 + 1)
    fx, fy = np.fft.rfft(x)[j], np.fft.rfft(y)[j]
    re = (fx * np.conj(fy)).real / n
    s1 = _smoothed((fx.real**2 + fx.imag**2) / n)
    s2 = _smoothed((fy.real**2 + fy.imag**2) / n)
    wt = 2.0 / (s1 * s2)
    design = np.stack([s1, s2], axis=1)
    info = design.T @ (design * wt[:, None])
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return 0.0
    theta = cov @ (design.T @ (wt * re))
    var = float(cov[0, 0] + cov[1, 1] + 2.0 * cov[0, 1])
    return float(theta[0] + theta[1]) / math.sqrt(var) if var > 0 else 0.0


_DISAGREE = "the recordings fitted together disagree"


def _gain_ratio(separate, volts: bool) -> float:
    """Axis 2's detector gain over axis 1's that would explain the two axes' own fits:
    ``sqrt(gamma1 / gamma2)`` in metres (a gain g makes the apparent gamma gamma/g^2), ``Rd1
    / Rd2`` in volts (each axis's own Rd from the known friction; the gain is 1/Rd); NaN
    without both single-axis fits."""
    if separate is None or any(r is None for r in separate):
        return math.nan
    try:
        if volts:
            rd = [float(r.params["displacement_sensitivity"]) for r in separate]
            return rd[0] / rd[1]
        return math.sqrt(float(separate[0].gamma) / float(separate[1].gamma))
    except (KeyError, ValueError, ZeroDivisionError):
        return math.nan


def xy_pooling_notes(notes, phi: float, separate, volts: bool) -> tuple[str, ...]:
    """The joint fit's `notes` with a disagreement on gamma or eps^2 between the two
    principal-axis traces worded for an x/y recording: both traces are one bead in the same
    frames, so another bead, height, temperature, exposure or illumination cannot explain it;
    unequal detector gains on x and y can (with the principal axes along the detector's, a
    gain changes each axis's apparent gamma and eps^2 instead of coupling the axes). The note
    fires on the joint fit's own test (:mod:`._pooling`): this changes its words, never when
    it fires."""
    from ._pooling import _WHY

    ratio = _gain_ratio(separate, volts) if abs(math.sin(2.0 * phi)) < 0.5 else math.nan
    est = (f"; the two axes alone need axis 2's gain {ratio:.3g} times axis 1's"
           if math.isfinite(ratio) else "")
    why = {
        "gamma": (
            "both traces are one bead recorded at one time, so the friction cannot differ "
            "between them (no other bead, height, temperature or viscosity): the likelier cause "
            "is unequal detector sensitivities along x and y (a per-axis gain g scales that "
            "axis's apparent k and gamma by 1/g^2: with the principal axes along the detector's "
            "it shows as this disagreement, away from them also as a lag-1 coupling; axis 1 is "
            f"at phi = {math.degrees(phi):.3g} deg from x{est}), else an anisotropic friction "
            "(a non-spherical particle) or unequal tracking noise on x and y. Calibrate each "
            "axis's sensitivity separately (positions in one length unit on both axes)"),
        "tracking_var": (
            "both traces come from the same frames (one exposure, one illumination): the "
            "tracking error differs between x and y (a camera's localisation error can differ "
            "between its axes), or the detector's sensitivities along x and y differ (a "
            "per-axis gain g scales that axis's eps^2 by g^2, and its gamma by 1/g^2). Fit x "
            "and y alone, or calibrate each axis's sensitivity separately"),
    }
    out = []
    for n in notes:
        if n.startswith(_DISAGREE):
            for name, text in why.items():
                if f"on {name} (" in n:
                    n = n.replace(_WHY[name], text) if _WHY[name] in n else f"{n}. In x/y: {text}"
        out.append(n)
    return tuple(out)
