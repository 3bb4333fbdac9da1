"""pylake runner for the active case of ``study_hydro_known.py`` (peer virtual environment;
numpy + pylake only).

``python _peer_hydro_active.py IN.npz OUT.json``: ``IN.npz`` holds ``v`` (B, N) in volts,
``stage`` (B, N) [m], ``f_drive`` [Hz], ``fs``, ``temperature`` [K], ``radius`` [m],
``viscosity`` [Pa s], ``rho_sample``, ``rho_bead`` [kg/m^3], ``fit_range`` [Hz],
``excluded`` [Hz, Hz] and ``block``. Each trace: ``lk.calibrate_force(...,
active_calibration=True, driving_data=stage [um], hydrodynamically_correct=True,
fast_sensor=True)``; written back: Rd [m/V], k [N/m], gamma_ex [N s/m] and the errors pylake
reports (Rd, k; none for gamma_ex).

Near a surface: an optional ``distance`` [m] in ``IN.npz`` (bead centre to surface) is passed
as ``distance_to_surface`` [um]; pylake's hydrodynamically correct model then uses the
near-wall friction of Tolic-Norrelykke et al. (2006) eq. D6 in the passive spectrum and the
drive's response. Written back in addition (with or without a distance): ``gamma_local``
[N s/m] (pylake's ``local_drag_coefficient``: ``gamma_ex`` times Re D6 at f = 0, i.e.
``gamma_ex/(1 - 9R/16h)``; ``gamma_ex`` itself is the bulk value) and ``Rf`` [N/V] (no errors
reported for either). Without ``distance`` the call is the bulk one above, unchanged.
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
    out = {key: [] for key in ("Rd", "Rd_err", "k", "k_err", "gamma", "gamma_local", "Rf")}
    extra = {}
    if "distance" in z.files:
        extra["distance_to_surface"] = 1e6 * float(z["distance"])
    out["version"] = version("lumicks.pylake")
    for v, stage in zip(z["v"], z["stage"]):
        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = lk.calibrate_force(
                v, bead_diameter=2e6 * float(z["radius"]),
                temperature=float(z["temperature"]) - 273.15, sample_rate=float(z["fs"]),
                viscosity=float(z["viscosity"]), active_calibration=True,
                driving_data=stage * 1e6, driving_frequency_guess=float(z["f_drive"]),
                hydrodynamically_correct=True, rho_sample=float(z["rho_sample"]),
                rho_bead=float(z["rho_bead"]), fast_sensor=True,
                fit_range=tuple(z["fit_range"]), num_points_per_block=int(z["block"]),
                excluded_ranges=[tuple(z["excluded"])], **extra)
        out["Rd"].append(float(r["Rd"].value) * 1e-6)
        out["Rd_err"].append(float(r["err_Rd"].value) * 1e-6)
        out["k"].append(float(r["kappa"].value) * 1e-3)
        out["k_err"].append(float(r["err_kappa"].value) * 1e-3)
        out["gamma"].append(float(r["gamma_ex"].value))
        out["gamma_local"].append(float(r["local_drag_coefficient"].value))
        out["Rf"].append(float(r["Rf"].value) * 1e-12)
    with open(out_path, "w") as fh:
        json.dump(out, fh)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
