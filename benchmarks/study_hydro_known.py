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

Active case (``active`` first): the same bead and photodiode with a 200 nm stage drive at
F_DRIVE Hz moved to the nearest Fourier ordinate (stage recorded with 1 nm of white noise;
the peak's amplitude and phase from Tolic-Norrelykke et al. 2006 eq. D3, tests/_hydro_gen.py),
positions in volts (Rd = 100 nm/V), friction free: blurtrap ``hydrodynamics=False`` / ``True`` (Rd, gamma, k),
the ``True`` fit with its drive response put back to the Lorentzian (passive part corrected,
drive not: Rd x |H_Lorentz(f_c)|/|H_D3(f_c)|, gamma and k / that ratio squared, SEs of the
``True`` fit) and pylake ``active_calibration=True, hydrodynamically_correct=True`` (band
10 Hz - 0.4 fs, 100 points per block, the drive +-12.5 % excluded).

    nice python benchmarks/study_hydro_known.py active [N_SEEDS [TRACKING_STD_M [F_DRIVE [SEED0]]]]
    (defaults 50, 0.5e-9, 32 and 2000: seeds SEED0 ... SEED0 + N_SEEDS - 1)

Near a surface (``active_wall``): the same bead, trap, photodiode and drive (0.5 nm tracking
noise), the bead's centre H_OVER_R radii from the surface; traces from tests/_wall_gen.py
(numpy: TN 2006 eq. D2 with the near-wall friction of eq. D6 by spectral synthesis, the drive's
response of eq. D3 with the same friction). blurtrap in volts, friction free, with the distance
given (``distance_to_surface_m``), without it (bulk friction) and with ``hydrodynamics=False``;
truth for gamma: the zero-frequency friction of eq. D6, ``6 pi eta R/(1 - 9R/16h)``.

    nice python benchmarks/study_hydro_known.py active_wall [N_SEEDS [H_OVER_R [F_DRIVE [SEED0
        [TRACKING_STD_M]]]]] [--peer]
    (defaults 30, 1.6, 32, 3000 and 0.5e-9; the thermal traces do not depend on the noise)

``--peer`` adds pylake on the same traces in volts: ``active_calibration=True,
hydrodynamically_correct=True, distance_to_surface=h`` (the bulk active call above plus the
distance: eq. D6 in its passive spectrum and drive response), and the same call without the
distance (bulk eq. D4); Rd and k with its errors, gamma its ``local_drag_coefficient`` (the
zero-frequency friction at the wall, against the same truth; ``gamma_ex`` without the
distance), Rf = k Rd (no errors reported for gamma and Rf).

The radius's error (``radius``): one near-wall trace (seed SEED0, H_OVER_R, F_DRIVE as above)
calibrated with the bead radius drawn N_RADII times from N(R, (3 % R)^2) (no error given):
the SD of the results against the radius's part of each error that one fit with
``bead_radius_err_m = 3 % R`` propagates (blurtrap/inference/_radius_error.py).

    nice python benchmarks/study_hydro_known.py radius [N_RADII [H_OVER_R [F_DRIVE [SEED0]]]]
    (defaults 12, 1.6, 32 and 3000)
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
    """bias, SE/SD and coverage; the last two NaN where no errors were reported at all."""
    vals, errs = np.asarray(vals, float), np.asarray(errs, float)
    has_err = bool(np.isfinite(errs).any())
    ok = np.isfinite(vals) & (np.isfinite(errs) if has_err else True)
    v, e = vals[ok], errs[ok]
    return dict(n=int(ok.sum()), bias_pct=float(100 * (v.mean() / truth - 1)),
                bias_se_pct=float(100 * v.std(ddof=1) / truth / math.sqrt(v.size)),
                se_over_sd=float(e.mean() / v.std(ddof=1)) if has_err else math.nan,
                coverage=float(np.mean(np.abs(v - truth) < 1.96 * e)) if has_err
                else math.nan)


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


def _active_fits(traces, f_d):
    """blurtrap's rows of the active case (module docstring) on ``traces`` [(x_m, stage_m)]."""
    import blurtrap as bt
    from blurtrap.effects import make_effect
    from blurtrap.inference._active import fluid_response
    from blurtrap.inference._hydro_drive import drive_friction

    eff = make_effect("hydrodynamics", viscosity=ETA, fluid_density=RHO, bead_friction=GAMMA0)
    g, f_m = drive_friction(eff, R, T, f_d)
    names = ("displacement_sensitivity", "gamma", "k")
    rows = {hd: {n: ([], []) for n in names} for hd in (False, True, "lorentz")}
    for x, stage in traces:
        rec = bt.Recording(positions=x / RD, frame_interval=1 / FS, exposure=1 / FS,
                           temperature=T, stage=stage, position_unit="V", metadata=dict(
                               detector="photodiode", anti_aliasing=True, bead_radius_m=R,
                               viscosity_Pa_s=ETA, fluid_density_kg_per_m3=RHO,
                               drive={"frequency_Hz": f_d}))
        for hd in (False, True):
            r = bt.calibrate(rec, hydrodynamics=hd)
            err = np.sqrt(np.diag(r.covariance))
            val = dict(zip(r.param_names, zip(r.values, err)))
            for n in names:
                rows[hd][n][0].append(val[n][0])
                rows[hd][n][1].append(val[n][1])
        fc = val["k"][0] / (2 * math.pi * val["gamma"][0])
        lor = abs(fluid_response(f_d, fc)[0]) / abs(fluid_response(f_d, fc, g, f_m)[0])
        for n, p in zip(names, (lor, lor**-2, lor**-2)):
            rows["lorentz"][n][0].append(val[n][0] * p)
            rows["lorentz"][n][1].append(val[n][1])
    truth = {"displacement_sensitivity": RD, "gamma": GAMMA0, "k": K}
    label = {False: "hydrodynamics=False", True: "hydrodynamics=True",
             "lorentz": "hydrodynamics=True, drive response Lorentzian"}
    return {f"blurtrap {label[hd]}": {n.replace("displacement_sensitivity", "Rd"):
                                      _row(*rows[hd][n], truth[n]) for n in names}
            for hd in rows}


def main_active(n_seeds=50, eps=EPS, f_d=32.0, seed0=2000):
    from _hydro_gen import generate_hydro_driven

    # on a Fourier ordinate (a whole number of periods in the record): pylake's periodogram
    # has no window, and off an ordinate the peak's leakage spoils its fit at 300 Hz
    f_d = round(f_d * N / FS) * FS / N

    traces = [generate_hydro_driven(N, FS, K, R, seed0 + s, amplitude=200e-9, frequency=f_d,
                                    eta=ETA, rho_f=RHO, rho_b=RB, tracking_std=eps,
                                    stage_noise=1e-9) for s in range(n_seeds)]
    t0 = time.time()
    fits = _active_fits(traces, f_d)
    print(json.dumps(fits), f"{time.time() - t0:.0f} s", flush=True)
    peer = _run_peer_active(traces, f_d)
    fits[f"pylake {peer['version']} active, hydrodynamically_correct=True"] = {
        "Rd": _row(peer["Rd"], peer["Rd_err"], RD),
        "gamma": _row(peer["gamma"], np.full(n_seeds, np.nan), GAMMA0),
        "k": _row(peer["k"], peer["k_err"], K)}
    print(json.dumps(fits, indent=1))
    return fits


def _run_peer_active(traces, f_d, distance=None):
    """pylake's active hydrodynamically correct calibration of ``traces`` ((volts-scaled
    positions, stage) pairs) in the peer venv (``_peer_hydro_active.py``), with
    ``distance_to_surface`` when ``distance`` [m] is given; its JSON output."""
    extra = {} if distance is None else {"distance": distance}
    with tempfile.TemporaryDirectory() as tmp:
        inp, out = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.json")
        np.savez(inp, v=np.stack([x for x, _ in traces]) / RD,
                 stage=np.stack([st for _, st in traces]), f_drive=f_d, fs=FS, temperature=T,
                 radius=R, viscosity=ETA, rho_sample=RHO, rho_bead=RB,
                 fit_range=np.array([10.0, 0.4 * FS]), excluded=np.array([0.875, 1.125]) * f_d,
                 block=100, **extra)
        subprocess.run([PEER, os.path.join(HERE, "_peer_hydro_active.py"), inp, out],
                       check=True)
        with open(out) as fh:
            return json.load(fh)


_WALL_OUT = ("displacement_sensitivity", "gamma", "k", "force_sensitivity")


def _wall_recording(x, stage, f_d, distance, radius=R, radius_err=None):
    import blurtrap as bt

    meta = dict(detector="photodiode", anti_aliasing=True, bead_radius_m=radius,
                viscosity_Pa_s=ETA, fluid_density_kg_per_m3=RHO, drive={"frequency_Hz": f_d})
    if distance is not None:
        meta["distance_to_surface_m"] = distance
    if radius_err is not None:
        meta["bead_radius_err_m"] = radius_err
    return bt.Recording(positions=x / RD, frame_interval=1 / FS, exposure=1 / FS,
                        temperature=T, stage=stage, position_unit="V", metadata=meta)


def _wall_traces(n_seeds, h_over_r, f_d, seed0, eps=EPS):
    from _wall_gen import generate_wall_driven  # pyright: ignore[reportMissingImports]

    return [generate_wall_driven(N, FS, K, R, seed0 + s, amplitude=200e-9, frequency=f_d,
                                 distance=h_over_r * R, eta=ETA, rho_f=RHO, rho_b=RB,
                                 tracking_std=eps, stage_noise=1e-9) for s in range(n_seeds)]


def _peer_wall(traces, f_d, h, truth):
    """pylake's active hydrodynamically correct fit with ``distance_to_surface = h`` (or none
    when ``h`` is None) on ``traces`` (the rows of the ``--peer`` option of ``active_wall``)."""
    peer = _run_peer_active(traces, f_d, distance=h)
    none = np.full(len(traces), np.nan)
    label = (f"pylake {peer['version']} active, hydrodynamically_correct=True, "
             f"distance_to_surface {'not given (bulk)' if h is None else 'given'}")
    return {label: {"Rd": _row(peer["Rd"], peer["Rd_err"], truth["displacement_sensitivity"]),
                    "gamma": _row(peer["gamma_local"], none, truth["gamma"]),
                    "k": _row(peer["k"], peer["k_err"], truth["k"]),
                    "Rf": _row(peer["Rf"], none, truth["force_sensitivity"])}}


def main_active_wall(n_seeds=30, h_over_r=1.6, f_d=32.0, seed0=3000, eps=EPS, peer=False):
    from _wall_gen import zero_frequency_friction  # pyright: ignore[reportMissingImports]

    import blurtrap as bt

    f_d = round(f_d * N / FS) * FS / N
    h = h_over_r * R
    truth = dict(zip(_WALL_OUT, (RD, zero_frequency_friction(R, ETA, h), K, K * RD)))
    cases = {"distance given": (h, None), "distance not given (bulk)": (None, None),
             "hydrodynamics=False": (h, False)}
    rows = {c: {n: ([], []) for n in _WALL_OUT} for c in cases}
    t0 = time.time()
    traces = _wall_traces(n_seeds, h_over_r, f_d, seed0, eps)
    for x, stage in traces:
        for case, (dist, hd) in cases.items():
            r = bt.calibrate(_wall_recording(x, stage, f_d, dist), hydrodynamics=hd)
            err = np.sqrt(np.diag(r.covariance))
            for n in _WALL_OUT:
                i = r.param_names.index(n)
                rows[case][n][0].append(r.values[i])
                rows[case][n][1].append(err[i])
    fits = {f"blurtrap {c}": {n.replace("displacement_sensitivity", "Rd").replace(
        "force_sensitivity", "Rf"): _row(*rows[c][n], truth[n]) for n in _WALL_OUT}
        for c in cases}
    print(json.dumps(fits, indent=1), f"{time.time() - t0:.0f} s", flush=True)
    if peer:
        t0 = time.time()
        for dist in (h, None):
            fits.update(_peer_wall(traces, f_d, dist, truth))
        print(json.dumps(fits, indent=1), f"pylake {time.time() - t0:.0f} s", flush=True)
    return fits


def main_radius(n_radii=12, h_over_r=1.6, f_d=32.0, seed0=3000):
    import blurtrap as bt

    f_d = round(f_d * N / FS) * FS / N
    h = h_over_r * R
    (x, stage), = _wall_traces(1, h_over_r, f_d, seed0)
    s = 0.03 * R
    one = bt.calibrate(_wall_recording(x, stage, f_d, h, radius_err=s), hydrodynamics=True)
    names = list(one.param_names)
    cov = np.asarray(one.covariance)
    ir = names.index("hydro_radius")
    radii = R + s * np.random.default_rng(seed0).standard_normal(n_radii)
    vals = []
    t0 = time.time()
    for rad in radii:
        r = bt.calibrate(_wall_recording(x, stage, f_d, h, radius=float(rad)),
                         hydrodynamics=True)
        vals.append(np.asarray(r.values))
    vals = np.asarray(vals)
    out = {}
    for n in _WALL_OUT:
        i = names.index(n)
        part = abs(cov[i, ir]) / s  # |dy/dR| s: the radius's part of the error
        sd = float(np.std(vals[:, i], ddof=1))
        rel = 100 / one.values[i]
        out[n] = dict(propagated_pct=part * rel, mc_sd_pct=sd * rel,
                      mc_sd_se_pct=sd * rel / math.sqrt(2 * (n_radii - 1)),
                      slope_ratio=float(np.polyfit(radii, vals[:, i], 1)[0] * s**2 / cov[i, ir]))
    # linear in R: the MC SD is the propagated part times the draws' own SD / s
    out["radii_sd_over_s"] = float(np.std(radii, ddof=1) / s)
    print(json.dumps(out, indent=1), f"{time.time() - t0:.0f} s", flush=True)
    return out


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "active_wall":
        a = [v for v in sys.argv[2:] if v != "--peer"]
        main_active_wall(int(a[0]) if a else 30, float(a[1]) if len(a) > 1 else 1.6,
                         float(a[2]) if len(a) > 2 else 32.0, int(a[3]) if len(a) > 3 else 3000,
                         float(a[4]) if len(a) > 4 else EPS, peer="--peer" in sys.argv[2:])
    elif len(sys.argv) > 1 and sys.argv[1] == "radius":
        a = sys.argv[2:]
        main_radius(int(a[0]) if a else 12, float(a[1]) if len(a) > 1 else 1.6,
                    float(a[2]) if len(a) > 2 else 32.0, int(a[3]) if len(a) > 3 else 3000)
    elif len(sys.argv) > 1 and sys.argv[1] == "active":
        a = sys.argv[2:]
        main_active(int(a[0]) if a else 50, float(a[1]) if len(a) > 1 else EPS,
                    float(a[2]) if len(a) > 2 else 32.0, int(a[3]) if len(a) > 3 else 2000)
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 50,
             float(sys.argv[2]) if len(sys.argv) > 2 else EPS)
