"""pylake runner for ``study_instruments.py`` (not a test; runs in the *peer* virtual environment).

Imports only numpy and lumicks.pylake, never blurtrap. Usage::

    python _peer_instruments.py versions OUT.json
    python _peer_instruments.py passive IN.npz OUT.json
    python _peer_instruments.py active IN.npz OUT.json

``IN.npz`` holds ``v`` (shape (B, N), detector signal in **volts**), ``fs`` [Hz],
``temperature`` [K], ``radius`` [m], ``viscosity`` [Pa s], ``fit_range`` [Hz], ``block``
(pylake points per block) and, for ``active``, ``stage`` (shape (N,) or (B, N), stage
positions in **m**) and ``f_drive`` [Hz].

pylake's units (``lk.calibrate_force``): signal in V, ``bead_diameter`` [um], ``temperature``
[Celsius], ``viscosity`` [Pa s], ``sample_rate`` [Hz], ``driving_data`` [um] (stage),
``driving_frequency_guess`` [Hz]; results ``Rd`` [um/V], ``kappa`` [pN/nm], ``Rf`` [pN/V],
``err_Rd``, ``err_kappa``; active also ``gamma_ex`` [kg/s] (measured bulk drag; pylake reports
no error for it, nor for ``Rf``). ``fast_sensor=True``: a plain Lorentzian, no diode filter
(the simulated photodiode has none). Everything is written back in SI: Rd [m/V], k [N/m],
Rf [N/V], gamma [N s/m]. A fit that raises is a failure (NaN), counted with its message.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import time
import traceback
import warnings

import numpy as np


def versions():
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": sys.version.split()[0], "numpy": np.__version__}
    for name in ("lumicks.pylake", "scipy"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


def _val(r, key):
    try:
        return float(r[key].value)
    except (KeyError, AttributeError):
        return float("nan")


def fit_one(v, meta, stage=None):
    import lumicks.pylake as lk

    kw = dict(bead_diameter=2e6 * meta["radius"], temperature=meta["temperature"] - 273.15,
              viscosity=meta["viscosity"], sample_rate=meta["fs"], fast_sensor=True,
              fit_range=tuple(meta["fit_range"]), num_points_per_block=int(meta["block"]))
    if stage is None:
        r = lk.calibrate_force(v, active_calibration=False, **kw)
    else:
        r = lk.calibrate_force(v, active_calibration=True, driving_data=stage * 1e6,
                               driving_frequency_guess=meta["f_drive"], **kw)
    return dict(Rd=_val(r, "Rd") * 1e-6, Rd_err=_val(r, "err_Rd") * 1e-6,
                k=_val(r, "kappa") * 1e-3, k_err=_val(r, "err_kappa") * 1e-3,
                Rf=_val(r, "Rf") * 1e-12, gamma=_val(r, "gamma_ex"), fc=_val(r, "fc"),
                fc_err=_val(r, "err_fc"))


FIELDS = ("Rd", "Rd_err", "k", "k_err", "Rf", "gamma", "fc", "fc_err", "time")


def run(mode, in_path, out_path):
    z = np.load(in_path)
    meta = {k: (z[k].tolist() if z[k].ndim else float(z[k])) for k in z.files
            if k not in ("v", "stage")}
    v = np.asarray(z["v"], dtype=np.float64)
    stage = np.asarray(z["stage"], dtype=np.float64) if mode == "active" else None
    rows = {f: [] for f in FIELDS}
    fails, msgs = 0, {}
    for i in range(v.shape[0]):
        s = None if stage is None else (stage if stage.ndim == 1 else stage[i])
        t0 = time.perf_counter()
        try:
            with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = fit_one(v[i], meta, s)
        except Exception as exc:  # noqa: BLE001 - a peer failure is a result
            fails += 1
            m = f"{type(exc).__name__}: {str(exc)[:120]}"
            msgs[m] = msgs.get(m, 0) + 1
            r = {}
        el = time.perf_counter() - t0
        for f in FIELDS:
            rows[f].append(el if f == "time" else r.get(f, float("nan")))
    with open(out_path, "w") as fh:
        json.dump({"versions": versions(), "fails": fails, "fail_messages": msgs, **rows}, fh)


def main(argv):
    try:
        if argv[0] == "versions":
            with open(argv[1], "w") as fh:
                json.dump(versions(), fh)
        elif argv[0] in ("passive", "active"):
            run(argv[0], argv[1], argv[2])
        else:
            raise SystemExit(f"unknown command {argv[0]!r}; expected versions, passive, active")
    except SystemExit:
        raise
    except Exception:  # pragma: no cover - reported to the parent on stderr
        traceback.print_exc()
        raise SystemExit(2) from None


if __name__ == "__main__":
    main(sys.argv[1:])
