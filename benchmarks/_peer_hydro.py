"""pylake runner for ``study_hydro_known.py`` (peer virtual environment; numpy + pylake only).

``python _peer_hydro.py IN.npz OUT.json``: ``IN.npz`` holds ``v`` (B, N) in volts, ``fs``,
``temperature`` [K], ``radius`` [m], ``viscosity`` [Pa s], ``rho_sample``, ``rho_bead``
[kg/m^3], ``fit_range`` [Hz], ``block``. Each trace: ``lk.calibrate_force(...,
hydrodynamically_correct=True, fast_sensor=True)``; written back: k [N/m], k_err, Rd [m/V].
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import warnings

import numpy as np


def main(in_path, out_path):
    from importlib.metadata import version

    import lumicks.pylake as lk

    z = np.load(in_path)
    out = {"k": [], "k_err": [], "Rd": [], "version": version("lumicks.pylake")}
    for v in z["v"]:
        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = lk.calibrate_force(
                v, bead_diameter=2e6 * float(z["radius"]),
                temperature=float(z["temperature"]) - 273.15, sample_rate=float(z["fs"]),
                viscosity=float(z["viscosity"]), hydrodynamically_correct=True,
                rho_sample=float(z["rho_sample"]), rho_bead=float(z["rho_bead"]),
                fast_sensor=True, fit_range=tuple(z["fit_range"]),
                num_points_per_block=int(z["block"]))
        out["k"].append(float(r["kappa"].value) * 1e-3)
        out["k_err"].append(float(r["err_kappa"].value) * 1e-3)
        out["Rd"].append(float(r["Rd"].value) * 1e-6)
    with open(out_path, "w") as fh:
        json.dump(out, fh)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
