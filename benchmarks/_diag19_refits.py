"""Issue 19's done-when additions to ``study_diagnose.py``: the naive start on one camera
recording, and the remedies of the effects that are not in the Gaussian likelihood.

- ``naive_camera``: one blurred camera recording (W = dt = 1/1500 s, k = 0.05 pN/nm, 1.5 um
  bead in water at 295 K, eps = 2 nm, 16 384 frames) diagnosed with ``model="naive"``. The
  refit is the coupled group's (``d.ranking[0].fit``); the row also keeps the naive base fit
  (is the error falling?) and where :func:`blurtrap.select_model` ends from ``naive``.
- ``anharmonicity`` -> :func:`blurtrap.calibrate_anharmonic` (k, gamma of the quartic trap).
- ``timing_jitter`` -> :func:`blurtrap.calibrate` on the recording with its irregular time
  stamps (the exact likelihood at the recorded frame times), see :func:`jitter_refit`.
- ``laser_heating``: the refit's per-power gamma and T (``fit.extras["per_recording"]``)
  and the heating coefficient b against their truths.

Every remedy returns a dict of plain numbers (pulls = (estimate - truth) / SE) that the
study stores per seed; ``truth_ok(remedy, n_se)`` applies the "within n SE" criterion.
"""

from __future__ import annotations

import math

import jax
import numpy as np

import blurtrap as bt

DT = 1 / 1500
N_CAM = 16384
K_CAM = 5e-5  # 0.05 pN/nm, issue 19 item 3
R_CAM = 1.5e-6
EPS_CAM = 2e-9
T0 = 295.0


def gamma_stokes(radius, temperature=T0):
    from blurtrap.physics import water_viscosity

    return 6 * math.pi * float(water_viscosity(temperature)) * radius


GAMMA_CAM = gamma_stokes(R_CAM)


def naive_camera(seed, eps=EPS_CAM, n=N_CAM):
    """One blurred, aliased camera recording (W = dt) with white tracking noise ``eps``."""
    x = np.asarray(bt.simulate(K_CAM, GAMMA_CAM, DT, DT, n, key=jax.random.key(seed),
                               method="exact_frames", tracking_std=eps))[0]
    return bt.Recording(x, frame_interval=DT, exposure=DT)


def _pulls(k, k_err, g, g_err, k_true, g_true) -> dict:
    return {"k_pull": float((k - k_true) / k_err), "gamma_pull": float((g - g_true) / g_err),
            "k_rel": float(k / k_true - 1), "gamma_rel": float(g / g_true - 1)}


def fit_pulls(fit, k_true, g_true) -> dict:
    """Pulls of a ``CalibrationResult`` (or ``AnharmonicResult``) against the truth."""
    return _pulls(fit.k, fit.k_err, fit.gamma, fit.gamma_err, k_true, g_true)


def naive_remedy(rec, d, threshold) -> dict:
    """The coupled group's refit against the naive base fit, and the end of forward
    selection from ``naive`` (one more diagnose per step)."""
    out = {"base": fit_pulls(d.fit, K_CAM, GAMMA_CAM)}
    top = d.ranking[0] if d.ranking else None
    if top is None or top.fit is None:
        return {**out, "error": "no refit of the first-ranked candidate"}
    out.update(fit_pulls(top.fit, K_CAM, GAMMA_CAM))
    out["gof_p"] = float(top.fit.gof["p_value"])
    out["gof_ok"] = bool(out["gof_p"] > threshold)
    b = out["base"]
    out["error_falls"] = bool(abs(out["k_rel"]) < abs(b["k_rel"])
                              and abs(out["gamma_rel"]) < abs(b["gamma_rel"]))
    sel = bt.select_model(rec, "naive")
    out["select_added"] = list(sel.added)
    out["select_adequate"] = bool(sel.adequate)
    out["select"] = fit_pulls(sel.fit, K_CAM, GAMMA_CAM)
    return out


