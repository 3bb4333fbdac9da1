"""One frame of the scan (dimensionless: positions in sigma, times in tau).

:func:`frame_step` runs the substeps of ``method="exact"`` / ``"euler"`` (exposure average
accumulated with trapezoid weights) or draws the exposure segments of ``"exact_frames"`` from
their exact law; :func:`innovation_pair` runs two frames of the innovations form. The
coefficients `P` come in a :class:`~blurtrap.simulate._scan_coefs.ScanCoefs`.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jax.sharding import NamedSharding, PartitionSpec

from ._rng import jitter_normals, pair_normals


def constrain(cfg, x, spec):
    if cfg.mesh is None:
        return x
    return lax.with_sharding_constraint(x, NamedSharding(cfg.mesh, PartitionSpec(*spec)))


def unpack(rt):
    """``(r, t)`` from the draws (float32 pairs come packed as ``r + i t``)."""
    if len(rt) == 1:
        return jnp.real(rt[0]), jnp.imag(rt[0])
    return rt


def _drift(cfg, x, P, force_params):
    if cfg.force is None:
        return -x
    sig = P.scale[:, None]
    f_si = cfg.force(x * sig, force_params)
    return (f_si / (P.k[:, None] * sig)).astype(x.dtype)


def _pair_rows(a, r0, r1, j0, n_pairs, fill):
    """Per-row coefficients ``a`` (G, r1 - r0, ...) laid out as (pairs, 2, G, ...), rows
    ``2 j0 ...``, with `fill` outside ``[r0, r1)``."""
    lo = r0 - 2 * j0
    pad = [(0, 0)] * a.ndim
    pad[1] = (lo, 2 * n_pairs - lo - a.shape[1])
    a = jnp.pad(a, pad, constant_values=fill)
    a = a.reshape((a.shape[0], n_pairs, 2) + a.shape[2:])
    return jnp.moveaxis(a, 0, 2)


def _scan_substeps(cfg, r, t, r0, r1, x, acc, coefs, fills, step):
    """Run `step` over rows ``[r0, r1)`` of the frame's normals, one Box-Muller pair (two rows)
    per iteration. `coefs`: per-row coefficients (G, r1 - r0, ...), padded with `fills`."""
    j0, j1 = r0 // 2, -(-r1 // 2)
    cs = tuple(_pair_rows(c, r0, r1, j0, j1 - j0, f) for c, f in zip(coefs, fills))
    dtype = x.dtype

    def body(carry, inp):
        xx, ac = carry
        rj, tj, cc = inp
        zs = pair_normals(rj, tj)
        for i in range(2):
            xx, ac = step(xx, ac, zs[i].astype(dtype), *(c[i] for c in cc))
        return (xx, ac), None

    (x, acc), _ = lax.scan(body, (x, acc), (r[j0:j1], t[j0:j1], cs), unroll=cfg.unroll)
    return x, acc


def frame_step(cfg, P, force_params, keys_j, rt, x, delta, frame):
    """Frame `frame` from the start state `x` with its Box-Muller pairs ``rt = (r, t)``."""
    dtype = jnp.dtype(cfg.dtype)
    n_t = x.shape[-1]
    r, t = unpack(rt)

    def row(i):
        z = pair_normals(r[i // 2], t[i // 2])[i % 2]
        return z.astype(dtype)

    # dead time up to the next frame start (absorbs the timing jitter)
    rdead = P.rdead[:, None]
    if cfg.jitter:
        d_next = P.jstd[:, None] * jitter_normals(keys_j, frame + 1, n_t, dtype)
        d = jnp.maximum(rdead + d_next - delta, 0.0)
        # a frame cannot start before the previous exposure ends: where the dead time was
        # clipped at 0 the next frame starts late, and its time stamp (the carried offset)
        # says so (equal to d_next wherever nothing was clipped)
        d_next = delta - rdead + d
    else:
        d_next = delta
        d = rdead

    if cfg.method == "exact_frames":
        acc = jnp.zeros((x.shape[0], cfg.n_win, n_t), dtype)
        last = cfg.n_seg - 1
        for s in range(cfg.n_seg):
            z1, z2 = row(2 * s), row(2 * s + 1)
            m = P.p[:, s, None] * x + P.sm[:, s, None] * z1
            acc = acc + P.M[:, s, :, None] * m[:, None, :]
            # increments (e - 1 = em1): see _coeffs, "Decay by increments"
            em1, cx, sx = P.em1[:, s, None], P.cx[:, s, None], P.sx[:, s, None]
            if s < last:
                x = x + (em1 * x + cx * z1 + sx * z2)
            else:
                # end of exposure then the dead step, in one draw: with e_d = exp(-d),
                # x' = e_d (e x + cx z1 + sx z2) + sqrt(1 - e_d^2) z3
                #    = e_d e x + e_d cx z1 + sqrt(e_d^2 sx^2 + 1 - e_d^2) z2'
                # and e_d e - 1 = e_d em1 + expm1(-d)
                ed = jnp.exp(-d)
                sd = jnp.sqrt(ed * ed * sx * sx - jnp.expm1(-2.0 * d))
                x = x + ((ed * em1 + jnp.expm1(-d)) * x + ed * cx * z1 + sd * z2)
    else:
        acc = P.Wt[:, 0, :, None] * x[:, None, :]
        n_exp = cfg.n_exp
        coefs = (P.A[..., None], P.B[..., None], P.Wt[:, 1:, :, None])
        if cfg.method == "exact":

            def sub(xx, ac, zi, a, b, w):  # a = exp(-h) - 1: by increments
                xx = xx + (a * xx + b * zi)
                return xx, ac + w * xx[:, None, :]

            fills = (0.0, 0.0, 0.0)
        else:

            def sub(xx, ac, zi, a, b, w):
                xx = xx + a * _drift(cfg, xx, P, force_params) + b * zi
                return xx, ac + w * xx[:, None, :]

            fills = (0.0, 0.0, 0.0)
        x, acc = _scan_substeps(cfg, r, t, 0, n_exp, x, acc, coefs, fills, sub)
        if cfg.method == "euler":
            nd = cfg.n_dead
            dsub = jnp.broadcast_to(d, x.shape) / nd  # (G, T): per-trajectory with jitter
            ones = jnp.ones((x.shape[0], nd, 1), dtype)

            def dead(xx, ac, zi, m):
                h = m * dsub
                return xx + h * _drift(cfg, xx, P, force_params) + jnp.sqrt(2.0 * h) * zi, ac

            x, _ = _scan_substeps(cfg, r, t, n_exp, n_exp + nd, x, jnp.zeros((), dtype),
                                  (ones,), (0.0,), dead)
        else:
            x = x + (jnp.expm1(-d) * x + jnp.sqrt(-jnp.expm1(-2.0 * d)) * row(n_exp))
    x = constrain(cfg, x, (None, "traces"))
    out = (acc, delta) if cfg.jitter else (acc, None)
    return x, d_next, out


def innovation_pair(cfg, P, rt, xh):
    """Frames ``2j, 2j + 1`` of the innovations form from the predictor `xh` (units of sigma)
    and one Box-Muller pair: returns the next predictor and the frames (2, G, 1, T)."""
    dtype = jnp.dtype(cfg.dtype)
    cm1, cb, s = (c[:, None] for c in (P.icm1, P.icb, P.istd))
    out = []
    r, t = unpack(rt)
    for z in pair_normals(r[0], t[0]):
        e = s * z.astype(dtype)
        out.append(xh + e)
        xh = xh + (cm1 * xh + cb * e)  # c - 1 = cm1: by increments
    xh = constrain(cfg, xh, (None, "traces"))
    return xh, jnp.stack(out)[:, :, None, :]
