r"""Goodness of fit of frames at irregular times, from the Kalman innovations.

The periodogram of frames taken at irregular times (dropped frames, a wandering clock) is not
the model's spectrum: computed as if the frames were regular it misfits correct data (10 %
dropped frames: p ~ 1e-5..1e-8 with the exact fit within 1 SE of the truth). The exact
likelihood at the recorded times (:mod:`._irregular`) factorises into innovations instead:
under the fitted model the standardised innovations ``r_i = (e_i - mu e1_i) / sqrt(v_i)``
(``mu`` the GLS trap centre) are independent N(0, 1), whatever the frame times. Their
periodogram has mean 1 and Exp(1) ordinates, so the binned chi^2 of
:func:`._spectral.spectral_gof` applies unchanged; a model that misses an effect leaves the
innovations correlated, and their spectrum departs from 1 where the model misfits.

The filter runs over fixed-size frame chunks carrying its state, as the fit does
(:mod:`._exact_chunks`), so a new record length compiles nothing.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._irregular import IrregularArgs, _filter, _frame_terms, frame_params
from ._spectral import spectral_gof

#: frames per compiled chunk of the filter
_CHUNK = 16384


@jax.jit
def _chunk(sigma2, tau, w, e2, state_m, state_p, y, mask, d):
    """One chunk of the filter from state ``(state_m, state_p)``: (end state, innovations
    (C, 2) of the frames and of the mean's regressor, their variances [m^2] (C,))."""
    a, q, c, b, r = _frame_terms(d, w, tau)
    series = jnp.stack([y, jnp.ones_like(y)], axis=-1)
    (m_end, p_end), (e, f) = _filter(series, b, r, mask, a, q, c, e2 / sigma2,
                                     (state_m, state_p))
    return m_end, p_end, e, f * sigma2


def standardised_innovations(p, args: IrregularArgs) -> list[np.ndarray]:
    """Per recording, its frames' standardised innovations at parameters ``p`` (length the
    record's number of frames): independent N(0, 1) under the model."""
    sigma2, tau, w, e2 = (np.asarray(v, dtype=float) for v in
                          frame_params(jnp.asarray(p), args.layout, args.model, args.meta))
    ys, ds, ms = (np.asarray(v, dtype=float) for v in (args.ys, args.intervals, args.mask))
    out = []
    for i in range(ys.shape[0]):
        n = int(round(float(ms[i].sum())))
        state_m, state_p = np.zeros(2), np.asarray(1.0)
        es, vs = [], []
        for s in range(0, n, _CHUNK):
            y, d, m = (np.zeros(_CHUNK), np.ones(_CHUNK) * ds[i, 0], np.zeros(_CHUNK))
            take = min(_CHUNK, n - s)
            y[:take], d[:take], m[:take] = ys[i, s:s + take], ds[i, s:s + take], 1.0
            state_m, state_p, e, v = _chunk(sigma2[i], tau[i], w[i], e2[i], state_m, state_p,
                                            y, m, d)
            es.append(np.asarray(e)[:take])
            vs.append(np.asarray(v)[:take])
        e, v = np.concatenate(es), np.concatenate(vs)
        mu = 0.0 if args.mean == "zero" else float(np.sum(e[:, 1] * e[:, 0] / v)
                                                  / np.sum(e[:, 1] ** 2 / v))
        out.append((e[:, 0] - mu * e[:, 1]) / np.sqrt(v))
    return out


def innovation_gof(p, args: IrregularArgs, n_params: int, mean_intervals):
    """``(gof, extras)`` of a fit at irregular times: the binned chi^2 of the standardised
    innovations' periodogram against 1 (module doc), and its ordinates as the fit's data/model
    ratio (``f`` [Hz] at the recording's mean frame interval ``mean_intervals[i]``, ``ratio``,
    ``weight``; shape (R, M), weight 0 on padding)."""
    res = standardised_innovations(p, args)
    m_max = max(len(r) // 2 for r in res)
    f, ratio, weight = (np.zeros((len(res), m_max)) for _ in range(3))
    for i, r in enumerate(res):
        n = len(r)
        spec = np.fft.rfft(r - r.mean())[1:]
        m = n // 2
        f[i, :m] = np.arange(1, m + 1) / (n * float(mean_intervals[i]))
        ratio[i, :m] = (spec.real**2 + spec.imag**2)[:m] / n
        weight[i, :m] = 1.0
        if n % 2 == 0:
            weight[i, m - 1] = 0.5  # Nyquist ordinate is chi^2_1
    gof = spectral_gof(ratio, weight, n_params)
    gof["test"] = "binned chi2 of the standardised innovations' spectrum (irregular times)"
    return gof, {"f": f, "ratio": ratio, "weight": weight}