def anharmonic_remedy(rec, k_true, g_true, threshold) -> dict:
    """``calibrate_anharmonic``: k (harmonic coefficient) and gamma; its J test as the gof."""
    a = bt.calibrate_anharmonic(rec)
    out = fit_pulls(a, k_true, g_true)
    out.update(gof_p=float(a.gof["p_value"]), gof_ok=bool(a.gof["p_value"] > threshold),
               converged=bool(a.converged), beta=float(a.beta), beta_err=float(a.beta_err))
    return out


def actual_times(rec) -> np.ndarray:
    """The frame start times the simulator used: ``TimingJitter`` clips a dead time that
    the jitter would make negative (the next exposure starts when the last ends), but
    ``return_times`` reports the unclipped ``n dt + delta_n``. The times actually simulated
    have intervals ``max(stamped interval, W)`` (blurtrap/simulate/_frame.py)."""
    t = np.asarray(rec.times, dtype=float)
    d = np.maximum(np.diff(t), float(rec.exposure))
    return np.concatenate([[t[0]], t[0] + np.cumsum(d)])


def jitter_remedy(rec, k_true, g_true, threshold) -> dict:
    """The exact likelihood at the recorded (irregular) frame times. The stamps as the
    simulator returns them are tried first (a refusal is recorded), then the times it
    actually simulated (:func:`actual_times`)."""
    out: dict = {"n_short": int(np.sum(np.diff(np.asarray(rec.times)) < float(rec.exposure)))}
    try:
        fit = bt.calibrate(rec, likelihood="exact")
        out["stamped"] = fit_pulls(fit, k_true, g_true)
    except ValueError as exc:
        out["stamped_error"] = str(exc)
    fixed = bt.Recording(rec.positions, frame_interval=float(rec.frame_interval),
                         exposure=float(rec.exposure), times=actual_times(rec),
                         allow_irregular=True)
    fit = bt.calibrate(fixed, likelihood="exact")
    out.update(fit_pulls(fit, k_true, g_true))
    out.update(gof_p=float(fit.gof["p_value"]), gof_ok=bool(fit.gof["p_value"] > threshold),
               notes=list(fit.notes))
    return out


def heating_remedy(fit, recs, b_true, c_true, g_true, threshold) -> dict:
    """Per-power T and gamma of the refit (``extras["per_recording"]``) and b, each as a
    pull against its truth (T = T0 + b P, gamma = gamma(T0) eta(T)/eta(T0))."""
    from blurtrap.physics import water_viscosity

    names = list(fit.param_names)
    ib = names.index("heating")
    out = {"b_pull": float((fit.values[ib] - b_true) / fit.errors[ib]),
           "gof_p": float(fit.gof["p_value"]), "gof_ok": bool(fit.gof["p_value"] > threshold)}
    if "c" in names:
        ic = names.index("c")
        out["c_pull"] = float((fit.values[ic] - c_true) / fit.errors[ic])
    per = {}
    for label, value, err, quantity in fit.extras.get("per_recording", ()):
        p = float(label.split("=")[1].split(" ")[0]) * 1e-3
        t = T0 + b_true * p
        truth = t if quantity == "temperature" else g_true * float(
            water_viscosity(t) / water_viscosity(T0))
        per[label] = float((value - truth) / err)
    out["per_recording_pulls"] = per
    out["n_per_recording"] = len(per)
    out["n_powers"] = len({float(r.laser_power) for r in recs})
    return out


def truth_ok(rem: dict | None, n_se: float) -> bool | None:
    """Whether a remedy's estimates lie within ``n_se`` standard errors of the truth."""
    if rem is None or "error" in rem:
        return None if rem is None else False
    if "b_pull" in rem:  # heating: b and every per-power T and gamma
        pulls = [rem["b_pull"], *rem["per_recording_pulls"].values()]
        complete = rem["n_per_recording"] == 2 * rem["n_powers"]
        return bool(complete and all(abs(p) < n_se for p in pulls))
    return bool(abs(rem["k_pull"]) < n_se and abs(rem["gamma_pull"]) < n_se)


