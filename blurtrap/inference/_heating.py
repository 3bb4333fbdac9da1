"""Laser heating, per recording: with the ``laser_heating`` effect (``T = T0 + b P``, gamma
following the water viscosity), a fit reports one gamma (at the room temperature T0 of the
recordings) and the heating coefficient b; this module turns them into the temperature and
the friction of each recording, with first-order (delta-method) errors from the fit's
covariance, so that the result shows what the bead felt at each power."""

from __future__ import annotations

import numpy as np

from .._config import x64_context
from ..physics import water_viscosity

#: relative step of the viscosity's temperature derivative (central difference)
_DT = 1e-3  # K


def _eta(t) -> np.ndarray:
    with x64_context(True):
        return np.asarray(water_viscosity(np.asarray(t, dtype=float)), dtype=float)


def heating_rows(recs, names, values, cov) -> tuple:
    """``((label, value, error, quantity), ...)`` for each recording: ``T[P=..]`` [K] and
    ``gamma[P=..]`` [N s/m]; empty without the heating parameter or laser powers."""
    if "heating" not in names or "gamma" not in names:
        return ()
    powers = [r.laser_power for r in recs]
    if any(p is None for p in powers):
        return ()
    ib, ig = names.index("heating"), names.index("gamma")
    b, g = float(values[ib]), float(values[ig])
    c = np.asarray(cov, dtype=float)[np.ix_([ig, ib], [ig, ib])]
    rows = []
    seen = set()
    for r, p in zip(recs, powers, strict=True):
        t0, p = float(r.temperature), float(p)
        if (t0, p) in seen:
            continue
        seen.add((t0, p))
        t = t0 + b * p
        ratio = float(_eta(t) / _eta(t0))
        deta = float((_eta(t + _DT) - _eta(t - _DT)) / (2 * _DT)) / float(_eta(t0))
        jt = np.array([0.0, p])  # d T / d (gamma, b)
        jg = np.array([ratio, g * deta * p])  # d gamma_i / d (gamma, b)
        lab = f"[P={p * 1e3:g} mW]"
        rows.append((f"T{lab}", t, float(np.sqrt(max(jt @ c @ jt, 0.0))), "temperature"))
        rows.append((f"gamma{lab}", g * ratio, float(np.sqrt(max(jg @ c @ jg, 0.0))), "gamma"))
    return tuple(rows)
