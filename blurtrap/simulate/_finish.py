"""After the sampler: frame times, additive injections, stage drives, the sensitivity, and the
output's shape (or labelled axes) of :func:`blurtrap.simulate.simulate`."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._instruments import drive_frames
from ._labelled import label_frames


def frame_times(g, dj, n_frames, dtype, needed):
    """Frame start times [s]: (G, T, n) with timing jitter (`dj`: offsets in units of tau),
    else (G, 1, n) when `needed`, else None."""
    if dj is not None:
        n_idx = jnp.arange(n_frames, dtype=dtype)
        return (n_idx * jnp.asarray(g.dt, dtype)[:, None, None]
                + dj * jnp.asarray(g.tau, dtype)[:, None, None])
    if needed:
        return jnp.broadcast_to(jnp.asarray(np.arange(n_frames) * g.dt[:, None, None], dtype),
                                (g.G, 1, n_frames))
    return None


def add_injections(pos, times, k_inj, g, inj, wins, eps_any, n_traces, n_frames, dtype):
    """Tracking noise and the additive injections (each grid point with its own key), then
    the stage drives' exact blurred response and the sensitivity (`wins`: the
    ExposureWindows durations in the user's order, or None)."""
    G, n_win = g.G, g.n_win
    additive = inj.additive
    if additive or eps_any:
        epsj = jnp.asarray(g.eps, dtype)
        pos = pos.reshape(G, n_win, n_traces, n_frames)

        def inject(xg, tg, kg, eg):
            ks = jr.split(kg, len(additive) + 1)
            xg = xg + eg * jr.normal(ks[0], xg.shape, dtype)
            for i, a in enumerate(additive):
                xg = a.apply(xg, tg, ks[i + 1])
            return xg

        pos = jax.vmap(inject)(pos, times, k_inj, epsj)

    if inj.drives:  # exact steady-state response, blurred over each exposure (_instruments)
        widths = (np.broadcast_to(wins[None, :], (G, n_win)) if wins is not None
                  else g.w[:, None])
        pos = pos.reshape(G, n_win, n_traces, n_frames) + drive_frames(
            inj.drives, g.k, g.gamma, widths, g.dt, n_frames,
            times if inj.jitter is not None else None, inj.photodiode, dtype)
    if inj.sensitivity is not None:
        pos = pos / inj.sensitivity.rd.astype(dtype)
    return pos


def shape_output(pos, times, p, n_win, n_traces, n_frames, return_times, labelled):
    """Reshape to ``(*G, [n_windows,] T, n_frames)``; optional times or labelled axes."""
    windows = p.windows is not None
    out_shape = tuple(p.shape) + ((n_win,) if windows else ()) + (n_traces, n_frames)
    if pos.shape != out_shape:
        pos = pos.reshape(out_shape)
    if return_times:
        tshape = tuple(p.shape) + ((1,) if windows else ()) + (times.shape[-2], n_frames)
        times = times.reshape(tshape)
    if labelled:
        return label_frames(pos, {"k": p.k, "gamma": p.gamma, "exposure": p.exposure,
                                  "frame_interval": p.frame_interval,
                                  "temperature": p.temperature, "tracking_std": p.tracking_std},
                            p.shape, p.windows, times if return_times else None)
    return (pos, times) if return_times else pos
