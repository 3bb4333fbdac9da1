r"""Calibration of x/y recordings: principal axes of an anisotropic trap, k per axis and one
friction shared by both axes (the same bead).

Model: ``F = -K r`` with ``K = R(phi) diag(k1, k2) R(phi)^T`` and an isotropic friction
``gamma``; the motion along each principal axis is an independent OU process
(``tau_i = gamma/k_i``). Exposure averaging, sampling and isotropic tracking noise act
linearly and identically on both detector axes, so they commute with the rotation: the frames
along the principal axes are independent blurred OU sequences with variances
``v_i = (kT/k_i) S(alpha_i) + eps2``, and the frame covariance of (x, y) is
``R diag(v1, v2) R^T``. Blur changes the eigenvalues (each by its own ``S(alpha_i)``) but not
the eigenvectors, because each axis's blurred variance stays on its axis; and the order is
kept (the softer axis has both the larger ``kT/k`` and the larger ``S``). So ``phi`` is the
angle of the eigenvector of the largest eigenvalue of the sample covariance, and axis 1 is
the soft axis.

The traces projected on the estimated axes are then fitted jointly by :func:`calibrate` with
``k="per_recording"`` (k1, k2, one gamma and one eps2). Uncertainty of phi (delta method):
in the principal frame the sample cross-covariance ``c12`` has mean 0 and variance
``(1/N) sum_n C1(n) C2(n)`` (exact frame autocovariances, DESIGN 2.5), and
``phi_hat - phi = c12 / (v1 - v2)`` to first order. The error of phi enters the projected
traces' variances only at second order (``O(1/N)`` bias against ``O(1/sqrt N)`` errors), and
``c12`` is uncorrelated with the variances, so phi is treated as independent of (k1, k2,
gamma); benchmarks/study_xy.py checks the coverage that results. The model is in metres, so
positions in volts enter every statistic times the joint fit's displacement sensitivity Rd
(one for both axes: :mod:`._xy_checks`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, cast

import numpy as np

from ..data import XYRecording
from ..physics import psd_measured
from ._calibrate import calibrate
from ._result import LAB, CalibrationResult, FitError
from ._xy_checks import COUPLING_Z as COUPLING_Z
from ._xy_checks import _angle_stats as _angle_stats
from ._xy_checks import _coupling_note, metres_per_unit, xy_pooling_notes

#: principal axes count as resolved when the eigenvalue gap exceeds this many of its
#: standard errors (under isotropy the gap is Rayleigh: false "resolved" rate exp(-z^2/2))
RESOLVE_Z = 3.5


def _joint_fit(u, v, xy: XYRecording, phi: float, kwargs) -> CalibrationResult:
    """The joint fit of the traces along the principal axes (one gamma, one eps^2); its
    refusal in the x/y words (k1 and k2, not k[axis1], k[axis2]), with each axis fitted alone
    (its own eps^2) to name the likely cause: unequal tracking noise on the two axes, which
    the shared eps^2 cannot describe (an independent pass: 2 nm on x and 20 nm on y, a
    refusal listing outliers, a wrong exposure or a short record)."""
    try:
        return calibrate([u, v], k="per_recording", **kwargs)
    except FitError as err:
        msg = str(err).replace("k[axis1]", "k1").replace("k[axis2]", "k2")
        alone = _axes_alone(u, v, phi, kwargs)
        raise FitError(f"calibrate_xy: {msg}" if alone is None
                       else alone + "The joint fit said: " + msg) from err


def _axes_alone(u, v, phi: float, kwargs) -> str | None:
    """What each principal axis fitted alone says (the start of the joint fit's refusal);
    None when neither can be fitted alone (the joint fit's reason then stands)."""
    said, fitted = [], 0
    for i, rec in enumerate((u, v)):
        angle = math.degrees(phi) + 90.0 * i
        try:
            fit = calibrate(rec, **kwargs)
        except (FitError, ValueError) as err:
            said.append(f"axis {i + 1} ({angle:.1f} deg from x) alone is refused too: "
                        f"{str(err).split(';')[0]}")
            continue
        e2 = (f"eps^2 = {fit.tracking_var * 1e18:.3g} +- {fit.tracking_var_err * 1e18:.2g} nm^2"
              if "tracking_var" in fit.param_names else "no tracking noise in the model")
        said.append(f"axis {i + 1} ({angle:.1f} deg from x) alone: k = {fit.k * 1e3:.4g} pN/nm, "
                    f"{e2}")
        fitted += 1
    if not fitted:
        return None
    return ("calibrate_xy: the joint fit of the two principal axes (one gamma, one tracking "
            "noise eps^2 for both) failed. " + "; ".join(said) + ". A tracking noise much "
            "larger on one axis than the other (or swamping one axis's motion) breaks the "
            "shared eps^2: calibrate each axis alone (calibrate(xy.project(phi)[i]), its own "
            "eps^2) or reduce the noise. ")


@dataclasses.dataclass(frozen=True)
class XYCalibration:
    """Result of :func:`calibrate_xy` (SI units; ``summary()`` in lab units).

    - `k1`, `k2` [N/m]: principal stiffnesses; axis 1 (at angle `phi` [rad] from the
      detector's x axis, counter-clockwise, in (-pi/2, pi/2]) is the soft axis (larger
      frame variance).
    - `k_x`, `k_y`, `k_xy` [N/m]: the stiffness matrix ``K = R diag(k1, k2) R^T`` in the
      detector's axes: ``k_x = K_xx`` is the restoring force along x per unit displacement
      along x (y held fixed); ``k_xy = K_xy`` couples the axes and vanishes when phi = 0.
      Note ``kT / <x^2>`` (equipartition along x) is ``1 / (K^-1)_xx``, not ``K_xx``.
    - `gamma` [N s/m] and `tracking_var` [m^2]: shared by both axes (joint fit).
    - `frame_covariance` [m^2]: sample covariance of the (x, y) frames (positions in volts:
      times Rd^2, the joint fit's displacement sensitivity); `anisotropy_z` compares its
      eigenvalue gap with the model's standard error, in metres too.
    - `expected_gamma_se`: expected (Fisher) SE of gamma [N s/m] from (the joint fit, axis 1
      alone, axis 2 alone) at the fitted values; ``gamma_precision_gain`` is their ratio.
    - `joint`: the joint :class:`CalibrationResult` of the two projected traces;
      `separate`: the two single-axis fits (None for an axis whose fit fails, e.g. a stiff
      axis that alone cannot identify gamma), for the precision gain of sharing gamma.
    - `resolved`: False when the eigenvalue gap is within `RESOLVE_Z` standard errors of 0
      (trap isotropic within errors): phi is then undefined (noted), k1 and k2 still hold.
    """

    k1: float
    k1_err: float
    k2: float
    k2_err: float
    phi: float
    phi_err: float
    gamma: float
    gamma_err: float
    tracking_var: float
    k_x: float
    k_x_err: float
    k_y: float
    k_y_err: float
    k_xy: float
    k_xy_err: float
    frame_covariance: np.ndarray
    anisotropy_z: float
    resolved: bool
    temperature: float
    n_frames: int
    joint: CalibrationResult
    separate: tuple[CalibrationResult | None, CalibrationResult | None] | None
    expected_gamma_se: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    notes: tuple[str, ...] = ()

    @property
    def principal_axes(self) -> np.ndarray:
        """2x2 array whose columns are the unit vectors of axes 1 and 2 in (x, y)."""
        c, s = math.cos(self.phi), math.sin(self.phi)
        return np.array([[c, -s], [s, c]])

    @property
    def stiffness_matrix(self) -> np.ndarray:
        """``K`` [N/m] in the detector's axes."""
        return np.array([[self.k_x, self.k_xy], [self.k_xy, self.k_y]])

    @property
    def gamma_err_separate(self) -> tuple[float, float]:
        """SE of gamma [N s/m] from each axis alone (NaN without separate fits)."""
        if self.separate is None:
            return (math.nan, math.nan)
        return tuple(math.inf if r is None else float(r.gamma_err)  # type: ignore[return-value]
                     for r in self.separate)

    @property
    def gamma_precision_gain(self) -> float:
        """Expected SE of gamma from the better axis alone / expected SE of the shared gamma
        (> 1: gain), both from the Whittle Fisher information at the fitted values. Unlike
        the realised single-axis SEs (``gamma_err_separate``) it is not noisy and not
        understated when a single-axis fit puts eps^2 at its bound."""
        joint, a1, a2 = self.expected_gamma_se
        return min(a1, a2) / joint

    def _rows(self):
        kf, ku = LAB["k"]
        gf, gu = LAB["gamma"]
        deg = 180.0 / math.pi
        rows = [("k1 (soft axis)", self.k1 * kf, self.k1_err * kf, ku),
                ("k2", self.k2 * kf, self.k2_err * kf, ku),
                ("phi (axis 1 from x)", self.phi * deg, self.phi_err * deg, "deg"),
                ("gamma (shared)", self.gamma * gf, self.gamma_err * gf, gu),
                ("k_x = K_xx", self.k_x * kf, self.k_x_err * kf, ku),
                ("k_y = K_yy", self.k_y * kf, self.k_y_err * kf, ku),
                ("k_xy = K_xy", self.k_xy * kf, self.k_xy_err * kf, ku),
                ("eps (tracking rms)", math.sqrt(max(self.tracking_var, 0.0)) * 1e9, math.nan,
                 "nm")]
        if self.separate is not None:
            for i, r in enumerate(self.separate, start=1):
                if r is None:
                    continue
                rows.append((f"gamma (axis {i} alone)", r.gamma * gf, r.gamma_err * gf, gu))
                rows.append((f"k{i} (axis {i} alone)", r.k * kf, r.k_err * kf, ku))
        return rows

    def summary(self) -> str:
        """A readable table in lab units (pN/nm, pN s/um, degrees, nm)."""
        lines = [f"x/y calibration: {self.n_frames} frames per axis, {self.temperature:g} K"]
        for name, v, e, u in self._rows():
            err = "" if math.isnan(e) else f" +- {e:.3g}"
            lines.append(f"  {name:<24s} {v:.5g}{err} {u}")
        lines.append(f"  shared-gamma precision gain: {self.gamma_precision_gain:.3g} x "
                     "(expected SE of gamma, better axis alone / joint)")
        lines.append(f"  anisotropy: eigenvalue gap = {self.anisotropy_z:.3g} SE "
                     f"({'resolved' if self.resolved else 'NOT resolved: phi undefined'})")
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def _repr_html_(self) -> str:
        import html

        body = "".join(
            f"<tr><td>{html.escape(n)}</td><td>{v:.5g}</td>"
            f"<td>{'' if math.isnan(e) else f'{e:.3g}'}</td><td>{html.escape(u)}</td></tr>"
            for n, v, e, u in self._rows())
        notes = "".join(f"<li>{html.escape(n)}</li>" for n in self.notes)
        return ("<table><tr><th>parameter</th><th>value</th><th>error</th><th>unit</th></tr>"
                f"{body}</table>" + (f"<ul>{notes}</ul>" if notes else ""))

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict in SI units (angles in rad)."""
        out: dict[str, Any] = {
            name: float(getattr(self, name)) for name in (
                "k1", "k1_err", "k2", "k2_err", "phi", "phi_err", "gamma", "gamma_err",
                "tracking_var", "k_x", "k_x_err", "k_y", "k_y_err", "k_xy", "k_xy_err",
                "anisotropy_z", "temperature")}
        out.update(
            n_frames=int(self.n_frames), resolved=bool(self.resolved),
            principal_axes=self.principal_axes.tolist(),
            frame_covariance=np.asarray(self.frame_covariance).tolist(),
            gamma_err_separate=list(self.gamma_err_separate),
            expected_gamma_se=list(self.expected_gamma_se),
            gamma_precision_gain=float(self.gamma_precision_gain),
            notes=list(self.notes), joint=self.joint.to_dict())
        return out


def _principal(pos: np.ndarray):
    """``(phi, l1, l2, cov)``: angle of the largest-variance axis in (-pi/2, pi/2] and the
    eigenvalues (l1 >= l2) of the sample covariance of ``(n, 2)`` positions."""
    d = pos - pos.mean(axis=0)
    cov = d.T @ d / d.shape[0]
    a, b, c = cov[0, 0], cov[1, 1], cov[0, 1]
    phi = 0.5 * math.atan2(2.0 * c, a - b)
    if phi <= -math.pi / 2:
        phi += math.pi
    half = 0.5 * math.hypot(a - b, 2.0 * c)
    mid = 0.5 * (a + b)
    return phi, mid + half, mid - half, cov


def _whittle_information(k, gamma, eps2, xy: XYRecording, noise: bool) -> np.ndarray:
    """Expected (Whittle) Fisher information of one axis's frames for (k, gamma[, eps2]):
    ``sum_f d log P d log P^T`` over the positive Fourier frequencies of N frames; the
    derivatives in k and gamma by central differences in log, in eps2 exactly
    (``dP/deps2 = dt``)."""
    n, dt = xy.n_frames, xy.frame_interval
    f = np.arange(1, (n + 1) // 2) / (n * dt)

    def logp(kk, gg):
        return np.log(np.asarray(psd_measured(f, kk, gg, xy.exposure, xy.temperature, dt,
                                              max(eps2, 0.0))))

    h = 1e-5
    grads = [(logp(k * (1 + h), gamma) - logp(k * (1 - h), gamma)) / (2 * h * k),
             (logp(k, gamma * (1 + h)) - logp(k, gamma * (1 - h))) / (2 * h * gamma)]
    if noise:
        grads.append(dt / np.exp(logp(k, gamma)))
    g = np.stack(grads)
    return g @ g.T


def _expected_gamma_se(k1, k2, gamma, eps2, xy: XYRecording, noise: bool):
    """Expected SE of gamma from ``(joint, axis 1 alone, axis 2 alone)`` (Whittle Fisher)."""
    i1 = _whittle_information(k1, gamma, eps2, xy, noise)
    i2 = _whittle_information(k2, gamma, eps2, xy, noise)
    m = i1.shape[0]  # (k, gamma[, eps2]); joint: (k1, k2, gamma[, eps2])
    joint = np.zeros((m + 1, m + 1))
    for i, info in ((0, i1), (1, i2)):
        sel = [i] + list(range(2, m + 1))
        joint[np.ix_(sel, sel)] += info
    out = []
    for info, ig in ((joint, 2), (i1, 1), (i2, 1)):
        try:
            out.append(float(math.sqrt(np.linalg.inv(info)[ig, ig])))
        except (np.linalg.LinAlgError, ValueError):
            out.append(math.inf)
    return tuple(out)


def _tensor(k1, k2, phi, cov3):
    """K_xx, K_yy, K_xy and their SEs from (k1, k2, phi) with covariance `cov3`."""
    c, s = math.cos(phi), math.sin(phi)
    vals = (k1 * c * c + k2 * s * s, k1 * s * s + k2 * c * c, (k1 - k2) * s * c)
    jac = np.array([[c * c, s * s, -2.0 * (k1 - k2) * s * c],
                    [s * s, c * c, 2.0 * (k1 - k2) * s * c],
                    [s * c, -s * c, (k1 - k2) * math.cos(2.0 * phi)]])
    errs = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, cov3, jac), 0.0))
    return vals, tuple(float(e) for e in errs)


def _alone(rec, i: int, notes: list, kwargs):
    """The fit of one principal axis alone, or None (with a note) when it fails."""
    try:
        res = calibrate(rec, **kwargs)
    except FitError as e:
        notes.append(f"axis {i} alone does not give a calibration (its gamma error counts as "
                     f"infinite): {str(e).splitlines()[0]}")
        return None
    if res.at_bounds:
        notes.append(f"axis {i} alone: {', '.join(res.at_bounds)} at its bound, so that fit's "
                     "other errors are the unconstrained bound (wide); gamma_precision_gain "
                     "uses the expected errors instead")
    return res


def calibrate_xy(xy: XYRecording, *, separate: bool = True, **kwargs) -> XYCalibration:
    """Calibrate an x/y recording: principal axes, k1 and k2, one shared gamma.

    **Arguments:**

    - `xy`: an :class:`blurtrap.data.XYRecording` (see ``xy_from_arrays``, ``load_xy_csv``).
    - `separate`: also fit each principal axis alone (two more fits) to report the
      precision gained by sharing gamma (default True).
    - other keywords go to :func:`calibrate` (``method``, ``model``, ``likelihood``,
      ``fixed``, ...) for the joint fit with ``k="per_recording"`` and the single-axis fits.

    **Returns:** :class:`XYCalibration`.

    **Raises:** ``TypeError`` when `xy` is not an XYRecording; ``ValueError`` when ``k`` is
    passed (the layout is one k per principal axis); ``FitError`` from the fits.
    """
    if not isinstance(xy, XYRecording):
        raise TypeError(f"calibrate_xy: xy must be an XYRecording (blurtrap.data.xy_from_arrays"
                        f" or load_xy_csv); got {type(xy).__name__}")
    if "k" in kwargs:
        raise ValueError(f"calibrate_xy: k = {kwargs['k']!r} cannot be set: the x/y fit has one "
                         "stiffness per principal axis and one shared gamma")
    phi, l1, l2, cov = _principal(xy.positions)
    u, v = xy.project(phi)
    joint = _joint_fit(u, v, xy, phi, kwargs)
    names = list(joint.param_names)
    idx = [i for i, n in enumerate(names) if n.startswith("k[")]
    cov_k = np.asarray(joint.covariance)[np.ix_(idx, idx)]
    k1, k2 = (float(x) for x in joint.k_per_recording)
    gamma = float(joint.gamma)
    noise = "tracking_var" in names
    eps2 = float(joint.tracking_var) if noise else 0.0
    m = metres_per_unit(joint, xy)  # the data in metres, as the model (_xy_checks docstring)
    phi_err, z = _angle_stats(k1, k2, gamma, eps2, xy, l1 * m * m, l2 * m * m)
    cov3 = np.zeros((3, 3))
    cov3[:2, :2] = cov_k
    cov3[2, 2] = phi_err**2 if math.isfinite(phi_err) else 0.0
    (kxx, kyy, kxy), (exx, eyy, exy) = _tensor(k1, k2, phi, cov3)
    notes = []
    coupled = None
    if "gamma" in names:
        coupled = _coupling_note(m * np.asarray(u.positions, float), m * np.asarray(v.positions, float),
                                 k1, k2, gamma, eps2, xy)
    if coupled:
        notes.append(coupled)
    resolved = z > RESOLVE_Z
    if not resolved:
        notes.append(f"principal axes not resolved: the gap between the frame variances along "
                     f"the two axes is {z:.2g} standard errors (< {RESOLVE_Z:g}); the trap is "
                     "isotropic within errors, so phi is undefined (its value and error mean "
                     "nothing); k1 and k2 are the stiffnesses along two perpendicular axes")
    expected = (math.nan,) * 3
    if "gamma" in names:
        expected = _expected_gamma_se(k1, k2, gamma, eps2, xy, noise)
    seps = None
    if separate:
        seps = (_alone(u, 1, notes, kwargs), _alone(v, 2, notes, kwargs))
    return XYCalibration(
        k1=k1, k1_err=float(math.sqrt(cov_k[0, 0])), k2=k2,
        k2_err=float(math.sqrt(cov_k[1, 1])), phi=phi, phi_err=phi_err, gamma=gamma,
        gamma_err=float(joint.gamma_err), tracking_var=eps2, k_x=kxx, k_x_err=exx,
        k_y=kyy, k_y_err=eyy, k_xy=kxy, k_xy_err=exy, frame_covariance=cov * (m * m),
        anisotropy_z=float(z), resolved=bool(resolved), temperature=float(xy.temperature),
        n_frames=xy.n_frames, joint=joint, separate=seps,
        expected_gamma_se=cast(Any, expected),
        notes=tuple(notes) + xy_pooling_notes(joint.notes, phi, seps, xy.position_unit == "V"))
