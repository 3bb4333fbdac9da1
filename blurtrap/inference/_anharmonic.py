r"""Calibration of a quartic (anharmonic) trap from blurred frames: :func:`calibrate_anharmonic`.

The remedy for the ``anharmonicity`` effect (``U = k x^2/2 + k4 x^4/4``): a generalized method
of moments (GMM) fit of the harmonic coefficient ``k`` (the small-amplitude stiffness), ``k4``,
``gamma`` and the tracking-noise variance ``eps^2`` to moments of the frames whose model values
are computed *exactly* for any exposure ``0 <= W <= dt`` (camera or photodiode) from the
Fokker-Planck generator (``blurtrap.inference._anharmonic_moments``), so no simulation, no
simulation noise and no time-step bias enter the fit.

**Moments** (frames ``x_t`` minus their mean, ``t = 0 .. n-1``, ``n = N - max(lags)``):
``mean x_t^2``, ``mean x_t x_{t+l}`` at lags ``l`` (default: 1, 2, 3 and about 0.25, 0.5, 1, 2,
3 correlation times of a harmonic start fit, so the decay is sampled on the scale of tau),
``mean x_t^4`` and ``mean x_t^2 x_{t+l}^2`` at ``square_lags`` (default 1, 2: the squared frames
decay at their own rates, which carry k4; with tau ~ dt the 0.25-3 tau lags all round to 1-2
and, without lags 3 and the squared frames, the fit had 4 moments for 4 parameters: no J test).
Model: ``C(0) = sigma0^2 var + eps^2``, ``C(l) = sigma0^2 cov_l`` and
``E[(m + e)^4] = sigma0^4 m4 + 6 sigma0^2 var eps^2 + 3 eps^4`` (white Gaussian tracking
noise), with the dimensionless blurred moments of the generator at ``beta = k4 kT/k^2``,
``w = W/tau``, ``d = dt/tau``, ``sigma0^2 = kT/k``, ``tau = gamma/k``. Excess kurtosis carries
``k4``; the autocovariances carry ``gamma`` and, with the variance, ``k``.

**Estimator.** Two-step efficient GMM: the weight is the inverse of the long-run covariance
``Omega`` of the moment contributions, estimated from the data (Bartlett/Newey-West, bandwidth
``~15 tau/dt + max lag``); the fit is Gauss-Newton (Levenberg-damped) with forward-mode JAX
Jacobians of the exact model moments. Standard errors: ``(G' Omega^-1 G)^-1 / n``; Hansen's
J statistic ``n Q`` is the goodness of fit (chi^2 with ``p - 4`` dof; at 0 dof a note says the
fit has no such check). ``intervals``: Wald for k, gamma, eps^2; for k4 the profile of the GMM
distance (``_anharmonic_fit``), since its delta-method error shrinks with the estimate.

**Exact / approximate.** Exact: the model moments for any exposure (up to the generator grid,
relative error ~1e-4 for the variance and kurtosis, far below the statistical errors of a few
per cent). Asymptotic (as in every fit here): the normal sampling law of the moments and the
HAC estimate of ``Omega`` from the data. Measured (benchmarks/RESULTS_anharmonic.md; 50
independent camera records of 16 384 frames per beta, W = dt, tau = 4 frames): k and gamma
unbiased to < 1 % (harmonic fit: k +12 % at beta = 0.05, +22 % at 0.1), within 2 SE in
92-96 % of records and within 3 SE in all; SD/SE 0.9-1.1 at beta = 0.05 and 0.1, but 1.24
for k (1.33 for beta) on a harmonic trap (beta = 0: the data-based variance of x^4 is noisy
for Gaussian tails; a larger HAC bandwidth does not change it). Photodiode (W -> 0, 65 536
samples, beta = 0.1): k and gamma unbiased, within 2 SE in 92 % / 100 %, but the SEs of k
and k4 ~20 % small (SD/SE 1.19, 1.23). Cost: ~2 s per fit of 16 384
frames after a ~5 s compilation (one CPU core). Assumed: a symmetric quartic potential (no
cubic term), white Gaussian tracking noise, a rectangular exposure, regular frames, one
recording.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope
from .._constants import BOLTZMANN
from ._anharmonic_fit import BETA_BOUNDS, Z95, gauss_newton, k4_profile_interval
from ._anharmonic_moments import frame_moments, square_covariance
from ._fit import chi2_sf

_PARAMS = ("k", "k4", "gamma", "tracking_var")
DEFAULT_SQUARE_LAGS = (1, 2)
_LAB = {"k": (1e3, "pN/nm"), "k4": (1e-15, "pN/nm^3"), "gamma": (1e6, "pN s/um"),
        "tracking_var": (1e18, "nm^2")}


@dataclasses.dataclass(frozen=True)
class AnharmonicResult:
    """Result of :func:`calibrate_anharmonic` (SI units).

    ``k`` [N/m] is the harmonic coefficient (small-amplitude stiffness), ``k4`` [N/m^3],
    ``gamma`` [N s/m], ``tracking_var`` = eps^2 [m^2] (the unconstrained moment estimate:
    below 0 within its error when the tracking noise is small; a note says so), each with
    ``*_err``; ``beta`` =
    k4 kT/k^2 (dimensionless); ``covariance`` in the order ``("k", "k4", "gamma",
    "tracking_var")``; ``gof`` the J test; ``lags`` and ``bandwidth`` as used."""

    k: float
    k_err: float
    k4: float
    k4_err: float
    gamma: float
    gamma_err: float
    tracking_var: float
    tracking_var_err: float
    beta: float
    beta_err: float
    covariance: np.ndarray
    temperature: float
    n_frames: int
    lags: tuple[int, ...]
    bandwidth: int
    gof: dict
    converged: bool
    iterations: int
    notes: tuple[str, ...] = ()
    square_lags: tuple[int, ...] = ()
    intervals: dict = dataclasses.field(default_factory=dict)
    interval_kinds: dict = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict in SI units."""
        out: dict[str, Any] = {n: float(getattr(self, n)) for n in (
            "k", "k_err", "k4", "k4_err", "gamma", "gamma_err", "tracking_var",
            "tracking_var_err", "beta", "beta_err", "temperature")}
        out.update(param_names=list(_PARAMS), covariance=np.asarray(self.covariance).tolist(),
                   n_frames=self.n_frames, lags=list(self.lags), bandwidth=self.bandwidth,
                   gof=dict(self.gof), converged=self.converged, iterations=self.iterations,
                   notes=list(self.notes), method="anharmonic_gmm", units="SI",
                   square_lags=list(self.square_lags),
                   intervals={n: [float(a), float(b)] for n, (a, b) in self.intervals.items()},
                   interval_kinds=dict(self.interval_kinds))
        return out

    def summary(self) -> str:
        """A table in lab units (k pN/nm, k4 pN/nm^3, gamma pN s/um, eps nm)."""
        kt = BOLTZMANN * self.temperature
        rows = [(n, getattr(self, n) * f, getattr(self, n + "_err") * f, u)
                for n, (f, u) in _LAB.items()]
        rows.append(("beta = k4 kT/k^2", self.beta, self.beta_err, ""))
        tau = self.gamma / self.k
        rows.append(("tau = gamma/k", tau * 1e3, math.nan, "ms"))
        rows.append(("eps (tracking rms)", math.sqrt(max(self.tracking_var, 0.0)) * 1e9,
                     math.nan, "nm"))
        lines = [f"method: anharmonic GMM (exact blurred moments)   frames: {self.n_frames}   "
                 f"T = {self.temperature:g} K (kT = {kt * 1e21:.4g} pN nm)",
                 f"  {'parameter':<20}  {'value':>12}  {'+- error':>10}  unit"]
        for name, v, e, unit in rows:
            err = f"{e:10.3g}" if math.isfinite(e) else " " * 10
            lines.append(f"  {name:<20}  {v:12.6g}  {err}  {unit}".rstrip())
        if "k4" in self.intervals:
            lo, hi = (v * _LAB["k4"][0] for v in self.intervals["k4"])
            lines.append(f"  k4 95 % interval: ({lo:.4g}, {hi:.4g}) pN/nm^3   "
                         f"[{self.interval_kinds.get('k4', '')}]")
        g = self.gof
        lines.append(f"  goodness of fit: J test: statistic = {g['statistic']:.4g}, "
                     f"dof = {g['dof']}, p = {g['p_value']:.3g}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.summary()


@functools.partial(jax.jit, static_argnums=(2, 3))
def _model(phi, consts, n_grid, n_modes):
    """Scaled model moments at phi = (log k, beta, log gamma, eps^2/s^2).

    consts = (kT/s^2, W, dt, lags, sq_lags): positions are in units of the data scale s."""
    kt_s2, w, dt, lags, sq_lags = consts
    k, beta, gamma, e2 = jnp.exp(phi[0]), phi[1], jnp.exp(phi[2]), phi[3]
    tau = gamma / k
    var, cov, m4 = frame_moments(beta, w / tau, dt / tau, lags, n_grid, n_modes)
    s02 = kt_s2 / k
    c0 = s02 * var + e2
    q4 = s02**2 * m4 + 6.0 * s02 * var * e2 + 3.0 * e2**2
    out = [c0[None], s02 * cov, q4[None]]
    if sq_lags.shape[0]:
        sq = square_covariance(beta, w / tau, dt / tau, sq_lags, n_grid, n_modes)
        out.append(s02**2 * sq + 2.0 * s02 * var * e2 + e2**2)
    return jnp.concatenate(out)


_model_jac = jax.jit(jax.jacfwd(_model), static_argnums=(2, 3))


def _default_lags(tau_frames, n):
    raw = [1, 2, 3] + [round(f * tau_frames) for f in (0.25, 0.5, 1.0, 2.0, 3.0)]
    top = max(3, n // 20)
    return tuple(sorted({min(max(int(v), 1), top) for v in raw}))


def _contributions(y, lags, sq_lags=()):
    n = y.size - max(tuple(lags) + tuple(sq_lags))
    y2 = y**2
    cols = ([y2[:n]] + [y[:n] * y[lag:lag + n] for lag in lags] + [y2[:n] ** 2]
            + [y2[:n] * y2[lag:lag + n] for lag in sq_lags])
    return np.stack(cols, axis=1)


def _hac(g, bandwidth):
    """Bartlett (Newey-West) long-run covariance of the rows of g."""
    u = g - g.mean(axis=0)
    n = u.shape[0]
    omega = u.T @ u / n
    for j in range(1, bandwidth + 1):
        gj = u[j:].T @ u[:-j] / n
        omega += (1.0 - j / (bandwidth + 1.0)) * (gj + gj.T)
    return omega


def _check(recording, lags, bandwidth, n_grid, max_iter, square_lags=None):
    from ..data import Recording

    if not isinstance(recording, Recording):
        raise TypeError("recording must be a blurtrap.Recording (one trace); got "
                        f"{type(recording).__name__}")
    if recording.position_unit != "m":
        raise ValueError("calibrate_anharmonic needs positions in metres; got a recording in "
                         "volts (position_unit = 'V'): convert it with the displacement "
                         "sensitivity first")
    if recording.n_frames < 512:
        raise ValueError(f"recording has {recording.n_frames} frames; calibrate_anharmonic "
                         "needs >= 512 (the kurtosis of fewer frames cannot resolve k4)")
    if lags is not None:
        arr = np.asarray(lags)
        if (arr.ndim != 1 or arr.size < 2 or not np.issubdtype(arr.dtype, np.integer)
                or np.any(arr < 1) or np.unique(arr).size != arr.size
                or arr.max() > recording.n_frames // 10):
            raise ValueError("lags must be >= 2 distinct integers >= 1 and <= n_frames/10 = "
                             f"{recording.n_frames // 10}; got lags = {lags!r}")
    if square_lags is not None:
        arr = np.asarray(square_lags)
        if (arr.ndim != 1 or (arr.size and (not np.issubdtype(arr.dtype, np.integer)
                                            or np.any(arr < 1) or arr.max() > recording.n_frames // 10))
                or np.unique(arr).size != arr.size):
            raise ValueError("square_lags must be distinct integers >= 1 and <= n_frames/10 = "
                             f"{recording.n_frames // 10} (or empty); got square_lags = {square_lags!r}")
    for name, v, lo in (("bandwidth", bandwidth, 1), ("n_grid", n_grid, 61),
                        ("max_iter", max_iter, 1)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | np.integer)
                              or v < lo):
            raise ValueError(f"{name} must be an integer >= {lo}; got {name} = {v!r}")


def _start_values(start):
    try:
        k0, g0, e0 = (float(v) for v in start)
        ok = k0 > 0 and g0 > 0 and e0 >= 0 and all(map(math.isfinite, (k0, g0, e0)))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError("start must be a CalibrationResult or (k [N/m] > 0, gamma [N s/m] > 0, "
                         f"eps^2 [m^2] >= 0); got start = {start!r}")
    return k0, g0, e0


def _fit_setup(recording, lags, square_lags, bandwidth, start):
    """Start values, lags, the scaled moment contributions and their HAC weight."""
    from ._calibrate import moment_start

    if start is None:
        k0, g0, e0, _ = moment_start(recording)
    elif hasattr(start, "k") and hasattr(start, "gamma"):
        k0, g0, e0 = start.k, start.gamma, max(start.tracking_var, 0.0)
    else:
        k0, g0, e0 = _start_values(start)
    tau_frames = g0 / k0 / float(recording.frame_interval)
    lags = _default_lags(tau_frames, recording.n_frames) if lags is None else tuple(
        int(v) for v in lags)
    square_lags = DEFAULT_SQUARE_LAGS if square_lags is None else tuple(
        int(v) for v in square_lags)
    x = np.asarray(recording.positions, dtype=np.float64)
    x = x - x.mean()
    s = float(x.std())
    g = _contributions(x / s, lags, square_lags)
    n = g.shape[0]
    if bandwidth is None:
        bandwidth = int(min(math.ceil(15.0 * max(tau_frames, 1.0)) + max(lags + square_lags),
                            n // 4))
    winv = np.linalg.inv(_hac(g, bandwidth))
    return (k0, g0, e0), lags, square_lags, s, g.mean(axis=0), winv, n, int(bandwidth)


def _notes(converged, beta, e2_m2, err, dof, n_moments, k4, k4_se, k4_iv, k4_kind):
    notes = []
    if not converged:
        notes.append("Gauss-Newton did not converge; treat the estimates with caution")
    if dof <= 0:
        notes.append(f"the J test has {dof} degrees of freedom ({n_moments} moments for 4 "
                     "parameters): the fit is exactly identified, so it has no goodness-of-fit "
                     "check (statistic ~0, p = NaN); pass more lags or square_lags for one")
    if beta <= BETA_BOUNDS[0] + 1e-9 or beta >= BETA_BOUNDS[1] - 1e-9:
        notes.append(f"beta = {beta:.3g} is at its bound {BETA_BOUNDS}")
    if beta < 0:
        notes.append("k4 < 0: a quartic term that does not confine (continued by a sextic "
                     "term); consistent with a harmonic trap if |k4| < 2 SE")
    half = Z95 * k4_se
    if k4_kind.startswith("profile") and half > 0 and max(
            abs(k4_iv[0] - (k4 - half)), abs(k4_iv[1] - (k4 + half))) > 0.25 * half:
        notes.append(f"k4's error is not a normal one here (|k4|/SE = {abs(k4) / k4_se:.2g}): "
                     f"its 95 % interval is intervals['k4'] = ({k4_iv[0]:.3g}, {k4_iv[1]:.3g}) "
                     "N/m^3 (profile of the GMM distance), not k4 +- 1.96 SE")
    if e2_m2 < 0:
        # unconstrained, as a moment estimate is (clipping it at 0 would bias it up)
        se = float(err[3])
        z = e2_m2 / se if math.isfinite(se) and se > 0 else math.nan
        notes.append(f"eps^2 < 0 ({z:.2g} SE): the moment estimate is not held at its bound "
                     "(unlike calibrate's likelihood fits); "
                     + ("its error is not available" if not math.isfinite(z) else
                        "consistent with no tracking noise within its error" if z > -2 else
                        "a significantly negative eps^2 means the moments do not follow this "
                        "model (a detector filter, wrong exposure or frame interval)"))
    return tuple(notes)


@float64_scope
def calibrate_anharmonic(recording, *, lags=None, square_lags=None, bandwidth: int | None = None,
                         start=None, n_grid: int = 121, max_iter: int = 50,
                         profile: bool = True) -> AnharmonicResult:
    r"""Fit ``k``, ``k4``, ``gamma`` and ``eps^2`` of a quartic trap to one recording.

    Generalized method of moments on exact blurred-frame moments (module docstring): valid for
    cameras (any exposure ``W <= dt``, where the frame histogram is *not* the Boltzmann law)
    and photodiodes (``W -> 0``). ``k`` is the harmonic coefficient of
    ``U = k x^2/2 + k4 x^4/4`` (the small-amplitude stiffness), not the harmonic fit's
    effective ``kT/var``.

    **Arguments:**

    - `recording`: a :class:`blurtrap.Recording` (positions in metres, >= 512 frames).
    - `lags`: autocovariance lags in frames (default: 1, 2, 3 and ~0.25-3 correlation times of
      the moment start).
    - `square_lags`: lags of the covariance of squared frames ``mean x_t^2 x_{t+l}^2``
      (default ``(1, 2)``; ``()`` for none).
    - `bandwidth`: Bartlett bandwidth in frames for the moments' covariance (default
      ``ceil(15 tau/dt) + max(lags)``, at most ``n/4``).
    - `start`: optional ``(k, gamma, eps^2)`` start [SI] or a ``CalibrationResult`` (default:
      the closed-form moment start of ``calibrate``); ``k4`` starts at 0.
    - `n_grid`: grid points of the generator (default 121; relative error of the moments
      ~1e-4 for the variance and kurtosis, ~5e-3 for C(l) at 3 correlation times).
    - `max_iter`: Gauss-Newton iterations (default 50).
    - `profile`: the 95 % interval of ``k4`` from the profile of the GMM distance (default;
      ``False``: Wald, and no extra fits).

    **Returns:** :class:`AnharmonicResult` (``summary()`` in lab units, ``to_dict()``,
    ``intervals``).

    **Raises:** ``TypeError`` for a non-``Recording``; ``ValueError`` naming the argument for
    bad lags, bandwidth, grid or iteration counts, or too short a recording.
    """
    _check(recording, lags, bandwidth, n_grid, max_iter, square_lags)
    dt, w = float(recording.frame_interval), float(recording.exposure)
    kt = BOLTZMANN * float(recording.temperature)
    (k0, g0, e0), lags, square_lags, s, ghat, winv, n, bandwidth = _fit_setup(
        recording, lags, square_lags, bandwidth, start)
    consts = (kt / s**2, w, dt, jnp.asarray(lags), jnp.asarray(square_lags, dtype=int))

    def model(p):
        return _model(p, consts, n_grid, 16)

    def jac(p):
        return _model_jac(p, consts, n_grid, 16)

    phi0 = np.array([math.log(k0), 0.0, math.log(g0), e0 / s**2])
    phi, gm, converged, its = gauss_newton(ghat, winv, model, jac, phi0, max_iter, n)
    cov_phi = np.linalg.inv(gm.T @ winv @ gm) / n
    r = ghat - np.asarray(model(jnp.asarray(phi)))
    jstat = float(n * r @ winv @ r)
    dof = ghat.size - 4
    k, beta, gamma, e2 = math.exp(phi[0]), float(phi[1]), math.exp(phi[2]), float(phi[3])
    # d(k, k4, gamma, eps^2)/d(phi); k4 = beta k^2/kT
    jt = np.diag([k, k * k / kt, gamma, s**2])
    jt[1, 0] = 2.0 * beta * k * k / kt
    cov = jt @ cov_phi @ jt.T
    err = np.sqrt(np.diag(cov))
    vals = (k, beta * k * k / kt, gamma, e2 * s**2)
    ivs = {nm: (v - Z95 * e, v + Z95 * e) for nm, v, e in zip(_PARAMS, vals, err, strict=True)}
    kinds = dict.fromkeys(_PARAMS, "wald")
    if profile and converged:
        ivs["k4"], kinds["k4"] = k4_profile_interval(ghat, winv, model, jac, phi, n, kt,
                                                     float(err[1]))
    return AnharmonicResult(
        k=k, k_err=float(err[0]), k4=vals[1], k4_err=float(err[1]), gamma=gamma,
        gamma_err=float(err[2]), tracking_var=vals[3], tracking_var_err=float(err[3]),
        beta=beta, beta_err=float(math.sqrt(cov_phi[1, 1])), covariance=cov,
        temperature=float(recording.temperature), n_frames=int(recording.n_frames),
        lags=lags, bandwidth=bandwidth,
        gof={"test": "J (GMM overidentification)", "statistic": jstat, "dof": dof,
             "p_value": float(chi2_sf(jstat, dof)) if dof > 0 else math.nan},
        converged=bool(converged), iterations=int(its),
        notes=_notes(converged, beta, vals[3], err, dof, ghat.size, vals[1], float(err[1]),
                     ivs["k4"], kinds["k4"]),
        square_lags=square_lags, intervals={nm: (float(a), float(b)) for nm, (a, b) in ivs.items()},
        interval_kinds=kinds)