def _ms(v) -> str:
    v = np.asarray([x for x in v if x is not None and np.isfinite(x)], dtype=float)
    if not v.size:
        return "-"
    sd = f", SD {v.std(ddof=1):.2f}" if v.size > 1 else ""
    return f"{v.mean():+.2f}{sd}"


def _n_within(v, n_se=2.0) -> str:
    v = [x for x in v if x is not None]
    return f"{sum(abs(x) < n_se for x in v)}/{len(v)}"


def remedy_lines(rows) -> list[str]:
    """Markdown: the refits' pulls per scenario (identified seeds with a remedy)."""
    lines = ["## Refit pulls (identified seeds; pull = (estimate - truth) / SE)\n",
             "| scenario | n | k (or P0) pull mean, SD | gamma pull mean, SD | k within 2 SE | "
             "gamma within 2 SE | other |", "|---|---|---|---|---|---|---|"]
    names = list(dict.fromkeys(r["scenario"] for r in rows))
    for name in names:
        rems = [r["remedy"] for r in rows if r["scenario"] == name and r.get("remedy")
                and "error" not in r["remedy"]]
        if not rems:
            continue
        kp = [m.get("k_pull") for m in rems]
        gp = [m.get("gamma_pull") for m in rems]
        other = []
        if "b_pull" in rems[0]:
            kp = [m.get("c_pull") for m in rems]
            gp = [max(abs(v) for k, v in m["per_recording_pulls"].items() if "gamma" in k)
                  for m in rems]
            other.append(f"b pull {_ms([m['b_pull'] for m in rems])}, within 2 SE "
                         f"{_n_within([m['b_pull'] for m in rems])}; gamma column: largest "
                         "|pull| of the per-power gammas; per-power T pulls equal b's")
        if "base" in rems[0]:
            falls = sum(m["error_falls"] for m in rems)
            sel = [m for m in rems if "select" in m]
            other.append(f"naive base fit k {_ms([100 * m['base']['k_rel'] for m in rems])} %, "
                         f"gamma {_ms([100 * m['base']['gamma_rel'] for m in rems])} %; "
                         f"refit k {_ms([100 * m['k_rel'] for m in rems])} %, gamma "
                         f"{_ms([100 * m['gamma_rel'] for m in rems])} %; |error| of k and "
                         f"gamma falls in {falls}/{len(rems)}")
            ends = {}
            for m in sel:
                key = "naive+" + "+".join(m["select_added"])
                ends[key] = ends.get(key, 0) + 1
            other.append("select_model from naive ends at " + ", ".join(
                f"{k} ({v})" for k, v in ends.items()) + f"; its k pull "
                f"{_ms([m['select']['k_pull'] for m in sel])}, gamma pull "
                f"{_ms([m['select']['gamma_pull'] for m in sel])}, k and gamma within 2 SE "
                f"{sum(truth_ok(m['select'], 2.0) for m in sel)}/{len(sel)}")
        if "n_short" in rems[0]:
            refused = sum("stamped_error" in m for m in rems)
            other.append(f"stamps as simulated: an interval < W in {refused}/{len(rems)} "
                         f"records (median {np.median([m['n_short'] for m in rems]):.0f} "
                         "intervals), refused by the exact likelihood; pulls use the times "
                         "actually simulated")
        if "beta" in rems[0]:
            other.append(f"beta {_ms([m['beta'] for m in rems])}")
        lines.append(f"| {name} | {len(rems)} | {_ms(kp)} | {_ms(gp)} | {_n_within(kp)} | "
                     f"{_n_within(gp)} | {'; '.join(other) or '-'} |")
    lines.append("")
    return lines
