"""Batched calibration: many recordings of the same shape in one vmapped, jitted call.

For sweeps ("how wrong is the naive calibration over this grid?") and large data sets.
Every item gets its own status: one failing fit never aborts the batch.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import float64_scope, warn_if_float32
from .._constants import BOLTZMANN, DEFAULT_TEMPERATURE
from . import _batch_checks as checks
from ._fit import _finish_from, _newton, fit_ml
from ._models import get_model
from ._problems import RecMeta, SpectralArgs, make_layout, spectral_model_psd, spectral_nll

#: default ``gof_threshold`` of :func:`calibrate_batch` (see its docstring for the measured
#: false-alarm rate)
GOF_THRESHOLD = 1e-4


@dataclasses.dataclass(frozen=True)
class BatchCalibration:
    """Per-item results (numpy arrays of shape ``batch``; SI units)."""

    k: np.ndarray
    k_err: np.ndarray
    gamma: np.ndarray
    gamma_err: np.ndarray
    tracking_var: np.ndarray
    tracking_var_err: np.ndarray
    diffusion: np.ndarray
    success: np.ndarray  # bool: status == "ok"
    n_steps: np.ndarray
    #: per item: "ok", "not converged", "singular Fisher information" (a parameter at its
    #: bound or unidentifiable: errors are NaN), "relaxation not resolved" (tau > T/3: the
    #: bead diffuses almost freely and k is not identified), "constant trace" (no
    #: fluctuations; values NaN), or, with values and errors NaN, "invalid: ..." (NaN/inf
    #: frames, positions not in metres), "refused: ..." (dt >> tau or tracking noise swamps
    #: the motion: gamma not identifiable) or "inadequate: goodness of fit p = ..." (the model
    #: does not describe the spectrum, e.g. a line or drift)
    status: np.ndarray
    method: str
    model: str
    #: per item: p-value of the binned spectral goodness-of-fit test of ``calibrate``
    #: (``result.gof``), NaN where no fit was made or the spectrum has fewer than one bin
    gof_p: np.ndarray | None = None
    #: per item: its chi^2 statistic (``gof_dof`` degrees of freedom, the same for all items)
    gof_statistic: np.ndarray | None = None
    gof_dof: int = 0
    #: items with ``gof_p`` below this are "inadequate"
    gof_threshold: float = GOF_THRESHOLD
    #: per item: lag-1 correlation of the frames in standard errors (``r1 sqrt(N)``); below
    #: 5 the frames carry no temporal information and the item is refused
    lag1_z: np.ndarray | None = None
    #: per item ("ok" items only): a parameter, as a rule tracking_var, was held at its lower
    #: bound 0 (``calibrate``'s ``result.at_bounds``), and the other errors are conditional
    #: on it. They can then be far too small: of 400 simulated camera records (k = 5e-5 N/m,
    #: W = dt = 1/1500 s, 2 nm tracking noise, 65 536 frames) 43 had eps^2 at 0, and all 43
    #: had k 5-20 SE off (about 0.86 k), the same fits as ``calibrate`` returns
    at_bound: np.ndarray | None = None

    def __len__(self):
        return len(self.k)

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in out.items()}

    #: per-item columns by name (``batch["k"]``): SI arrays
    _COLUMNS = ("k", "k_err", "gamma", "gamma_err", "tracking_var", "tracking_var_err",
                "diffusion", "status", "success", "gof_p", "lag1_z", "at_bound")

    def __getitem__(self, name: str) -> np.ndarray:
        """A per-item column by name (SI): ``batch["k"]``, ``batch["gamma_err"]``,
        ``batch["D"]`` (= diffusion), ``batch["status"]`` ..."""
        key = "diffusion" if name == "D" else name
        if key not in self._COLUMNS or getattr(self, key) is None:
            raise KeyError(f"no column {name!r}; columns: "
                           f"{[c for c in self._COLUMNS if getattr(self, c) is not None]}")
        return np.asarray(getattr(self, key))

    def to_dataframe(self):
        """One row per item: values and errors in SI and lab units, status, goodness of fit.
        Needs pandas (``pip install "blurtrap[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError('to_dataframe needs pandas: pip install "blurtrap[pandas]"'
                              ) from None
        cols = {c: np.ravel(getattr(self, c)) for c in self._COLUMNS
                if getattr(self, c) is not None}
        cols["k_pN_per_nm"] = cols["k"] * 1e3
        cols["gamma_pN_s_per_um"] = cols["gamma"] * 1e6
        cols["D_um2_per_s"] = cols["diffusion"] * 1e12
        return pd.DataFrame(cols)

    def summary(self) -> str:
        """Counts by status and the median k, gamma, D of the "ok" items, in lab units."""
        status = np.ravel(self.status)
        ok = status == "ok"
        kinds, counts = np.unique([s.split(":")[0] for s in status], return_counts=True)
        lines = [f"{len(status)} items ({self.method}, model {self.model}): "
                 + ", ".join(f"{c} {k}" for k, c in zip(kinds, counts))]
        if ok.any():
            for name, fac, unit in (("k", 1e3, "pN/nm"), ("gamma", 1e6, "pN s/um"),
                                    ("diffusion", 1e12, "um^2/s")):
                v = np.ravel(getattr(self, name))[ok] * fac
                lines.append(f"  {name}: median {np.median(v):.5g} {unit} (16-84 %: "
                             f"{np.percentile(v, 16):.4g}..{np.percentile(v, 84):.4g})")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        import html

        return f"<pre>{html.escape(self.summary())}</pre>"


