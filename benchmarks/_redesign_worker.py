"""Child process of ``compare_redesign.py``: imports blurtrap from ``$PYTHONPATH`` (the old or
the new source tree) and runs one job on data handed over in files. Only the public API
(``bt.simulate``, ``bt.calibrate``, ``bt.calibrate_batch``, ``bt.sample_posterior``,
``bt.diagnose``), present in both trees, is called.

Jobs (``python _redesign_worker.py JOB DIR [args]``):

- ``gen DIR N_CAL N_POST DIAG_SPEC``: simulate the studies' data with this tree's simulator
  (the same keys as ``study_calibration.py``, ``study_posterior.py``, ``study_diagnose.py``)
  into ``DIR``;
- ``calib DIR``, ``posterior DIR STEPS``, ``diagnose DIR``: fit the data in ``DIR`` and write
  ``DIR/<job>_<tag>.json`` (``tag`` from ``$REDESIGN_TAG``);
- ``time DIR N_BATCH``: a timing server (JSON commands on stdin, one JSON line per answer);
- ``first DIR N_BATCH``: the first (compiling) and the second call of every timing case in a
  fresh process.
"""

from __future__ import annotations

import inspect
import json
import math
import os
import pathlib
import pickle
import sys
import time
import warnings

import jax
import numpy as np

import blurtrap as bt

bt.enable_x64()
DT = 1.0 / 1500.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
EPS = 2e-9
N_FRAMES = 65536
K_CAL = (1e-5, 5e-5)
TAG = os.environ.get("REDESIGN_TAG", "x")


def _dump(path, obj):
    pathlib.Path(path).write_text(json.dumps(obj))


# ------------------------------------------------------------------------------------------
# data (this tree's simulator; the driver compares old and new draws)
# ------------------------------------------------------------------------------------------
def _sim_calib(k, n, seed, chunk=100):
    """As ``study_calibration.simulate``: keys seed * 1000 + chunk index."""
    out = []
    for i, start in enumerate(range(0, n, chunk)):
        b = min(chunk, n - start)
        y = bt.simulate(k, GAMMA, DT, DT, N_FRAMES, key=jax.random.key(seed * 1000 + i),
                        method="exact_frames", tracking_std=EPS, n_traces=b)
        out.append(np.asarray(y, dtype=np.float64).reshape(b, N_FRAMES))
    return np.concatenate(out, axis=0)


def _sim_posterior(n, chunk=20):
    """As ``study_posterior.coverage_study``: k log-uniform, one key per dataset."""
    rng = np.random.default_rng(20240601)
    ks = np.exp(rng.uniform(np.log(5e-6), np.log(1e-4), n))
    ys = []
    for c0 in range(0, n, chunk):
        kk = ks[c0:c0 + chunk]
        keys = jax.random.split(jax.random.key(1000 + c0), kk.size)
        x = bt.simulate(kk, GAMMA, DT, DT, N_FRAMES, key=keys, method="exact_frames",
                        tracking_std=EPS, n_traces=1)
        ys.append(np.asarray(x, dtype=float).reshape(kk.size, N_FRAMES))
    return ks, np.concatenate(ys, axis=0)


def _rec_dict(r):
    return {"x": np.asarray(r.positions), "dt": r.frame_interval, "w": r.exposure,
            "T": r.temperature, "P": r.laser_power,
            "times": None if r.times is None else np.asarray(r.times)}


def gen(out, n_cal, n_post, spec):
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if n_cal > 0:
        np.save(out / "calib.npy", np.stack([_sim_calib(k, n_cal, 10 + i)
                                             for i, k in enumerate(K_CAL)]))
    if n_post > 0:
        ks, ys = _sim_posterior(n_post)
        np.save(out / "post_k.npy", ks)
        np.save(out / "post_y.npy", ys)
    if spec:
        sys.path.insert(0, str(pathlib.Path(os.environ["PYTHONPATH"]) / "benchmarks"))
        import study_diagnose as sd

        items = []
        for kv in spec.split(","):
            name, n = kv.split("=")
            for i in range(int(n)):
                seed = sd.SEED_BASE[name] + i
                data = sd.SCENARIOS[name][1](seed)
                recs = data if isinstance(data, list) else [data]
                items.append({"scenario": name, "seed": seed, "list": isinstance(data, list),
                              "recs": [_rec_dict(r) for r in recs]})
        (out / "diag_data.pkl").write_bytes(pickle.dumps(items))


