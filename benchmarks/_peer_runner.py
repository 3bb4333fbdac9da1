"""Peer-tool runner for ``bench_peers.py`` (not a test; runs in the *peer* virtual environment).

Run by ``bench_peers.py`` with the interpreter named by ``BLURTRAP_PEER_PYTHON``; it imports
only numpy and the peers (lumicks.pylake, tweezepy, emcee), never blurtrap, so the project
environment stays untouched. Usage::

    python _peer_runner.py versions OUT.json
    python _peer_runner.py fit IN.npz OUT.json
    python _peer_runner.py mcmc IN.npz OUT.json WALKERS STEPS

``IN.npz`` holds ``x`` (shape (B, N), positions in metres), ``fs`` [Hz], ``exposure`` [s],
``temperature`` [K], ``radius`` [m], ``viscosity`` [Pa s], ``fit_range`` [Hz] (pylake) and
``block`` (pylake points per block). Every trace is converted to the units each peer expects:

- pylake (``lk.calibrate_force``): a 1-D "voltage" trace. We pass positions in **um**, so
  pylake's distance response ``Rd`` should come out 1 um/V and its fitted diffusion constant
  ``D`` [V^2/s] is D in um^2/s. ``bead_diameter`` [um], ``temperature`` [Celsius],
  ``viscosity`` [Pa s] = the simulation's. Its stiffness ``kappa = 2 pi gamma_0 f_c`` [pN/nm]
  uses the *theoretical* Stokes drag ``gamma_0`` (here exactly the simulated gamma); the fitted
  friction is ``gamma = kT / D``.
- tweezepy (``PSD(trace, fsample).mlefit``, ``AV(trace, fsample).mlefit``): positions in
  **nm**, ``kT`` in pN nm, guesses from ``viscosity`` [pN s/nm^2] and ``radius`` [nm]; returns
  ``g`` [pN s/nm], ``k`` [pN/nm], ``e`` [nm]. ``D = kT / g``.

All results are written back in SI (N/m, N s/m, m^2/s). A fit that raises, or (tweezepy)
whose Nelder-Mead search reports ``success = False``, is a failure (NaN) and is counted.
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

KB = 1.380649e-23


def versions():
    out = {"python": sys.version.split()[0], "numpy": np.__version__}
    from importlib.metadata import PackageNotFoundError, version

    for name in ("lumicks.pylake", "tweezepy", "emcee", "scipy", "autograd", "numba"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    for mod in ("lumicks.pylake", "tweezepy.smmcalibration", "emcee"):
        try:
            with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                __import__(mod)
            out[f"import:{mod}"] = "ok"
        except Exception as exc:  # noqa: BLE001 - reported, not hidden
            out[f"import:{mod}"] = f"{type(exc).__name__}: {exc}"
    return out


# ------------------------------------------------------------------------------------------
# one fit per peer method; each returns dict(k, k_err, gamma, gamma_err, D, D_err, ok, msg)
# ------------------------------------------------------------------------------------------
def _pylake_result(r, kt):
    d_um2 = float(r["D"].value)
    d_err = float(r["err_D"].value)
    d = d_um2 * 1e-12
    gamma = kt / d
    return dict(k=float(r["kappa"].value) * 1e-3, k_err=float(r["err_kappa"].value) * 1e-3,
                gamma=gamma, gamma_err=gamma * d_err / d_um2, D=d, D_err=d_err * 1e-12,
                fc=float(r["fc"].value), Rd=float(r["Rd"].value), ok=True, msg="")


def pylake_fit(x_um, meta, hydro):
    import lumicks.pylake as lk

    r = lk.calibrate_force(
        x_um, bead_diameter=2e6 * meta["radius"], temperature=meta["temperature"] - 273.15,
        viscosity=meta["viscosity"], sample_rate=meta["fs"], fast_sensor=True,
        hydrodynamically_correct=hydro, fit_range=tuple(meta["fit_range"]),
        num_points_per_block=int(meta["block"]))
    return _pylake_result(r, KB * meta["temperature"])


def pylake_blur_alias(x_um, meta):
    """pylake's *private* motion-blur and aliasing model wrappers (not reachable from the
    public ``calibrate_force``), fitted with the public ``fit_power_spectrum``."""
    import lumicks.pylake as lk

    model = lk.PassiveCalibrationModel(2e6 * meta["radius"], viscosity=meta["viscosity"],
                                       temperature=meta["temperature"] - 273.15,
                                       fast_sensor=True)
    model = model._motion_blur(meta["exposure"])._alias_model(meta["fs"], 10)
    ps = lk.calculate_power_spectrum(x_um, meta["fs"], fit_range=tuple(meta["fit_range"]),
                                     num_points_per_block=int(meta["block"]))
    return _pylake_result(lk.fit_power_spectrum(ps, model), KB * meta["temperature"])


def _tweezepy_result(obj, kt_pn):
    res = obj.results
    g, k = float(res["g"]), float(res["k"])
    g_err, k_err = float(res["g_error"]), float(res["k_error"])
    d_nm2 = kt_pn / g  # nm^2/s
    out = dict(k=k * 1e-3, k_err=k_err * 1e-3, gamma=g * 1e-3, gamma_err=g_err * 1e-3,
               D=d_nm2 * 1e-18, D_err=d_nm2 * g_err / g * 1e-18, ok=bool(obj.success), msg="")
    if "e" in res:
        out["eps"] = float(res["e"]) * 1e-9
    if not obj.success:
        out["msg"] = "Nelder-Mead did not converge (success=False)"
    return out


def _tweezepy_kwargs(meta):
    return dict(kT=KB * meta["temperature"] * 1e21, viscosity=meta["viscosity"] * 1e-6,
                radius=meta["radius"] * 1e9)


def tweezepy_psd(x_nm, meta, te):
    from tweezepy.smmcalibration import PSD

    p = PSD(x_nm, meta["fs"])
    p.mlefit(tracking_error=te, **_tweezepy_kwargs(meta))
    return _tweezepy_result(p, KB * meta["temperature"] * 1e21)


def tweezepy_av(x_nm, meta, te):
    from tweezepy.smmcalibration import AV

    a = AV(x_nm, meta["fs"])
    a.mlefit(tracking_error=te, **_tweezepy_kwargs(meta))
    return _tweezepy_result(a, KB * meta["temperature"] * 1e21)


METHODS = {
    "pylake Lorentzian": ("pylake", lambda x, m: pylake_fit(x * 1e6, m, False)),
    "pylake hydrodynamic": ("pylake", lambda x, m: pylake_fit(x * 1e6, m, True)),
    "pylake blur+alias (private API)": ("pylake", lambda x, m: pylake_blur_alias(x * 1e6, m)),
    "tweezepy PSD": ("tweezepy", lambda x, m: tweezepy_psd(x * 1e9, m, False)),
    "tweezepy PSD + tracking error": ("tweezepy", lambda x, m: tweezepy_psd(x * 1e9, m, True)),
    "tweezepy AV": ("tweezepy", lambda x, m: tweezepy_av(x * 1e9, m, False)),
    "tweezepy AV + tracking error": ("tweezepy", lambda x, m: tweezepy_av(x * 1e9, m, True)),
}
FIELDS = ("k", "k_err", "gamma", "gamma_err", "D", "D_err", "eps", "time", "cpu")


def load_meta(path):
    z = np.load(path)
    meta = {k: (z[k].tolist() if z[k].ndim else float(z[k])) for k in z.files if k != "x"}
    return np.asarray(z["x"], dtype=np.float64), meta


def fit(in_path, out_path):
    x, meta = load_meta(in_path)
    vers = versions()
    out = {"versions": vers, "methods": {}, "skipped": {}}
    for name, (peer, fn) in METHODS.items():
        mod = {"pylake": "lumicks.pylake", "tweezepy": "tweezepy.smmcalibration"}[peer]
        if vers.get(f"import:{mod}") != "ok":
            out["skipped"][name] = f"{mod} not importable: {vers.get(f'import:{mod}')}"
            continue
        if name.startswith("pylake blur") and not hasattr(
                __import__("lumicks.pylake", fromlist=["PassiveCalibrationModel"])
                .PassiveCalibrationModel, "_motion_blur"):
            out["skipped"][name] = "this pylake has no private _motion_blur model"
            continue
        rows = {f: [] for f in FIELDS}
        fails, msgs = 0, {}
        for i in range(x.shape[0]):
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    r = fn(x[i], meta)
            except Exception as exc:  # noqa: BLE001 - a peer failure is a result
                r = {"ok": False, "msg": f"{type(exc).__name__}: {str(exc)[:120]}"}
            el, cpu = time.perf_counter() - t0, time.process_time() - c0
            if not r.get("ok"):
                fails += 1
                msgs[r.get("msg", "")] = msgs.get(r.get("msg", ""), 0) + 1
                r = {}
            for f in FIELDS:
                rows[f].append(el if f == "time" else cpu if f == "cpu" else
                               r.get(f, float("nan")))
        out["methods"][name] = {"peer": peer, "fails": fails, "fail_messages": msgs, **rows}
    with open(out_path, "w") as fh:
        json.dump(out, fh)


def mcmc(in_path, out_path, walkers, steps):
    """Time tweezepy's emcee posterior (``.mcmc``) on trace 0 for PSD and AV (+ tracking
    error). tweezepy computes emcee's autocorrelation time after sampling and raises when the
    chain is shorter than 50 tau; the sampling itself is complete by then, so the time is
    still recorded (with the message)."""
    x, meta = load_meta(in_path)
    out = {"versions": versions(), "walkers": walkers, "steps": steps, "runs": {}}
    for name, cls in (("tweezepy PSD + tracking error", "PSD"),
                      ("tweezepy AV + tracking error", "AV")):
        from tweezepy import smmcalibration

        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            obj = getattr(smmcalibration, cls)(x[0] * 1e9, meta["fs"])
            obj.mlefit(tracking_error=True, **_tweezepy_kwargs(meta))
        np.random.seed(0)  # tweezepy draws the initial walkers from the global numpy RNG
        msg = ""
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(
                    io.StringIO()), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                obj.mcmc(walkers=walkers, steps=steps)
        except Exception as exc:  # noqa: BLE001
            msg = f"{type(exc).__name__}: {str(exc).splitlines()[0][:160]}"
        el, cpu = time.perf_counter() - t0, time.process_time() - c0
        rec = {"seconds": el, "cpu_seconds": cpu, "per_step_ms": 1e3 * el / steps,
               "message": msg}
        try:
            chain = obj.sampler.get_chain(discard=steps // 4, flat=True)
            q = np.percentile(chain, [15.87, 50, 84.13], axis=0)
            kt_pn = KB * meta["temperature"] * 1e21
            rec["k_median"] = float(q[1, 1]) * 1e-3
            rec["k_halfwidth"] = float(0.5 * (q[2, 1] - q[0, 1])) * 1e-3
            rec["gamma_median"] = float(q[1, 0]) * 1e-3
            rec["gamma_halfwidth"] = float(0.5 * (q[2, 0] - q[0, 0])) * 1e-3
            rec["D_median"] = kt_pn / float(q[1, 0]) * 1e-18
            rec["acceptance"] = float(np.mean(obj.sampler.acceptance_fraction))
        except Exception as exc:  # noqa: BLE001
            rec["chain_error"] = f"{type(exc).__name__}: {exc}"
        out["runs"][name] = rec
    with open(out_path, "w") as fh:
        json.dump(out, fh)


def main(argv):
    cmd = argv[0]
    try:
        if cmd == "versions":
            with open(argv[1], "w") as fh:
                json.dump(versions(), fh)
        elif cmd == "fit":
            fit(argv[1], argv[2])
        elif cmd == "mcmc":
            mcmc(argv[1], argv[2], int(argv[3]), int(argv[4]))
        else:
            raise SystemExit(f"unknown command {cmd!r}; expected versions, fit or mcmc")
    except SystemExit:
        raise
    except Exception:  # pragma: no cover - reported to the parent on stderr
        traceback.print_exc()
        raise SystemExit(2) from None


if __name__ == "__main__":
    main(sys.argv[1:])
