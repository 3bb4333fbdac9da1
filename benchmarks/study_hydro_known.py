"""Monte Carlo: passive calibration of a known bead with and without its hydrodynamic friction.

A 78.125 kHz anti-aliased photodiode, 2^17 samples, R = 1.5 um polystyrene in water at 295 K,
k = 0.1 pN/nm (f_c ~ 590 Hz), tracking noise 0.5 nm (or as given); traces from the independent NumPy
generator of tests/_hydro_gen.py (BSF 2004 eq. 12 by spectral synthesis). Fits:
blurtrap ``friction="free"`` with ``hydrodynamics=False`` / ``True`` (k and gamma),
``friction="stokes"`` with ``False`` / ``True`` (k), and pylake ``hydrodynamically_correct=True``
on the same traces in volts (Rd = 100 nm/V; pylake's fit band 10 Hz - 0.4 fs, 100 points per
block). Reported: bias, mean SE / SD, coverage of +-1.96 SE.

    nice python benchmarks/study_hydro_known.py [N_SEEDS [TRACKING_STD_M]]
    (defaults 50 and 0.5e-9; 0 gives traces pylake's model, which has no white noise, covers)
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
PEER = "/work/peervenv/bin/python"

T, ETA, RHO, RB = 295.0, 0.957812e-3, 997.803, 1050.0
R, FS, K, N, EPS, RD = 1.5e-6, 78125.0, 1e-4, 2**17, 0.5e-9, 1e-7
GAMMA0 = 6 * math.pi * ETA * R


def _row(vals, errs, truth):
    vals, errs = np.asarray(vals), np.asarray(errs)
    ok = np.isfinite(vals) & np.isfinite(errs)
    v, e = vals[ok], errs[ok]
    return dict(n=int(ok.sum()), bias_pct=float(100 * (v.mean() / truth - 1)),
                bias_se_pct=float(100 * v.std(ddof=1) / truth / math.sqrt(v.size)),
                se_over_sd=float(e.mean() / v.std(ddof=1)),
                coverage=float(np.mean(np.abs(v - truth) < 1.96 * e)))


def main(n_seeds=50, eps=EPS):
    from _hydro_gen import generate_hydro

    import blurtrap as bt

    traces = [generate_hydro(N, FS, K, R, 1000 + s, eta=ETA, rho_f=RHO, rho_b=RB,
                             tracking_std=eps) for s in range(n_seeds)]
    fits = {}
    t0 = time.time()
    for fr in ("free", "stokes"):
        for hd in (False, True):
            ks, kse, gs, gse = [], [], [], []
            for x in traces:
                rec = bt.Recording(positions=x, frame_interval=1 / FS, exposure=1 / FS,
                                   temperature=T, metadata=dict(
                                       detector="photodiode", anti_aliasing=True,
                                       bead_radius_m=R, viscosity_Pa_s=ETA,
                                       fluid_density_kg_per_m3=RHO, friction=fr))
                r = bt.calibrate(rec, hydrodynamics=hd)
                err = np.sqrt(np.diag(r.covariance))
                ks.append(r.values[0])
                kse.append(err[0])
                gs.append(r.values[1])
                gse.append(err[1])
            key = f"blurtrap friction={fr} hydrodynamics={hd}"
            fits[key] = {"k": _row(ks, kse, K)}
            if fr == "free":
                fits[key]["gamma"] = _row(gs, gse, GAMMA0)
            print(key, fits[key], f"{time.time() - t0:.0f} s", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        inp, out = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.json")
        np.savez(inp, v=np.stack(traces) / RD, fs=FS, temperature=T, radius=R, viscosity=ETA,
                 rho_sample=RHO, rho_bead=RB, fit_range=np.array([10.0, 0.4 * FS]), block=100)
        subprocess.run([PEER, os.path.join(HERE, "_peer_hydro.py"), inp, out], check=True)
        with open(out) as fh:
            peer = json.load(fh)
    fits[f"pylake {peer['version']} hydrodynamically_correct=True"] = {
        "k": _row(peer["k"], peer["k_err"], K)}
    print(json.dumps(fits, indent=1))
    return fits


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 50,
         float(sys.argv[2]) if len(sys.argv) > 2 else EPS)
