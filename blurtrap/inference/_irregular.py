r"""Exact likelihood of frames taken at irregular times (timing jitter, a wandering clock,
dropped frames), the remedy for the ``timing_jitter`` effect.

With regular frames the blurred, noisy frame sequence is a stationary ARMA(1,1) process
(:func:`blurtrap.inference._likelihood.arma_loglik`). With irregular frame times it is not
stationary, but it is still the output of a one-dimensional linear state-space model: let
``x_i = x(s_i)`` be the bead position at the start ``s_i`` of exposure i, ``y_i`` the frame
(the exposure average over ``[s_i, s_i + W]`` plus white tracking noise of variance eps^2) and
``Delta_i = s_(i+1) - s_i >= W``. For the Ornstein-Uhlenbeck motion (stationary variance
``sigma^2 = kT/k``, relaxation time ``tau = gamma/k``, ``alpha = W/tau``):

- ``y_i = a x_i + u_i + n_i`` with ``a = (1 - e^-alpha)/alpha`` and ``Var u_i = sigma^2 (S(alpha)
  - a^2)``, ``S(alpha) = 2 (alpha - 1 + e^-alpha)/alpha^2`` (paper eq. 5);
- ``x_(i+1) = b_i x_i + v_i`` with ``b_i = exp(-Delta_i / tau)``, ``Var v_i = sigma^2 (1 -
  b_i^2)``;
- ``Cov(u_i, v_i) = sigma^2 b_i 4 sinh^2(alpha/2) / alpha`` (the part of the exposure average
  that the next start position remembers beyond ``x_i``).

A Kalman filter with this correlated process/measurement noise gives the innovations and their
variances, hence the exact Gaussian log-likelihood in O(N) (one ``lax.scan``); the unknown trap
centre is handled as in :func:`arma_loglik` (the filter is linear in the data: run on the frames
and on a column of ones, GLS mean, REML correction). On a regular grid it equals
:func:`arma_loglik` (tested), and it is tested against the dense multivariate normal whose
covariance is integrated numerically from the OU kernel.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN
from ..data.internal import stamp_quantum
from ._likelihood import gls_loglik
from ._models import TrapModel
from ._problems import Layout, RecMeta, bucket_length, rec_meta

#: below this alpha = W/tau the exposure terms use their Taylor series (the direct formulas
#: cancel to ~1e-16/alpha relative; the series' truncation error is ~alpha^3)
_ALPHA_SERIES = 1e-3


def _exposure_terms(alpha):
    """(a, S - a^2, 4 sinh^2(alpha/2)/alpha) of an exposure alpha = W/tau >= 0, stable at 0."""
    small = alpha < _ALPHA_SERIES
    al = jnp.where(small, 1.0, alpha)  # safe value for the unselected branch (no NaN grads)
    em = -jnp.expm1(-al)  # 1 - e^-alpha
    a_direct = em / al
    s_direct = 2.0 * (al - em) / (al * al)
    q_direct = s_direct - a_direct * a_direct
    c_direct = 4.0 * jnp.sinh(0.5 * al) ** 2 / al
    a_ser = 1.0 - alpha / 2.0 + alpha**2 / 6.0 - alpha**3 / 24.0
    q_ser = 2.0 / 3.0 * alpha - 0.5 * alpha**2 + 7.0 / 30.0 * alpha**3
    c_ser = alpha + alpha**3 / 12.0
    return (jnp.where(small, a_ser, a_direct), jnp.where(small, q_ser, q_direct),
            jnp.where(small, c_ser, c_direct))


def irregular_loglik(y, intervals, exposure, sigma2, tau, eps2, *, mean: str = "reml",
                     mask=None):
    """Exact Gaussian log-likelihood of frames at irregular times.

    **Arguments:**

    - `y`: frames [m], shape (N,).
    - `intervals`: ``Delta_i = s_(i+1) - s_i`` [s] between the starts of consecutive
      exposures, shape (N,) (the last entry is not used), each >= `exposure`.
    - `exposure`: W [s] (0 for instantaneous sampling).
    - `sigma2`, `tau`, `eps2`: kT/k [m^2], gamma/k [s], tracking-error variance [m^2].
    - `mean`, `mask`: as in :func:`blurtrap.inference._likelihood.arma_loglik` (the mask must
      be a prefix of ones).

    **Returns:** log-likelihood (scalar).
    """
    if mean not in ("zero", "profile", "reml"):
        raise ValueError(f"mean must be 'zero', 'profile' or 'reml'; got mean = {mean!r}")
    y = jnp.asarray(y)
    if mask is None:
        mask = jnp.ones_like(y)
    n = jnp.sum(mask)
    if mean != "zero":
        y = (y - jnp.sum(mask * y) / n) * mask  # shift-invariant; centred for accuracy
    a, q, c, b, r = _frame_terms(intervals, exposure, tau)
    series = jnp.stack([y, jnp.ones_like(y)], axis=-1)  # filter y and the mean's regressor
    init = (jnp.zeros(2, dtype=y.dtype), jnp.asarray(1.0, dtype=y.dtype))
    _, (e, f) = _filter(series, b, r, mask, a, q, c, eps2 / sigma2, init)
    return gls_loglik(n, *_innovation_sums(e, f, sigma2, mask), mean)


def _frame_terms(intervals, exposure, tau):
    """``(a, Var u / sigma^2, Cov(u, v) / (sigma^2 b), b_i, 1 - b_i^2)`` of the state-space
    form (module doc) for frame intervals ``intervals`` and exposure ``exposure``."""
    a, q, c = _exposure_terms(exposure / tau)
    return a, q, c, jnp.exp(-intervals / tau), -jnp.expm1(-2.0 * intervals / tau)


def _filter(series, b, r, mask, a, q, c, noise, init):
    """The Kalman filter over frames: ``series`` (N, 2) the frames and a column of ones (the
    filter is linear in the data, so one recursion serves both), ``noise = eps^2 / sigma^2``,
    ``init = (state mean (2,), state variance / sigma^2)`` before the first frame. Frames with
    ``mask`` 0 (padding) leave the state as it is. Returns the final state and, per frame,
    the innovations (N, 2) and their variances / sigma^2 (N,)."""

    def step(carry, xs):
        m, p = carry  # state mean (2,) and variance (scaled by sigma2)
        yi, bi, ri, wi = xs
        f = a * a * p + q + noise
        e = yi - a * m
        g = bi * a * p + bi * c
        m_next = bi * m + (g / f) * e
        p_next = bi * bi * p + ri - g * g / f
        # padding (wi = 0) leaves the state as it is: it follows the real frames only
        m_next = jnp.where(wi > 0, m_next, m)
        p_next = jnp.where(wi > 0, p_next, p)
        return (m_next, p_next), (e, f)

    return jax.lax.scan(step, init, (series, b, r, mask))


def _innovation_sums(e, f, sigma2, mask):
    """``(sum log v, sum e_y^2/v, sum e_1 e_y/v, sum e_1^2/v)`` over the real frames, ``v = f
    sigma^2`` (the sums :func:`._likelihood.gls_loglik` takes)."""
    v = f * sigma2
    ey, e1 = e[:, 0], e[:, 1]
    wv = mask / v
    return (jnp.sum(mask * jnp.log(v)), jnp.sum(ey * ey * wv), jnp.sum(e1 * ey * wv),
            jnp.sum(e1 * e1 * wv))


#: the carry of :func:`chunk_step`: state mean (2), state variance / sigma^2, then the four
#: sums of :func:`_innovation_sums`
N_CARRY = 7


def chunk_step(theta, carry, y, m, d, w, mean):
    """The carry (:data:`N_CARRY`) after one chunk of frames ``y`` (mask ``m``, intervals
    ``d``) of one recording with exposure ``w`` and ``theta = (sigma^2, tau, eps^2)``: the
    recursion of :func:`irregular_loglik` continued from the carried state (the frame chunks
    of :mod:`._exact_chunks`). ``mean`` is unused: the four sums serve every mean treatment."""
    del mean
    sigma2, tau, e2 = theta[0], theta[1], theta[2]
    a, q, c, b, r = _frame_terms(d, w, tau)
    series = jnp.stack([y, jnp.ones_like(y)], axis=-1)
    (m_end, p_end), (e, f) = _filter(series, b, r, m, a, q, c, e2 / sigma2,
                                     (carry[:2], carry[2]))
    sums = jnp.stack(_innovation_sums(e, f, sigma2, m))
    return jnp.concatenate([m_end, p_end[None], carry[3:] + sums])


def initial_carry(dtype):
    """The carry before the first frame: state mean 0, state variance sigma^2 (1 scaled)."""
    return jnp.zeros(N_CARRY, dtype).at[2].set(1.0)


def frame_params(p, layout: Layout, model: TrapModel, meta: RecMeta):
    """``(sigma^2, tau, W, eps^2)`` per recording at parameters ``p`` (``W`` 0 without blur,
    ``eps^2`` 0 without tracking noise)."""
    k_rec, gamma, eps2 = layout.unpack(p)
    sigma2 = BOLTZMANN * meta.temp / k_rec
    tau = gamma / k_rec * jnp.ones_like(sigma2)
    w = exposures(model, meta) * jnp.ones_like(sigma2)
    e2 = (eps2 if model.noise else 0.0) * jnp.ones_like(sigma2)
    return sigma2, tau, w, e2


def exposures(model: TrapModel, meta: RecMeta):
    """The exposure W per recording [s] the filter uses: 0 for a model without blur."""
    return model._w(meta.w)  # noqa: SLF001


class IrregularArgs(eqx.Module):
    """Frames and frame intervals of R recordings, zero-padded to a common length."""

    layout: Layout
    model: TrapModel
    meta: RecMeta
    ys: jax.Array  # (R, N_max)
    intervals: jax.Array  # (R, N_max) [s]
    mask: jax.Array  # (R, N_max)
    mean: str = eqx.field(static=True, default="reml")


def frame_intervals(rec) -> np.ndarray:
    """Intervals between consecutive frames [s] (from the time stamps when the recording
    keeps them, else the nominal frame interval), shape (N,), last entry repeated."""
    n = rec.n_frames
    if rec.times is None:
        return np.full(n, float(rec.frame_interval))
    d = np.diff(np.asarray(rec.times, dtype=float))
    return np.append(d, d[-1] if d.size else float(rec.frame_interval))


def any_irregular(recordings) -> bool:
    """Whether a recording keeps irregular time stamps (``allow_irregular=True``)."""
    return any(r.times is not None and not r.is_regular for r in recordings)


def check_irregular_model(model: TrapModel, recordings) -> None:
    """The state-space form covers the closed-form models (rectangular exposure, white
    tracking noise); every interval must be at least the exposure (no overlapping frames),
    but for the rounding of the time stamps (:func:`rounding_shortfall`)."""
    if model.extra:
        raise ValueError(
            f"the irregular-time likelihood covers the closed-form models (naive, blur, "
            f"standard: rectangular exposure and white tracking noise); model {model.name!r} "
            "adds effects beyond those. Resample the recording to a regular grid or use one of those models.")
    for i, r in enumerate(recordings):
        d = frame_intervals(r)[:-1]
        if d.size and float(d.min()) <= 0.0:
            raise ValueError(f"recording {i}: time stamps must increase; the smallest interval "
                             f"is {float(d.min()):.3g} s")
        w = float(r.exposure) if model.blur else 0.0
        if d.size and float(d.min()) < w * (1.0 - 1e-9) and rounding_shortfall(r, w) is None:
            q = stamp_quantum(d)
            why = (f"; the time stamps are rounded to {q * 1e6:.4g} us, more than 1 % of the "
                   "exposure, too coarse to place the frames: write them with more digits"
                   if q is not None else "")
            raise ValueError(
                f"recording {i}: an interval between frames ({float(d.min()) * 1e3:.4g} ms) is "
                f"shorter than the exposure W = {w * 1e3:.4g} ms; exposures cannot overlap"
                + (why or " (check the exposure and the time stamps' unit)"))


#: rounded time stamps may place frames closer than the exposure by up to their resolution;
#: read as W when the resolution is at most this fraction of W
_ROUNDING_MAX = 0.01


def rounding_shortfall(rec, w: float) -> tuple[float, int] | None:
    """``(q, count)`` when ``rec``'s intervals shorter than the exposure ``w`` are explained
    by time stamps rounded to a resolution q <= 1 % of w (each short by at most q): ``count``
    of them, read as ``w`` by the likelihood. ``(0.0, 0)`` when none is short; None when an
    interval is shorter than rounding explains."""
    d = frame_intervals(rec)[:-1]
    short = d < w * (1.0 - 1e-9)
    if not short.any():
        return 0.0, 0
    q = stamp_quantum(d)
    if q is None or q > _ROUNDING_MAX * w or float(d.min()) < w - q * (1.0 + 1e-6):
        return None
    return q, int(short.sum())


def rounding_notes(model: TrapModel, recordings) -> list[str]:
    """A note per recording whose intervals shorter than the exposure were read as W."""
    notes = []
    for i, r in enumerate(recordings):
        got = rounding_shortfall(r, float(r.exposure) if model.blur else 0.0)
        if got is not None and got[1]:
            notes.append(f"recording {i}: time stamps rounded to {got[0] * 1e6:.4g} us: {got[1]} "
                         "interval(s) shorter than the exposure by at most that (exposures "
                         "cannot overlap) were read as the exposure")
    return notes


def make_irregular_args(recordings, layout, model, mean="reml") -> IrregularArgs:
    check_irregular_model(model, recordings)
    n_max = bucket_length(max(r.n_frames for r in recordings))  # masked beyond each record
    ys = np.zeros((len(recordings), n_max))
    dts = np.ones((len(recordings), n_max))
    mask = np.zeros((len(recordings), n_max))
    for i, r in enumerate(recordings):
        y = np.asarray(r.positions, dtype=float)
        ys[i, : r.n_frames] = y if mean == "zero" else y - y.mean()
        # rounded stamps (check_irregular_model): no interval shorter than the exposure
        dts[i, : r.n_frames] = np.maximum(frame_intervals(r),
                                           float(r.exposure) if model.blur else 0.0)
        dts[i, r.n_frames:] = float(r.frame_interval)
        mask[i, : r.n_frames] = 1.0
    return IrregularArgs(layout=layout, model=model, meta=rec_meta(recordings),
                         ys=jnp.asarray(ys), intervals=jnp.asarray(dts),
                         mask=jnp.asarray(mask), mean=mean)


def irregular_nll(p, a: IrregularArgs):
    """Exact negative log-likelihood at irregular frame times, summed over recordings."""
    sigma2, tau, w, e2 = frame_params(p, a.layout, a.model, a.meta)

    def one(y, d, m, s2, t, ww, ee):
        return irregular_loglik(y, d, ww, s2, t, ee, mean=a.mean, mask=m)

    return -jnp.sum(jax.vmap(one)(a.ys, a.intervals, a.mask, sigma2, tau, w, e2))
