"""The periodogram ordinates of the recordings as the spectral fits see them, their model
spectrum, and the binned goodness of fit of periodogram/model ratios."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from . import _chunked
from ._fit import chi2_sf
from ._problems import SpectralArgs, bucket_length, rec_meta, spectral_model_psd


def _np_periodogram(y, dt, n_blocks=1):
    """``(f [Hz], P [m^2/Hz], M)``: the average periodogram of ``n_blocks`` blocks of M
    frames (mean removed per block, ordinates j = 1 .. M//2, ``dt/M |FFT|^2``), on the host,
    batched over leading axes of ``y``. A numpy twin of :func:`._likelihood.block_periodogram`
    (tests hold them equal), kept because the JAX one compiles anew for every record length
    and block count (0.2-0.4 s jitted, ~1 s eager; benchmarks/bench_host_twins.py); the one
    host-side periodogram of the package (calibrate, calibrate_batch, the line finder and the
    drive response use it)."""
    y = np.asarray(y, dtype=float)
    n = y.shape[-1]
    m = n // n_blocks
    if m < 4:
        raise ValueError(
            f"n_blocks = {n_blocks} leaves {m} frames per block for a record of {n} "
            "frames; need at least 4 frames per block"
        )
    blocks = y[..., : m * n_blocks].reshape(*y.shape[:-1], n_blocks, m)
    blocks = blocks - blocks.mean(axis=-1, keepdims=True)
    spec = np.fft.rfft(blocks, axis=-1)[..., 1:]
    p = (spec.real**2 + spec.imag**2).mean(axis=-2) * dt / m
    f = np.arange(1, m // 2 + 1) / (m * dt)
    return f, p, m


def spectral_gof(ratio, weight, n_params, min_dof=64):
    """Binned test of periodogram/model ratios (each has mean 1, variance 1/n_blocks).

    ``ratio`` and ``weight`` have shape (R, M) (weight 0 on padding). Consecutive ordinates
    of each recording are pooled into bins worth >= ``min_dof`` exponential degrees of
    freedom, so each bin mean is close to normal with variance 1/(bin weight);
    ``T = sum_b W_b (mean_b - 1)^2 ~ chi^2(n_bins - n_params)``.
    """
    ratio, weight = np.asarray(ratio), np.asarray(weight)
    stat, nb = 0.0, 0
    for q, wt in zip(ratio, weight):
        keep = wt > 0
        q, wt = q[keep], wt[keep]
        if q.size == 0:
            continue
        per = max(1, int(math.ceil(min_dof / float(np.median(wt)))))
        nbin = len(q) // per
        if nbin == 0:
            continue
        qb = q[: nbin * per].reshape(nbin, per)
        wb = wt[: nbin * per].reshape(nbin, per)
        means = np.sum(qb * wb, axis=1) / np.sum(wb, axis=1)
        stat += float(np.sum(np.sum(wb, axis=1) * (means - 1.0) ** 2))
        nb += nbin
    dof = max(nb - n_params, 1)
    p = float(chi2_sf(stat, dof))
    return {"test": "binned spectral chi2", "statistic": stat, "dof": dof, "p_value": p}


def _spectral_args(recs, layout, model, n_blocks, f_range, excluded=None):
    """Periodogram ordinates of all recordings. Whenever the model has the closed form, its
    expectation is the exact expected periodogram of a block of M frames (the Fejer-kernel
    leakage of the finite block included, same cost as P_d): for blocked spectra and for the
    full-record Whittle likelihood alike, so that records that are not long compared with
    tau are not biased. Models with extra effects use P_d(f) (leakage O(tau/T); measured for a
    photodiode filter at 100 kHz: the expected periodogram exceeds P_d by ~1.5 % near Nyquist
    at 2^14 samples, 6 % at 2^12. Adding the closed-form trap's leakage fixed that but made
    the autodiff fits of these models ~2x slower to compile; not yet done)."""
    fs, ps, ws, ms = [], [], [], []
    for r in recs:
        nb = max(int(n_blocks), 1)
        f, p, m = _np_periodogram(r.positions, float(r.frame_interval), nb)
        ms.append(m)
        wt = np.full(f.shape, float(nb))
        if m % 2 == 0:
            wt[-1] *= 0.5  # Nyquist ordinate is chi^2_1
        if f_range is not None:
            sel = (f >= f_range[0]) & (f <= f_range[1])
            f, p, wt = f[sel], p[sel], wt[sel]
        for a, b in excluded or ():
            wt = np.where((f >= a) & (f <= b), 0.0, wt)  # excluded ordinates: no weight
        if excluded and f.size and np.count_nonzero(wt) < max(16, f.size // 20):
            raise ValueError(
                f"excluded ranges {[tuple(e) for e in excluded]} Hz leave "
                f"{np.count_nonzero(wt)} of the {f.size} ordinates "
                f"({f[0]:.4g}-{f[-1]:.4g} Hz) of a recording to fit: too few to fit the "
                "spectrum. Exclude only narrow bands (lines, resonances), in Hz")
        fs.append(f)
        ps.append(p)
        ws.append(wt)
    m_real = max(len(f) for f in fs)
    if m_real == 0:
        raise ValueError(f"f_range = {f_range} Hz leaves no frequencies to fit")
    m_max = bucket_length(m_real)  # weight 0 beyond m_real: one compiled fit per bucket
    ref = float(np.mean(np.concatenate(ps)))

    def pad(arrs, fill):
        return np.stack([np.concatenate([a, np.full(m_max - len(a), fill)]) for a in arrs])

    dts = np.array([float(r.frame_interval) for r in recs])
    f2 = pad([f for f in fs], 0.0)
    f2 = np.where(f2 == 0.0, 0.25 / dts[:, None], f2)  # harmless value on padding
    return SpectralArgs(
        layout=layout,
        model=model,
        meta=rec_meta(recs),
        f=jnp.asarray(f2),
        s2=jnp.asarray(np.sin(np.pi * f2 * dts[:, None]) ** 2),
        power=jnp.asarray(pad(ps, ref)),
        weight=jnp.asarray(pad(ws, 0.0)),
        log_ref=jnp.asarray(np.log(ref)),
        block_len=(jnp.asarray(np.array(ms, dtype=float))
                   if model.alias and model.closed_form else None),
        n_ordinates=jnp.asarray(np.array([len(f) for f in fs], dtype=np.int32)),
    )


def unpadded(args: SpectralArgs, z):
    """``z`` of shape (R, M) on the host without the bucket padding beyond the longest
    recording's ordinates (what results and reports show)."""
    z = np.asarray(z)
    if args.n_ordinates is None:
        return z
    return z[..., : int(np.max(np.asarray(args.n_ordinates)))]


_psd_kernel = eqx.filter_jit(spectral_model_psd)


def _psd_jit(p, args: SpectralArgs):
    """The model spectrum ``spectral_model_psd(p, args)``, shape (R, M), compiled; for the
    models the fit chunks evaluated in its ordinate chunks (:mod:`._chunked`), so that
    a new record length compiles nothing here either."""
    if _chunked.args_chunkable(args):
        return jnp.asarray(_chunked.model_psd_in_chunks(_psd_kernel, p, args))
    return _psd_kernel(p, args)

