"""Exposure windows and the dimensionless grid of :func:`blurtrap.simulate.simulate`.

Everything runs in units of ``sigma = sqrt(kT/k)`` and ``tau = gamma/k``, computed here in
float64 on the host for the flattened parameter grid.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..physics import BOLTZMANN


class ExposureWindows:
    """Several exposure windows recorded from one trajectory in one run.

    All windows start at the frame start; window ``j`` averages over ``[0, durations[j]]``.
    Passing ``exposure=ExposureWindows([W1, W2, ...])`` to :func:`simulate` adds a windows axis
    (in the given order) just before the traces axis. This is how the variance-vs-exposure curve
    of Wong & Halvorsen (2006), Fig. 1a, is obtained from a single simulation.

    - `durations`: 1-D sequence of distinct exposure times [s], each > 0.
    """

    def __init__(self, durations: Sequence[float]):
        d = np.asarray(durations, dtype=np.float64)
        if d.ndim != 1 or d.size < 1:
            raise ValueError(
                f"ExposureWindows needs a non-empty 1-D sequence of durations; got shape {d.shape}"
            )
        if not (np.all(np.isfinite(d)) and np.all(d > 0)):
            raise ValueError(f"exposure window durations must be finite and > 0 s; got {d!r} s")
        if np.unique(d).size != d.size:
            raise ValueError(f"exposure window durations must be distinct; got {d!r} s")
        self.durations = d

    def __repr__(self):
        return f"ExposureWindows({self.durations.tolist()!r})"


class Grid(NamedTuple):
    """The flattened parameter grid (``G`` points) in units of sigma and tau."""

    G: int
    k: np.ndarray  # (G,) [N/m]
    gamma: np.ndarray  # (G,) [N s/m]
    dt: np.ndarray  # (G,) frame interval [s]
    temperature: np.ndarray  # (G,) [K]
    eps: np.ndarray  # (G,) tracking std [m]
    w: np.ndarray | None  # (G,) exposure [s] (one window), else None
    sigma: np.ndarray  # (G,) [m]
    tau: np.ndarray  # (G,) [s]
    order: np.ndarray  # windows sorted by length: user index of each
    ends: np.ndarray | None  # sorted window durations [s] (ExposureWindows), else None
    seg_len_s: np.ndarray | None  # lengths of the segments between window ends [s]
    L: np.ndarray  # (G, n_seg) segment lengths / tau
    n_seg: int
    n_win: int
    a_win: np.ndarray  # (G, n_win) sorted window lengths / tau
    rdead: np.ndarray  # (G,) dead time after the longest window / tau (>= 0)


def make_grid(p) -> Grid:
    """The :class:`Grid` of checked parameters `p` (``_validate.Params``)."""
    shape = p.shape
    G = int(np.prod(shape, dtype=np.int64))
    flat = lambda a: np.broadcast_to(a, shape).reshape(G).astype(np.float64)  # noqa: E731
    kf, gf, dtf, tf, epsf = (flat(a) for a in (p.k, p.gamma, p.frame_interval,
                                               p.temperature, p.tracking_std))
    sigma = np.sqrt(BOLTZMANN * tf / kf)
    tau = gf / kf
    if p.windows is not None:
        wins = p.windows
        order = np.argsort(wins)
        ends = wins[order]
        seg_len_s = np.diff(np.concatenate([[0.0], ends]))  # [s], (m,)
        L = seg_len_s[None, :] / tau[:, None]  # (G, m)
        n_seg = n_win = wins.size
        a_win = ends[None, :] / tau[:, None]  # sorted windows, dimensionless
        w_max = np.full(G, ends[-1])
        wf = None
    else:
        order = np.zeros(1, dtype=np.int64)
        ends = seg_len_s = None
        wf = flat(p.exposure)
        L = (wf / tau)[:, None]
        n_seg = n_win = 1
        a_win = L.copy()
        w_max = wf
    rdead = (dtf - w_max) / tau
    rdead = np.maximum(rdead, 0.0)
    return Grid(G, kf, gf, dtf, tf, epsf, wf, sigma, tau, order, ends, seg_len_s, L, n_seg,
                n_win, a_win, rdead)