# ------------------------------------------------------------------------------------------
# statistics
# ------------------------------------------------------------------------------------------
def _row(r):
    return [r.k, r.k_err, r.gamma, r.gamma_err, r.tracking_var, r.tracking_var_err]


def calib(d):
    y = np.load(pathlib.Path(d) / "calib.npy")
    res = {"single": [], "batch": [], "wall_s": []}
    for j in range(y.shape[0]):
        t0 = time.perf_counter()
        rows = []
        for i in range(y.shape[1]):
            try:
                rows.append(_row(bt.calibrate(bt.Recording(y[j, i], frame_interval=DT,
                                                           exposure=DT))))
            except bt.FitError:
                rows.append([float("nan")] * 6)
        res["wall_s"].append(time.perf_counter() - t0)
        b = bt.calibrate_batch(y[j], frame_interval=DT, exposure=DT)
        arr = np.stack([b.k, b.k_err, b.gamma, b.gamma_err, b.tracking_var,
                        b.tracking_var_err], 1)
        arr[~np.asarray(b.success)] = np.nan
        res["single"].append(np.asarray(rows, dtype=float).tolist())
        res["batch"].append(arr.tolist())
    _dump(pathlib.Path(d) / f"calib_{TAG}.json", res)


def posterior(d, steps):
    ks = np.load(pathlib.Path(d) / "post_k.npy")
    ys = np.load(pathlib.Path(d) / "post_y.npy")
    truth = {"k": None, "gamma": GAMMA, "tracking_var": EPS**2}
    rows = []
    for i, (k, y) in enumerate(zip(ks, ys)):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            p = bt.sample_posterior(bt.Recording(y, frame_interval=DT, exposure=DT),
                                    n_walkers=32, n_steps=steps, seed=i)
        row = {"i": i, "wall_s": time.perf_counter() - t0,
               "max_tau": float(max(p.autocorr_time.values()))}
        for name in ("k", "gamma", "tracking_var"):
            q = np.quantile(p.samples[name], [0.025, 0.16, 0.5, 0.84, 0.975])
            row[name] = {"truth": float(k) if name == "k" else truth[name],
                         "q": [float(v) for v in q]}
        rows.append(row)
    _dump(pathlib.Path(d) / f"posterior_{TAG}.json", rows)


def _recording(r):
    times = None if r["times"] is None else np.asarray(r["times"])
    return bt.Recording(np.asarray(r["x"]), frame_interval=r["dt"], exposure=r["w"],
                        temperature=r["T"], laser_power=r["P"], times=times,
                        allow_irregular=times is not None)


def diagnose(d):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
    import study_diagnose as sd  # identical in both trees: scenarios and truth checks

    items = pickle.loads((pathlib.Path(d) / "diag_data.pkl").read_bytes())
    rows = []
    for it in items:
        name = it["scenario"]
        effect, _, model, kind, _ = sd.SCENARIOS[name]
        recs = [_recording(r) for r in it["recs"]]
        t0 = time.perf_counter()
        try:
            dg = bt.diagnose(recs if it["list"] else recs[0], model=model)
        except Exception as exc:  # a crash is a result
            rows.append({"scenario": name, "seed": it["seed"], "error": repr(exc)[:300]})
            continue
        top = dg.ranking[0] if dg.ranking else None
        fit = top.fit if top is not None else None
        row = {"scenario": name, "seed": it["seed"], "wall_s": time.perf_counter() - t0,
               "adequate": bool(dg.adequate), "gof_p": float(dg.gof["p_value"]),
               "top": top.effect if top else None,
               "top_significant": bool(top.significant) if top else False,
               "significant": [c.effect for c in dg.ranking if c.significant]}
        if effect is not None:
            row["identified"] = bool(top is not None and top.effect == effect
                                     and top.significant)
            gof_ok = (True if kind in ("histogram", "timestamps") else
                      None if fit is None else bool(fit.gof["p_value"] > dg.threshold))
            truth_ok = sd.fixed_ok(name, kind, fit) if row["identified"] else None
            row["fixed_ok"] = bool(row["identified"] and gof_ok and truth_ok)
        rows.append(row)
        print(f"{TAG} {name} {it['seed']} {row.get('top')} {row['wall_s']:.1f}s", flush=True)
    _dump(pathlib.Path(d) / f"diagnose_{TAG}.json", rows)