class _Rec:
    def __init__(self, dt, w, t):
        self.frame_interval, self.exposure, self.temperature = dt, w, t
        self.laser_power = None
        self.name = None


def _lag_moments(power, m, dt):
    """Circular autocovariances at lags 0, 1, 2 of the (mean-removed) blocks, from their
    periodograms ``power`` (B, M//2) at j = 1..M//2: ``c_k = 1/(M dt) sum_j w_j I_j
    cos(2 pi j k / M)`` over the full circle (w_j = 2, 1 at the Nyquist ordinate of an even M;
    j = 0 is 0 after mean removal). They differ from the lag products of ``moment_start``
    by O(1/M), immaterial for start values, for a small matrix product instead of three
    passes over the frames."""
    return (power @ _lag_basis(m, dt)).T


@functools.lru_cache(maxsize=8)
def _lag_basis(m, dt):
    j = np.arange(1, m // 2 + 1)
    wt = np.full(j.shape, 2.0)
    if m % 2 == 0:
        wt[-1] = 1.0
    return wt[:, None] * np.cos(2.0 * np.pi * np.outer(j, np.arange(3)) / m) / (m * dt)


def _moment_starts(c0, c1, c2, dt, w, temp):
    """Vectorised closed-form starts from lag moments (same estimator as ``moment_start``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(c1 > 0, c2 / c1, np.exp(-1.0))
    rho = np.clip(np.nan_to_num(rho, nan=np.exp(-1.0)), 0.05, 0.99999)
    tau = -dt / np.log(rho)
    a, r = w / tau, dt / tau
    phi1 = np.where(a < 1e-6, 1.0 - a / 2, -np.expm1(-a) / np.maximum(a, 1e-300))
    rho_b = phi1**2 * np.exp(a - r)
    s = np.where(a < 1e-3, 1 - a / 3 + a * a / 12, 2 / np.maximum(a, 1e-300)
                 * (1 + np.expm1(-a) / np.maximum(a, 1e-300)))
    sigma2 = np.where(c1 > 0, c1 / rho_b, c0)
    sigma2 = np.clip(sigma2, 0.3 * c0 / s, 3.0 * c0 / s)
    eps2 = np.maximum(c0 - sigma2 * s, 0.02 * c0)
    k = BOLTZMANN * temp / sigma2
    return np.stack([k, k * tau, eps2], axis=1)


#: rows per block of the host-side preparation (periodograms, start values): the same
#: per-row arithmetic as whole-array numpy calls, without GB-sized temporaries, whose fresh
#: pages cost more than the FFTs (1000 x 65 536 frames: 2.2 s -> 0.4 s for the start values)
_HOST_ROWS = 16


def _periodograms(y, n_blocks, m, dt):
    """Block-averaged periodograms (B, M//2) of every row: mean removed per block, ordinates
    j = 1..M/2, ``dt/M |FFT|^2`` averaged over the blocks; with the lag moments of
    :func:`_lag_moments` (3, B), the mean ordinate (B,) and the per-row checks of
    :func:`_batch_checks.row_stats` (B, 6), all taken while a block of rows is at hand."""
    out = np.empty((y.shape[0], m // 2))
    mom = np.empty((3, y.shape[0]))
    avg = np.empty(y.shape[0])
    stats = np.empty((y.shape[0], 6))
    for i in range(0, y.shape[0], _HOST_ROWS):
        stats[i:i + _HOST_ROWS] = checks.row_stats(y[i:i + _HOST_ROWS])
        with np.errstate(all="ignore"):  # rows with NaN/inf are replaced in _prepare
            blocks = y[i:i + _HOST_ROWS, : m * n_blocks].reshape(-1, n_blocks, m)
            blocks = blocks - blocks.mean(axis=2, keepdims=True)
            spec = np.fft.rfft(blocks, axis=2)[:, :, 1:]
            rows = out[i:i + _HOST_ROWS]
            rows[:] = (spec.real**2 + spec.imag**2).mean(axis=1) * dt / m
            mom[:, i:i + _HOST_ROWS] = _lag_moments(rows, m, dt)
            avg[i:i + _HOST_ROWS] = rows.mean(axis=1)
    return out, mom, avg, stats


#: rows per jitted call of calibrate_batch (larger batches are cut into chunks of this size)
_CHUNK = 64


def _prepare(y, n_blocks, m, dt, w, temp, noise, check_units):
    """Host-side inputs of the fit for rows ``y``: periodograms (B, M//2), start values, log
    reference levels, the per-row checks (B, 6) and the status of rows that are not fitted
    (``""`` for the others). Rows not fitted get a stand-in spectrum (not reported)."""
    power, mom, avg, stats = _periodograms(y, n_blocks, m, dt)
    pre = checks.prefit_status(stats, check_units)
    skip = pre != ""
    if skip.any():  # harmless stand-in data for the vmapped fit only
        power[skip] = power[~skip].mean(axis=0) if (~skip).any() else 1e-20
        mom[:, skip] = _lag_moments(power[skip], m, dt)
        avg[skip] = power[skip].mean(axis=1)
    starts = _moment_starts(mom[0], mom[1], mom[2], dt, w, temp)
    if not noise:
        starts = starts[:, :2]
    return power, starts, np.log(avg), stats, pre


#: Newton steps per item inside the vmapped fit. Under ``vmap`` a while loop runs until its
#: slowest item stops, so one hard item makes its whole chunk pay for its passes; from the
#: coarse start (records of >= 8192 frames) almost every item converges in 1-2 steps, from
#: the closed-form start of short records in 4-7. The rare rest is refitted alone on the host
#: side (the same Newton-then-BFGS fit as ``calibrate``; that compiles the single-record fit
#: once, so it must stay rare: 4 steps sent half of the 4096-frame items there).
_BATCH_NEWTON_STEPS = 16


def _gof(value, a: SpectralArgs, per: int, nbin: int):
    """Goodness-of-fit numbers (:func:`_batch_checks.gof_stats`) of one record's fit."""
    return checks.gof_stats(a.power[0] / spectral_model_psd(value, a)[0], a.weight[0], per,
                            nbin)


_gof_jit = eqx.filter_jit(_gof)  # for the items refitted alone


@eqx.filter_jit
def _batch_fit(scale, power, log_ref, shared: SpectralArgs, per: int, nbin: int, rtol=1e-9,
               atol=1e-9):
    """Newton only, at most ``_BATCH_NEWTON_STEPS`` steps: under vmap a ``lax.cond``
    fallback would run for every item, so items whose fit does not succeed are refitted one
    by one on the host side. Returns the fits and their goodness-of-fit numbers."""

    def one(s, pw, lr):
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared, (pw, lr))
        x_hat, x, v, g, h, ok, n = _newton(spectral_nll, s, a, rtol, atol, _BATCH_NEWTON_STEPS)
        out = _finish_from(x, v, g, h, s, ok, n, x_value=x_hat)
        return out, _gof(out.value, a, per, nbin)

    return jax.vmap(one)(scale, power, log_ref)


@float64_scope
def calibrate_batch(
    positions,
    *,
    frame_interval: float,
    exposure: float,
    temperature: float = DEFAULT_TEMPERATURE,
    model=None,
    n_blocks: int = 1,
    check_units: bool = True,
    gof_threshold: float = GOF_THRESHOLD,
) -> BatchCalibration:
    """Calibrate each row of ``positions`` (shape (B, N), metres) in one vmapped call.

    Items are independent: each has its own ``status`` and a failing item never aborts
    the batch (its errors are NaN). Uses the Whittle likelihood (``n_blocks=1``, the
    default of :func:`calibrate` for long records) or the blocked-PSD Gamma likelihood
    (``n_blocks > 1``) with the given model. It stays Whittle where ``calibrate``'s default
    would switch to the exact likelihood (records of <= 2^14 frames, or tau not short
    compared with the record).
    All rows share ``frame_interval`` [s], ``exposure`` [s] and ``temperature`` [K].

    Every item gets the checks of :func:`calibrate`, without aborting the others:

    - the checks of a ``Recording``: NaN/inf frames (``"invalid: NaN at frame 17"``), a
      constant trace (``"constant trace"``) and, with ``check_units`` (default), positions
      whose standard deviation exceeds 1 mm (``"invalid: positions look like nm ..."``);
      frame interval or exposure above 1 s or a temperature below 100 K concern every row
      and raise ``ValueError``;
    - the refusal of frames without temporal information (lag-1 correlation below 5
      standard errors: dt >> tau, or tracking noise swamping the motion, where gamma is not
      identifiable from one exposure): ``"refused: no temporal information ..."``; after
      the fit, a relaxation time longer than a third of the record (block) is
      ``"relaxation not resolved"``, or ``"refused: dt >> tau ..."`` when the frames are
      far less correlated than a freely diffusing bead's;
    - the binned spectral goodness-of-fit test of ``calibrate`` (``result.gof``): its
      p-value is ``gof_p``, and items below ``gof_threshold`` are ``"inadequate: goodness of
      fit p = ... (line at 50 Hz? ...)"`` (a missing effect: line noise, drift, a detector
      filter; diagnose such a row with :func:`blurtrap.diagnose`). False-alarm rate at the
      default 1e-4, measured on honest items: 3 of 7400 flagged (0.04 %; nominal 0.01 %,
      consistent with a tail a little heavier than chi^2's: each bin's term has variance
      2 + 6/64, not 2), namely 3/5000 exact
      AR(1) records of 16 384 frames (W ~ 0, dt/tau = 0.5, 2 nm white noise; 125 dof),
      0/1000 of 4096 frames, and 0/1400 simulated camera records (W = dt) of 4096 and
      65 536 frames; below p = 0.05 lie 4.9 % of the first 5000 (nominal 5 %).

    Items not fitted ("invalid", "constant trace", "refused" before the fit) and items
    "inadequate" or refused after it have NaN values and errors; other failed items keep
    their fitted values with NaN errors. A batch with no finite, fluctuating row at all
    (empty, every row NaN/inf or constant) raises ``ValueError``: there is nothing to
    calibrate.

    **Returns:** :class:`BatchCalibration` with per-item values, errors, ``status``,
    ``success`` (status ``"ok"``), ``gof_p``, ``lag1_z`` and ``at_bound`` (an "ok" item
    with eps^2 held at 0, whose other errors are conditional on it and can be far too
    small).
    """
    warn_if_float32("positions", positions)
    y = np.asarray(positions, dtype=float)
    if y.ndim != 2:
        raise ValueError(f"positions must have shape (batch, frames); got shape {y.shape}")
    b, n = y.shape
    if b == 0:
        raise ValueError(f"positions holds no records (shape {y.shape}): nothing to calibrate")
    if isinstance(n_blocks, bool) or not isinstance(n_blocks, (int, np.integer)) or n_blocks < 1:
        raise ValueError(f"n_blocks must be an integer >= 1; got n_blocks = {n_blocks!r}")
    m = n // n_blocks
    if m < 8:
        raise ValueError(f"n_blocks = {n_blocks} leaves {m} frames per block; need >= 8")
    if not isinstance(check_units, (bool, np.bool_)):
        raise ValueError(f"check_units must be True or False; got {check_units!r}")
    gof_threshold = float(gof_threshold)
    if not 0.0 <= gof_threshold < 1.0:
        raise ValueError(f"gof_threshold must be in [0, 1); got {gof_threshold!r}")
    mdl = get_model(model)
    dt, w, t = float(frame_interval), float(exposure), float(temperature)
    checks.check_shared(dt, w, t, bool(check_units))
    for row in y:  # stops at the first usable row (the first, as a rule)
        if np.isfinite(row).all() and row.max() != row.min():
            break
    else:
        bad = np.argwhere(~np.isfinite(y))
        where = f" (NaN/inf first at row {bad[0][0]}, frame {bad[0][1]})" if bad.size else ""
        raise ValueError("positions hold no finite, fluctuating row: every row is constant or "
                         f"contains NaN/inf{where}. There is nothing to calibrate.")
    f = np.arange(1, m // 2 + 1) / (m * dt)
    weight = np.full(f.shape, float(n_blocks))
    if m % 2 == 0:
        weight[-1] *= 0.5
    per, nbin = checks.gof_bins(weight)
    layout = make_layout([_Rec(dt, w, t)], "shared", mdl.noise)
    n_par = len(layout.names)
    shared = SpectralArgs(
        layout=layout, model=mdl,
        meta=RecMeta(dt=jnp.asarray([dt]), w=jnp.asarray([w]), temp=jnp.asarray([t])),
        f=jnp.asarray(f[None]), s2=jnp.asarray(np.sin(np.pi * f * dt)[None] ** 2),
        power=jnp.zeros((1, f.size)), weight=jnp.asarray(weight[None]),
        log_ref=jnp.asarray(0.0),
        # the exact expected periodogram of M frames, as in calibrate
        block_len=(jnp.asarray([float(m)]) if mdl.alias and mdl.closed_form else None),
    )
    # Chunks of at most _CHUNK rows: one compiled shape for every large batch, host memory
    # bounded by the chunk, and the host-side periodograms of the next chunk overlap with
    # the (asynchronously dispatched) jitted fit of the previous one.
    chunk = min(b, _CHUNK)
    pending = []
    stats = np.empty((b, 6))
    pre = np.empty(b, dtype=object)
    for i0 in range(0, b, chunk):
        i1 = min(i0 + chunk, b)
        power, starts, log_ref, stats[i0:i1], pre[i0:i1] = _prepare(
            y[i0:i1], n_blocks, m, dt, w, t, mdl.noise, bool(check_units))
        if np.all(pre[i0:i1] != ""):  # nothing to fit in this chunk
            pending.append((i0, i1, None))
            continue
        pad = chunk - (i1 - i0)  # the last chunk repeats its first row: same compiled shape
        if pad:
            power, starts, log_ref = (np.concatenate([z, np.repeat(z[:1], pad, axis=0)])
                                      for z in (power, starts, log_ref))
        pending.append((i0, i1, _batch_fit(jnp.asarray(starts), jnp.asarray(power[:, None, :]),
                                           jnp.asarray(log_ref), shared, per, nbin)))
    skip = pre != ""
    val, cov = np.empty((b, n_par)), np.empty((b, n_par, n_par))
    success, converged, pd = (np.empty(b, dtype=bool) for _ in range(3))
    steps = np.empty(b, dtype=int)
    gof = np.empty((b, 5))
    for i0, i1, res in pending:
        if res is None:
            val[i0:i1], cov[i0:i1], gof[i0:i1] = np.nan, np.nan, np.nan
            success[i0:i1], converged[i0:i1], pd[i0:i1], steps[i0:i1] = False, True, True, 0
            continue
        out, g = res
        n_i = i1 - i0
        val[i0:i1], cov[i0:i1] = np.asarray(out.value)[:n_i], np.asarray(out.cov)[:n_i]
        success[i0:i1] = np.asarray(out.success)[:n_i]
        steps[i0:i1] = np.asarray(out.n_steps)[:n_i]
        converged[i0:i1] = np.asarray(out.converged)[:n_i]
        pd[i0:i1] = np.asarray(out.hessian_pd)[:n_i]
        gof[i0:i1] = np.stack([np.asarray(z, dtype=float)[:n_i] for z in g], axis=1)
    for i in np.flatnonzero(~success & ~skip):  # rare: refit alone (Newton, then BFGS)
        power, starts, log_ref, _, _ = _prepare(y[i:i + 1], n_blocks, m, dt, w, t, mdl.noise,
                                                bool(check_units))
        a = eqx.tree_at(lambda z: (z.power, z.log_ref), shared,
                        (jnp.asarray(power), jnp.asarray(log_ref[0])))
        one = fit_ml(spectral_nll, jnp.asarray(starts[0]), a)
        val[i], cov[i] = np.asarray(one.value), np.asarray(one.cov)
        success[i], steps[i] = bool(one.success), int(one.n_steps)
        converged[i], pd[i] = bool(one.converged), bool(one.hessian_pd)
        gof[i] = [float(z) for z in _gof_jit(one.value, a, per, nbin)]
    gof_dof = max(nbin - n_par, 1)
    z = stats[:, 5]
    status = np.full(b, "ok", dtype=object)
    # a singular information is the symptom; an unresolved relaxation (below) its cause
    status[~pd] = "singular Fisher information"
    with np.errstate(divide="ignore", invalid="ignore"):
        unresolved = ~(val[:, 1] / val[:, 0] < m * dt / 3.0)
    status[unresolved] = "relaxation not resolved"
    # as calibrate: frames far less correlated than a freely diffusing bead's (r1 ~ 1) mean
    # that the fit ran tau up for want of temporal information, not free diffusion
    no_info = unresolved & (z < 0.5 * math.sqrt(n))
    for i in np.flatnonzero(no_info):
        status[i] = checks.no_information_status(z[i])
    status[~converged] = "not converged"
    gof[skip, 0] = np.nan  # not fitted: no test
    gof_p = checks.gof_p_values(gof[:, 0], gof_dof) if nbin > 0 else np.full(b, np.nan)
    for i in np.flatnonzero((status == "ok") & ~skip & (gof_p < gof_threshold)):
        status[i] = checks.inadequate_status(gof_p[i], gof[i, 1], gof[i, 2], gof[i, 3], gof[i, 4],
                                             f, per, n_blocks)
    status[skip] = pre[skip]
    refused = np.array([s.startswith(("invalid", "refused", "inadequate", "constant"))
                        for s in status])
    val[refused] = np.nan
    success = status == "ok"
    var = np.diagonal(cov, axis1=1, axis2=2)
    at_bound = np.isnan(var).any(axis=1) & np.isfinite(var).any(axis=1)
    if mdl.noise:  # calibrate's rule (_assemble): eps^2 below 1e-6 of the frame variance
        with np.errstate(invalid="ignore"):
            at_bound |= val[:, 2] < 1e-6 * stats[:, 4] ** 2
    at_bound &= success
    cov[~success] = np.nan  # never a confident error bar on a failed item
    err = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None))
    kt = BOLTZMANN * t
    zeros = np.zeros(b)
    return BatchCalibration(
        k=val[:, 0], k_err=err[:, 0], gamma=val[:, 1], gamma_err=err[:, 1],
        tracking_var=val[:, 2] if mdl.noise else zeros,
        tracking_var_err=err[:, 2] if mdl.noise else zeros,
        diffusion=kt / val[:, 1],
        success=success, n_steps=steps, status=status.astype(str),
        method="likelihood" if n_blocks == 1 else "psd", model=mdl.name,
        gof_p=gof_p, gof_statistic=gof[:, 0], gof_dof=int(gof_dof),
        gof_threshold=gof_threshold, lag1_z=z, at_bound=at_bound,
    )
