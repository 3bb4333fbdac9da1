"""Validate ``bt.design`` by simulation: the predicted (Whittle Cramer-Rao) relative SE of k and
gamma against the measured SD of log k and log gamma over simulated experiments.

Run:  python benchmarks/study_design.py designs --out DIR  # bt.design calls -> designs.json
      python benchmarks/study_design.py simulate --n 200 [--n-series 60] [--only a,b]
                                                 [--seed-base S] [--designs FILE] [--out DIR]
      python benchmarks/study_design.py report --inputs DIR1,DIR2,...  # markdown tables

Designs (1.53 um radius bead in water at 295 K, as in tests/design; eps = tracking-error rms):

- ``a``      camera 1500 fps, W = dt, 65 536 frames, eps 2 nm, k 0.05 pN/nm (one recording);
- ``b``      the same camera with W = 0.1 dt;
- ``c``      photodiode-like 100 kHz, W = dt, eps 0.5 nm, 2^17 frames, k 0.1 pN/nm;
- ``d``      camera 500 fps, k 0.5 pN/nm (dt >> tau), eps 2 nm, the exposure series recommended
             by bt.design for the same total time as 65 536 frames (joint fit,
             ``bt.calibrate(recordings, k="shared")``);
- ``a_rec``, ``a_paper``  case a's camera and total time: the series bt.design recommends and
             the paper's series (W = 0.15, 0.3, 0.6, 1 dt), both fitted by bt.calibrate;
- ``e_rec``, ``e_paper``  photon-limited noise (eps^2 = (2 nm)^2 dt / W): bt.design's
             recommendation and the paper's series. bt.calibrate fits one eps^2 shared by all
             recordings, not eps^2 proportional to 1/W, so these are fitted by a joint Whittle
             likelihood written here with that noise model (the model of the prediction).
             ``W = dt`` with photon-limited noise is design ``a`` (2 nm at W = dt).
- ``d_w``, ``a_rec_w``, ``a_paper_w``  designs d, a_rec, a_paper fitted by that joint Whittle
             fit with one shared eps^2 (the model of bt.calibrate; vmapped, so cheap).

Single recordings are fitted with ``bt.calibrate_batch`` (vmapped Whittle). Each experiment
uses its own key (``jax.random.key(seed)``, seed = seed_base + 1000 * SEED_INDEX[design] + chunk,
split over the recordings of a series). Results go to
``design_study.json`` in --out; a markdown table to stdout.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import pathlib
import platform
import sys
import time

import jax
import numpy as np
from _machine import cpu_model

import blurtrap as bt

bt.enable_x64()

from blurtrap.design import bounded_covariance, whittle_information  # noqa: E402
from blurtrap.physics import BOLTZMANN  # noqa: E402
from blurtrap.physics._effects import water_viscosity  # noqa: E402

T = 295.0
GAMMA = 6 * math.pi * float(water_viscosity(T)) * 1.53e-6
DT_CAM = 1 / 1500
N_CAM = 65536
PAPER = (0.15, 0.3, 0.6, 1.0)
HERE = pathlib.Path(__file__).resolve().parent


def run_designs(out: pathlib.Path) -> dict:
    """The three bt.design calls (fixed noise, photon-limited, dt >> tau)."""
    calls = {
        "a": dict(k=5e-5, gamma=GAMMA, max_fps=1500, total_time=N_CAM * DT_CAM,
                  tracking_std=2e-9, target="k"),
        "e": dict(k=5e-5, gamma=GAMMA, max_fps=1500, total_time=N_CAM * DT_CAM,
                  tracking_std=2e-9, photon_limited=True, target="k"),
        "d": dict(k=5e-4, gamma=GAMMA, max_fps=500, total_time=N_CAM / 500,
                  tracking_std=2e-9, target="k"),
    }
    res = {}
    for name, kw in calls.items():
        t0 = time.perf_counter()
        r = bt.design(**kw)
        print(r.summary(), f"\n({time.perf_counter() - t0:.0f} s)\n", flush=True)
        res[name] = {"call": kw, "result": r.to_dict()}
    (out / "designs.json").write_text(json.dumps(res, indent=1))
    return res


def best_finite(d: dict) -> dict:
    """bt.design's recommendation; the best candidate with a finite objective (a NaN
    objective, i.e. a singular information matrix, must not count as the best)."""
    cands = [d["best"]] + d["candidates"]
    ok = [c for c in cands if np.isfinite(c["objective"])]
    return min(ok, key=lambda c: c["objective"])


def recs_of(cand: dict) -> list:
    return [(r["frame_interval_s"], r["exposure_s"], int(round(r["n_frames"])))
            for r in cand["recordings"]]


def scenarios(designs: dict) -> dict:
    """name -> (k, [(dt, W, N, eps)], fitter)."""
    def series(dt, ws, n_total, eps_at, photon):
        n = n_total // len(ws)
        return [(dt, w, n, eps_at * (math.sqrt(dt / w) if photon else 1.0)) for w in ws]

    out = {
        "a": (5e-5, [(DT_CAM, DT_CAM, N_CAM, 2e-9)], "batch"),
        "b": (5e-5, [(DT_CAM, 0.1 * DT_CAM, N_CAM, 2e-9)], "batch"),
        "c": (1e-4, [(1e-5, 1e-5, 2 ** 17, 0.5e-9)], "batch"),
        "a_paper": (5e-5, series(DT_CAM, [f * DT_CAM for f in PAPER], N_CAM, 2e-9, False),
                    "calibrate"),
        "e_paper": (5e-5, series(DT_CAM, [f * DT_CAM for f in PAPER], N_CAM, 2e-9, True),
                    "photon"),
    }
    if designs:
        a_rec = recs_of(best_finite(designs["a"]["result"]))
        e_rec = recs_of(best_finite(designs["e"]["result"]))
        d_rec = recs_of(best_finite(designs["d"]["result"]))
        out["d"] = (5e-4, [(dt, w, n, 2e-9) for dt, w, n in d_rec], "calibrate")
        out["a_rec"] = (5e-5, [(dt, w, n, 2e-9) for dt, w, n in a_rec], "calibrate")
        # the same series fitted by the joint Whittle fit written here (one shared eps^2, the
        # model bt.calibrate fits): vmapped, so 200 experiments are cheap
        for name in ("d", "a_rec", "a_paper"):
            out[name + "_w"] = (*out[name][:2], "photon")
        out["e_rec"] = (5e-5, [(dt, w, n, 2e-9 * math.sqrt(dt / w)) for dt, w, n in e_rec],
                        "photon")
    # b without tracking noise, fitted without an eps^2 parameter (model "blur"): is the gap of
    # b the poorly identified eps^2 (predicted SE of log eps^2 = 76 % in b)? (last, so that
    # the seeds of the designs above do not depend on it)
    out["b0"] = (5e-5, [(DT_CAM, 0.1 * DT_CAM, N_CAM, 0.0)], "batch")
    return out


def predicted(k, recs, bounded=True) -> np.ndarray:
    """Relative SE of (k, gamma, eps^2) from the Whittle information summed over the
    recordings (one shared eps^2 parameter; eps_i^2 / eps_ref^2 fixed); ``bounded``: the
    scatter with eps^2 >= 0 (bt.design's prediction), else the Cramer-Rao bound."""
    info = sum(np.asarray(whittle_information(k, GAMMA, w, dt, n, T, eps ** 2))
               for dt, w, n, eps in recs)
    cov = np.linalg.inv(info)
    if bounded:
        cov = np.asarray(bounded_covariance(cov[None]))[0]
    return np.sqrt(np.diag(cov))


def simulate(k, rec, n, key):
    dt, w, nf, eps = rec
    x = bt.simulate(k, GAMMA, w, dt, nf, key=key, n_traces=n, method="exact_frames",
                    tracking_std=eps)
    return np.asarray(x).reshape(n, nf)


def fit_batch(k, recs, xs):
    (dt, w, _, eps), = recs
    r = bt.calibrate_batch(xs[0], frame_interval=dt, exposure=w, temperature=T,
                           model=None if eps > 0 else "blur")
    ok = np.array([s == "ok" for s in r.status])
    return np.asarray(r.k), np.asarray(r.gamma), ok


def fit_calibrate(k, recs, xs):
    ks, gs, ok = [], [], []
    for i in range(xs[0].shape[0]):
        recordings = [bt.Recording(x[i], frame_interval=dt, exposure=w, temperature=T)
                      for x, (dt, w, _, _) in zip(xs, recs)]
        try:
            r = bt.calibrate(recordings, k="shared", method="likelihood")
            ks.append(r.k)
            gs.append(r.gamma)
            ok.append(bool(np.isfinite(r.k) and np.isfinite(r.gamma)))
        except Exception as exc:  # a failed fit is counted, not fatal
            print(f"  fit {i} failed: {exc!s:.120}", flush=True)
            ks.append(np.nan)
            gs.append(np.nan)
            ok.append(False)
    return np.array(ks), np.array(gs), np.array(ok)


def fit_photon(k, recs, xs):
    """Joint Whittle fit of (log k, log gamma, log eps_ref^2) with eps_i^2 = eps_ref^2 *
    (eps_i / eps_0)^2 for a series at one frame interval and one record length."""
    import jax.numpy as jnp
    import optimistix as optx

    from blurtrap.physics import discrete_psd_unchecked

    dt = recs[0][0]
    nf = recs[0][2]
    assert all(r[0] == dt and r[2] == nf for r in recs)
    ws = jnp.asarray([r[1] for r in recs])[:, None]
    scale2 = jnp.asarray([(r[3] / recs[0][3]) ** 2 for r in recs])[:, None]
    j = np.arange(1, nf // 2)
    f = jnp.asarray(j / (nf * dt))[None, :]
    per = np.stack([np.abs(np.fft.rfft(x - x.mean(axis=1, keepdims=True), axis=1)[:, 1:nf // 2])
                    ** 2 * dt / nf for x in xs], axis=1)  # (n_exp, n_rec, n_f)
    kt = BOLTZMANN * T

    def nll(th, periodogram):
        kk, gg, e2 = jnp.exp(th[0]), jnp.exp(th[1]), jnp.exp(th[2])
        p = discrete_psd_unchecked(f, kt / kk, gg / kk, ws, dt, e2 * scale2)
        return jnp.mean(jnp.log(p) + periodogram / p)

    th0 = jnp.log(jnp.asarray([1.3 * k, 0.8 * GAMMA, 1.5 * recs[0][3] ** 2]))

    @jax.jit
    def one(periodogram):
        sol = optx.minimise(nll, optx.BFGS(rtol=1e-8, atol=1e-8), th0, args=periodogram,
                            max_steps=1000, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful

    th, conv = jax.lax.map(one, jnp.asarray(per))
    th = np.asarray(th)
    print(f"  optimiser flag 'successful' on {int(np.sum(conv))}/{len(th)} fits (a finite "
          "optimum counts as a fit)", flush=True)
    ok = np.all(np.isfinite(th), axis=1)
    return np.exp(th[:, 0]), np.exp(th[:, 1]), ok


# the design index in the seeds (the runs of RESULTS_design.md; d_w shares e_rec's seeds)
SEED_INDEX = {"a": 0, "b": 1, "c": 2, "a_paper": 3, "e_paper": 4, "d": 5, "a_rec": 6,
              "e_rec": 7, "d_w": 7, "a_rec_w": 8, "a_paper_w": 9, "b0": 11}

FITTERS = {"batch": fit_batch, "calibrate": fit_calibrate, "photon": fit_photon}


def run_one(idx, name, k, recs, fitter, n, chunk, seed_base=0):
    t0 = time.perf_counter()
    kk, gg, ok = [], [], []
    for c, start in enumerate(range(0, n, chunk)):
        m = min(chunk, n - start)
        keys = jax.random.split(jax.random.key(seed_base + 1000 * idx + c), len(recs))
        xs = [simulate(k, r, m, kr) for r, kr in zip(recs, keys)]
        a, b, o = FITTERS[fitter](k, recs, xs)
        kk.append(a)
        gg.append(b)
        ok.append(o)
        print(f"  {name}: {start + m}/{n} ({time.perf_counter() - t0:.0f} s)", flush=True)
    kk, gg, ok = np.concatenate(kk), np.concatenate(gg), np.concatenate(ok)
    pred = predicted(k, recs)
    nok = int(ok.sum())
    sd = [float(np.std(np.log(v[ok]), ddof=1)) for v in (kk, gg)]
    bias = [float(np.mean(np.log(v[ok]))) - math.log(t) for v, t in ((kk, k), (gg, GAMMA))]
    return {"name": name, "k": k, "gamma": GAMMA, "fitter": fitter,
            "recordings": [{"frame_interval_s": dt, "exposure_s": w, "n_frames": nf,
                            "tracking_std_m": eps} for dt, w, nf, eps in recs],
            "n": n, "n_ok": nok, "failures": n - nok,
            "predicted_se": {"k": float(pred[0]), "gamma": float(pred[1])},
            "measured_sd": {"k": sd[0], "gamma": sd[1]},
            "mean_log_bias": {"k": bias[0], "gamma": bias[1]},
            "mc_rel_uncertainty_of_sd": math.sqrt(1 / (2 * (nok - 1))),
            "seed_base": seed_base, "seconds": time.perf_counter() - t0,
            "log_k": [float(v) for v in np.log(kk)], "log_gamma": [float(v) for v in np.log(gg)],
            "ok": [bool(v) for v in ok]}


def table(rows) -> str:
    out = ["| design | param | predicted SE % | measured SD % | ratio | MC unc. of SD | n | "
           "failures | mean bias of log % |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for p in ("k", "gamma"):
            pr, sd = r["predicted_se"][p], r["measured_sd"][p]
            out.append(f"| {r['name']} | {p} | {100 * pr:.3g} | {100 * sd:.3g} | "
                       f"{sd / pr:.3f} | {100 * r['mc_rel_uncertainty_of_sd']:.1f} % | "
                       f"{r['n_ok']} | {r['failures']} | {100 * r['mean_log_bias'][p]:+.2g} |")
    return "\n".join(out)


def compare(rows, pairs) -> str:
    """Measured SD of log k (and log gamma) of a design against a reference design."""
    by = {r["name"]: r for r in rows}
    out = ["| design | vs | SD k % | SD k % (vs) | ratio k | SD gamma % | SD gamma % (vs) | "
           "ratio gamma | MC unc. of ratio | predicted ratio k |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for a, b in pairs:
        if a not in by or b not in by:
            continue
        ra, rb = by[a], by[b]
        unc = math.sqrt(1 / (2 * (ra["n_ok"] - 1)) + 1 / (2 * (rb["n_ok"] - 1)))
        sa, sb = ra["measured_sd"], rb["measured_sd"]
        out.append(f"| {a} | {b} | {100 * sa['k']:.3g} | {100 * sb['k']:.3g} | "
                   f"{sa['k'] / sb['k']:.2f} | {100 * sa['gamma']:.3g} | "
                   f"{100 * sb['gamma']:.3g} | {sa['gamma'] / sb['gamma']:.2f} | "
                   f"{100 * unc:.0f} % | "
                   f"{ra['predicted_se']['k'] / rb['predicted_se']['k']:.2f} |")
    return "\n".join(out)


def report(dirs) -> None:
    rows = []
    for d in dirs:
        data = json.loads((pathlib.Path(d) / "design_study.json").read_text())
        for r in data["rows"]:
            if r.get("seed_base"):
                r["name"] += f" (seeds +{r['seed_base']})"
            # the prediction of the current bt.design (with the bound eps^2 >= 0); rows
            # written before it held the Cramer-Rao bound there
            recs = [(x["frame_interval_s"], x["exposure_s"], x["n_frames"], x["tracking_std_m"])
                    for x in r["recordings"]]
            r["cramer_rao_se"] = dict(zip(("k", "gamma"), map(float, predicted(r["k"], recs,
                                                                              False)[:2])))
            r["predicted_se"] = dict(zip(("k", "gamma"), map(float, predicted(r["k"], recs)[:2])))
            rows.append(r)
        print("meta:", data["meta"])
    for r in rows:
        recs = "; ".join(f"{x['frame_interval_s'] * 1e3:.4g}/{x['exposure_s'] * 1e3:.4g} ms/"
                         f"{x['n_frames']}/{x['tracking_std_m'] * 1e9:.3g} nm"
                         for x in r["recordings"])
        print(f"\n### {r['name']}\n\nk = {r['k'] * 1e3:.3g} pN/nm; recordings (dt/W/frames/eps): "
              f"{recs}; fit: {r['fitter']}; {r['seconds']:.0f} s\n")
        print(table([r]))
    print()
    print(compare(rows, [("a_rec", "a"), ("a_rec_w", "a"), ("a_paper", "a"),
                         ("a_paper_w", "a"), ("a_rec", "a_paper"), ("a_rec_w", "a_paper_w"),
                         ("e_rec", "a"), ("e_paper", "a"), ("e_rec", "e_paper")]))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("phase", choices=("designs", "simulate", "report"))
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--n-series", type=int, default=None,
                    help="experiments for the series designs fitted by bt.calibrate "
                         "(default --n)")
    ap.add_argument("--chunk", type=int, default=50)
    ap.add_argument("--seed-base", type=int, default=0,
                    help="added to every seed (a further, independent set of experiments)")
    ap.add_argument("--only", default=None)
    ap.add_argument("--out", default=str(HERE))
    ap.add_argument("--inputs", default=None, help="report: comma-separated --out folders")
    ap.add_argument("--designs", default=None, help="designs.json (default: in --out)")
    a = ap.parse_args(argv)
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.phase == "designs":
        run_designs(out)
        return
    if a.phase == "report":
        report(a.inputs.split(","))
        return
    dpath = pathlib.Path(a.designs) if a.designs else out / "designs.json"
    designs = json.loads(dpath.read_text()) if dpath.exists() else {}
    sc = scenarios(designs)
    names = a.only.split(",") if a.only else list(sc)
    path = out / "design_study.json"
    rows = json.loads(path.read_text())["rows"] if path.exists() else []
    for name in names:
        k, recs, fitter = sc[name]
        n = a.n_series if (fitter == "calibrate" and a.n_series) else a.n
        print(f"{name}: k = {k:g}, {recs}, fitter {fitter}, n = {n}", flush=True)
        row = run_one(SEED_INDEX[name], name, k, recs, fitter, n, a.chunk, a.seed_base)
        rows = [r for r in rows if r["name"] != name] + [row]
        meta = {"date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
                "processor": platform.processor(), "cpu": cpu_model(),
                "nproc": os.cpu_count(), "python": sys.version.split()[0],
                "jax": jax.__version__, "blurtrap": getattr(bt, "__version__", "?")}
        path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
        print(table([row]), flush=True)
    print(table(rows))


if __name__ == "__main__":
    main()