# ------------------------------------------------------------------------------------------
# timing
# ------------------------------------------------------------------------------------------
class Cases:
    """The timed calls; data from ``DIR/time.npz`` (simulated once by the driver's gen)."""

    def __init__(self, d, n_batch):
        y = np.load(pathlib.Path(d) / "calib.npy")[1]
        self.single = [bt.Recording(v, frame_interval=DT, exposure=DT) for v in y[:10]]
        reps = -(-n_batch // y.shape[0])
        self.batch = np.tile(y, (reps, 1))[:n_batch]
        self.post = self.single[0]
        # the new tree finds and subtracts lines by default ("keep" skips that step); the old
        # tree has no line finder and no `lines` argument (no call here: first calls compile)
        params = inspect.signature(bt.calibrate).parameters
        self.keep = {"lines": "keep"} if "lines" in params else {}

    def run(self, case, i=0):
        if case == "calibrate":
            return bt.calibrate(self.single[i % len(self.single)]).k
        if case == "calibrate_keep":
            return bt.calibrate(self.single[i % len(self.single)], **self.keep).k
        if case == "batch":
            return bt.calibrate_batch(self.batch, frame_interval=DT, exposure=DT).k
        if case == "sim_substep":
            return np.asarray(bt.simulate(5e-5, GAMMA, DT, DT, 16384, key=jax.random.key(i),
                                          method="exact", tracking_std=EPS, n_traces=64))
        if case == "sim_exact_frames":
            return np.asarray(bt.simulate(5e-5, GAMMA, DT, DT, 65536, key=jax.random.key(i),
                                          method="exact_frames", tracking_std=EPS,
                                          n_traces=64))
        if case == "posterior":
            return bt.sample_posterior(self.post, n_walkers=32, n_steps=500, seed=i).ml.k
        raise ValueError(f"unknown case {case!r}")


CASES = ("calibrate", "calibrate_keep", "batch", "sim_substep", "sim_exact_frames", "posterior")


def first(d, n_batch):
    t0 = time.perf_counter()
    cases = Cases(d, n_batch)
    out = {"setup_s": time.perf_counter() - t0, "first": {}, "second": {}}
    warnings.simplefilter("ignore")
    for c in CASES:
        for key in ("first", "second"):
            t0 = time.perf_counter()
            cases.run(c, 1)
            out[key][c] = time.perf_counter() - t0
    print(json.dumps(out), flush=True)


def serve(d, n_batch):
    warnings.simplefilter("ignore")
    cases = Cases(d, n_batch)
    for c in CASES:  # compile and warm up
        cases.run(c, 0)
        cases.run(c, 1)
    print(json.dumps({"ready": True, "jax": jax.__version__, "file": bt.__file__}), flush=True)
    for line in sys.stdin:
        cmd = json.loads(line)
        if cmd["op"] != "time":
            break
        t0, c0 = time.perf_counter(), time.process_time()
        for j in range(cmd["inner"]):
            cases.run(cmd["case"], cmd["i"] + j)
        print(json.dumps({"t": (time.perf_counter() - t0) / cmd["inner"],
                          "cpu": (time.process_time() - c0) / cmd["inner"]}), flush=True)


if __name__ == "__main__":
    job, directory, *rest = sys.argv[1:]
    if job == "gen":
        gen(directory, int(rest[0]), int(rest[1]), rest[2] if len(rest) > 2 else "")
    elif job == "calib":
        calib(directory)
    elif job == "posterior":
        posterior(directory, int(rest[0]))
    elif job == "diagnose":
        diagnose(directory)
    elif job == "time":
        serve(directory, int(rest[0]))
    elif job == "first":
        first(directory, int(rest[0]))
    else:
        raise SystemExit(f"unknown job {job!r}")
