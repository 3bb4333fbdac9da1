"""blurtrap against the calibration tools users already have, on the same simulated data.

Not a test. Run:  python benchmarks/bench_peers.py [--seeds 20] [--mcmc-steps 2000]
                                                   [--out benchmarks] [--no-mcmc]

Peers (optional, benchmark-only): lumicks.pylake and tweezepy, installed in a *separate*
virtual environment whose interpreter is named by the environment variable
``BLURTRAP_PEER_PYTHON`` (default ``/work/peervenv/bin/python``)::

    python3 -m venv /work/peervenv
    /work/peervenv/bin/pip install lumicks.pylake tweezepy emcee numba setuptools

A peer that is absent or does not import is skipped with the reason printed and recorded.

What it does, in one command:

1. simulates with ``blurtrap.simulate(method="exact_frames")`` two data sets for k = 0.01 and
   0.05 pN/nm, gamma = 6 pi (0.00093 Pa s) (1.53 um), T = 295 K, ``--seeds`` traces each:
   *camera*: 1500 fps, W = dt, 65 536 frames, tracking error eps = 2 nm;
   *photodiode-like*: 100 kHz, W = dt/1000 (no blur), 2^18 frames, eps = 0.5 nm;
2. fits every trace with blurtrap (default ``calibrate``, exact likelihood, blocked PSD,
   naive equipartition) in this process, and with the peers in a subprocess of the peer
   interpreter on the *same* traces saved to ``.npz`` (units converted inside
   ``_peer_runner.py``, see its docstring);
3. tabulates bias, scatter and SE/SD of k, gamma, D for every method, and the fit time per
   recording (blurtrap after compilation; compile time separately);
4. times posteriors on one 65 536-frame camera trace: tweezepy's emcee (``.mcmc``) against
   ``blurtrap.sample_posterior`` (32 walkers x ``--mcmc-steps``);
5. writes ``RESULTS_peers.md``, ``peers_accuracy.png`` and ``peers_speed.png`` into ``--out``.

Every fit is timed in wall time and in process CPU time (all threads; robust to other jobs on
a shared machine). ``--data DIR`` saves the simulated traces (or reuses them), ``--raw FILE``
saves every per-trace result; ``--replot FILE [FILE ...]`` rewrites the tables and figures
from raw files, merging rows of later files (e.g. from ``--blurtrap-only "METHOD"`` run on the
same ``--data``) into the first. ``--max-frames N`` truncates the traces (smoke runs of
``run_all.sh --smoke`` only; the labels then say so).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import pathlib
import platform
import subprocess
import sys
import tempfile
import time
import warnings

import jax
import numpy as np
from _machine import cpu_model

import blurtrap as bt
from blurtrap.physics._constants import BOLTZMANN

bt.enable_x64()

T = 295.0
KT = BOLTZMANN * T
ETA = 0.00093
RADIUS = 1.53e-6
GAMMA = 6 * math.pi * ETA * RADIUS
KS = (1e-5, 5e-5)  # N/m = 0.01, 0.05 pN/nm
DATASETS = {
    # name: frame interval, exposure, frames, eps, pylake fit range [Hz], pylake block
    "camera": dict(dt=1 / 1500, w=1 / 1500, n=65536, eps=2e-9, fit_range=(1.0, 750.0),
                   block=50, label="camera, 1500 fps, W = dt, 65 536 frames, eps = 2 nm"),
    "photodiode": dict(dt=1e-5, w=1e-8, n=2**18, eps=0.5e-9, fit_range=(10.0, 1e4), block=50,
                       label="photodiode-like, 100 kHz, W = dt/1000, 2^18 frames, "
                             "eps = 0.5 nm"),
}
BT_METHODS = {
    "blurtrap default (auto)": {},
    "blurtrap exact likelihood": dict(method="likelihood", likelihood="exact"),
    "blurtrap Whittle likelihood": dict(method="likelihood", likelihood="whittle"),
    "blurtrap blocked PSD": dict(method="psd"),
    "blurtrap naive equipartition": dict(method="equipartition"),
    "blurtrap Allan variance": dict(method="allan"),
}
DEFAULT_PEER_PY = "/work/peervenv/bin/python"


def machine_info() -> dict:
    """CPU model, cores, versions, date and load (recorded next to every figure)."""
    import importlib.metadata as md

    cpu = cpu_model()
    vers = {}
    for name in ("jax", "jaxlib", "numpy", "scipy", "optimistix", "equinox", "emcee",
                 "matplotlib"):
        try:
            vers[name] = md.version(name)
        except md.PackageNotFoundError:
            vers[name] = None
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, cwd=pathlib.Path(__file__).parent).stdout.strip()
    except OSError:  # pragma: no cover
        commit = ""
    try:
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True,
                               cwd=pathlib.Path(__file__).parent).stdout.count("\n")
    except OSError:  # pragma: no cover
        dirty = None
    return {"date": datetime.datetime.now().isoformat(timespec="seconds"), "cpu": cpu,
            "dirty_files": dirty, "blurtrap_path": str(pathlib.Path(bt.__file__).parent),
            "cores": os.cpu_count(), "platform": platform.platform(),
            "python": sys.version.split()[0], "blurtrap": bt.__version__, "commit": commit,
            "devices": [str(d) for d in jax.devices()], "load_start": os.getloadavg(), **vers}


def machine_line(m: dict) -> str:
    return (f"{m['date']}; CPU {m['cpu']}, {m['cores']} cores, devices {m['devices']}; "
            f"Python {m['python']}, blurtrap {m['blurtrap']} (commit {m['commit']}"
            + (f" + {m['dirty_files']} modified tracked files" if m.get("dirty_files") else "")
            + (f", package imported from {m['blurtrap_path']}"
               if m.get("blurtrap_path") and m["blurtrap_path"] != str(
                   pathlib.Path(__file__).resolve().parent.parent / "blurtrap") else "")
            + f"), jax "
            f"{m['jax']}, numpy {m['numpy']}, scipy {m['scipy']}, optimistix {m['optimistix']}, "
            f"equinox {m['equinox']}, emcee {m['emcee']}; load average at start "
            f"{m['load_start'][0]:.1f}")


# ------------------------------------------------------------------------------------------
def simulate_set(ds, k, n_traces, seed):
    y = bt.simulate(k, GAMMA, ds["w"], ds["dt"], ds["n"], key=jax.random.key(seed),
                    method="exact_frames", tracking_std=ds["eps"], n_traces=n_traces)
    return np.asarray(y, dtype=np.float64)


def cached_set(data_dir, name, ds, k, n_traces, seed):
    """Simulate, or load the traces a previous run saved under ``data_dir`` (so that rows
    added later, e.g. with ``--blurtrap-only``, see exactly the same data even if the simulator
    has changed in between)."""
    if data_dir is None:
        return simulate_set(ds, k, n_traces, seed)
    path = pathlib.Path(data_dir) / f"{name}.npz"
    if path.exists():
        z = np.load(path)
        if (z["x"].shape[0] >= n_traces and z["x"].shape[1] == ds["n"]
                and int(z["seed"]) == seed and float(z["k"]) == k):
            return np.asarray(z["x"][:n_traces], dtype=np.float64)
    y = simulate_set(ds, k, n_traces, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, x=y, seed=seed, k=k)
    return y


def fit_blurtrap(y, ds, kwargs, warm):
    """Fit each row; ``warm`` is an extra trace of the same shape fitted first (compile)."""
    rec = lambda r: bt.Recording(r, frame_interval=ds["dt"], exposure=ds["w"])  # noqa: E731
    t0 = time.perf_counter()
    try:
        bt.calibrate(rec(warm), **kwargs)
    except bt.FitError:
        pass
    first = time.perf_counter() - t0
    out = {f: [] for f in ("k", "k_err", "gamma", "gamma_err", "D", "D_err", "time", "cpu")}
    fails, msgs = 0, {}
    for row in y:
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            r = bt.calibrate(rec(row), **kwargs)
            vals = dict(k=r.k, k_err=r.k_err, gamma=r.gamma, gamma_err=r.gamma_err,
                        D=r.diffusion, D_err=r.diffusion_err)
        except bt.FitError as exc:
            fails += 1
            msgs[str(exc)[:80]] = msgs.get(str(exc)[:80], 0) + 1
            vals = {}
        el, cpu = time.perf_counter() - t0, time.process_time() - c0
        for f in out:
            out[f].append(el if f == "time" else cpu if f == "cpu" else
                          float(vals.get(f, float("nan"))))
    return {"peer": "blurtrap", "fails": fails, "fail_messages": msgs, "first_call_s": first,
            **out}


def run_peer(peer_py, cmd, *args, timeout=3600):
    """Run ``_peer_runner.py`` with the peer interpreter; return (json or None, reason)."""
    if not peer_py or not pathlib.Path(peer_py).exists():
        return None, f"peer interpreter {peer_py!r} not found (set BLURTRAP_PEER_PYTHON)"
    runner = pathlib.Path(__file__).with_name("_peer_runner.py")
    with tempfile.TemporaryDirectory() as td:
        out = pathlib.Path(td) / "out.json"
        res = subprocess.run([peer_py, str(runner), cmd, *map(str, args[:1]), str(out),
                              *map(str, args[1:])], capture_output=True, text=True,
                             timeout=timeout)
        if res.returncode != 0 or not out.exists():
            tail = (res.stderr or res.stdout).strip().splitlines()[-3:]
            return None, f"peer runner failed (rc {res.returncode}): {' | '.join(tail)}"
        return json.loads(out.read_text()), ""


def save_npz(path, y, ds):
    np.savez(path, x=y, fs=1.0 / ds["dt"], exposure=ds["w"], temperature=T, radius=RADIUS,
             viscosity=ETA, fit_range=np.asarray(ds["fit_range"]), block=ds["block"])


def stats(vals, errs, true):
    v = np.asarray(vals, float)
    e = np.asarray(errs, float)
    ok = np.isfinite(v)
    n = int(ok.sum())
    if n < 2:
        return None
    v, e = v[ok], e[ok]
    mean, sd = v.mean(), v.std(ddof=1)
    se_ok = np.isfinite(e).all()
    return dict(n=n, bias=100 * (mean - true) / true, mcse=100 * sd / math.sqrt(n) / true,
                sd=100 * sd / true, se_sd=float(e.mean() / sd) if se_ok else float("nan"))


def fmt_stat(s):
    if s is None:
        return "— | — | —"
    z = s["bias"] / s["mcse"] if s["mcse"] > 0 else float("nan")
    sesd = "—" if not np.isfinite(s["se_sd"]) else f"{s['se_sd']:.2f}"
    return f"{s['bias']:+.2f} ({z:+.1f}) | {s['sd']:.2f} | {sesd}"


def _cap_frames(max_frames):
    """``--max-frames``: truncate the data sets (smoke runs) and say so in their labels."""
    if max_frames is None:
        return
    if max_frames < 1024:
        raise SystemExit(f"--max-frames: got {max_frames}, expected >= 1024")
    for ds in DATASETS.values():
        if ds["n"] > max_frames:
            ds["n"] = max_frames
            ds["label"] += f" [SMOKE: truncated to {max_frames} frames]"


# ------------------------------------------------------------------------------------------
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20, help="traces per (data set, k); >= 20")
    ap.add_argument("--mcmc-steps", type=int, default=2000)
    ap.add_argument("--no-mcmc", action="store_true", help="skip the posterior timing")
    ap.add_argument("--photodiode-exact-seeds", type=int, default=None,
                    help="fit only this many photodiode traces with blurtrap's exact "
                         "likelihood (O(N) but ~2-8 s per 2^18-frame fit here); default all")
    ap.add_argument("--out", default=str(pathlib.Path(__file__).parent))
    ap.add_argument("--data", default=None, metavar="DIR",
                    help="save the simulated traces here, or reuse them if already there")
    ap.add_argument("--raw", default=None,
                    help="also save every per-trace result to this JSON file")
    ap.add_argument("--replot", default=None, nargs="+", metavar="RAW_JSON",
                    help="rewrite RESULTS_peers.md and the figures from --raw file(s); rows of "
                         "later files (e.g. a --blurtrap-only run) are merged into the first")
    ap.add_argument("--blurtrap-only", default=None, metavar="METHODS",
                    help="comma-separated blurtrap method names to run (no peers, no "
                         "posterior); for supplementing a --raw file, same seeds")
    ap.add_argument("--max-frames", type=int, default=None, metavar="N",
                    help="cap the frames per trace (smoke runs only: the tables then no longer "
                         "describe the data sets of the issue, and the labels say so)")
    a = ap.parse_args(argv)
    _cap_frames(a.max_frames)
    if a.replot:
        raws = [json.loads(pathlib.Path(f).read_text()) for f in a.replot]
        raw = raws[0]
        _cap_frames(raw["args"].get("max_frames"))
        results = {(d, k): v for d, k, v in raw["results"]}
        supp = []
        for extra in raws[1:]:
            names = set()
            for d, k, v in extra["results"]:
                results[(d, k)].update(v)
                names |= set(v)
            supp.append((sorted(names), extra["machine"]))
        order = list(BT_METHODS)
        for key, v in results.items():
            results[key] = dict(sorted(v.items(), key=lambda kv: (
                order.index(kv[0]) if kv[0] in order else len(order))))
        for key in ("seeds", "mcmc_steps", "photodiode_exact_seeds"):
            setattr(a, key, raw["args"][key])
        out_dir = pathlib.Path(a.out)
        out_dir.mkdir(parents=True, exist_ok=True)
        write_results(out_dir, a, raw["machine"], raw["peer_versions"], results, raw["post"],
                      raw["peer_python"], supp)
        make_plots(out_dir, results)
        return
    bt_methods = BT_METHODS
    if a.blurtrap_only:
        names = [x.strip() for x in a.blurtrap_only.split(",")]
        bad = [x for x in names if x not in BT_METHODS]
        if bad:
            raise SystemExit(f"--blurtrap-only: unknown {bad}; expected names in "
                             f"{list(BT_METHODS)}")
        bt_methods = {x: BT_METHODS[x] for x in names}
        a.no_mcmc = True
    warnings.simplefilter("ignore", bt.SubstepBiasWarning)
    out_dir = pathlib.Path(a.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    peer_py = os.environ.get("BLURTRAP_PEER_PYTHON", DEFAULT_PEER_PY)
    t_start = time.time()
    mach = machine_info()
    print(f"# bench_peers: seeds={a.seeds}, mcmc steps={a.mcmc_steps}\n{machine_line(mach)}")
    vers, why = run_peer(peer_py, "versions") if not a.blurtrap_only else (None, "--blurtrap-only")
    if vers is None:
        print(f"peers skipped: {why}")
    else:
        for mod in ("lumicks.pylake", "tweezepy.smmcalibration"):
            st = vers.get(f"import:{mod}")
            print(f"peer {mod}: version {vers.get(mod.split('.smm')[0])}, import {st}")
    print(f"peer interpreter: {peer_py}", flush=True)

    results = {}  # (dataset, k) -> method -> dict
    with tempfile.TemporaryDirectory() as td:
        for ids, (dname, ds) in enumerate(DATASETS.items()):
            for ik, k in enumerate(KS):
                key = (dname, k)
                t0 = time.time()
                y = cached_set(a.data, f"{dname}_{ik}", ds, k, a.seeds + 1, 9000 + 10 * ids + ik)
                warm, y = y[0], y[1:]
                t_sim = time.time() - t0
                results[key] = {}
                for mname, kw in bt_methods.items():
                    t0 = time.time()
                    yy = y
                    if (dname == "photodiode" and kw.get("likelihood") == "exact"
                            and a.photodiode_exact_seeds is not None):
                        yy = y[: a.photodiode_exact_seeds]
                    results[key][mname] = fit_blurtrap(yy, ds, kw, warm)
                    print(f"[{dname} k={k * 1e3:g}] {mname}: {time.time() - t0:.1f} s",
                          flush=True)
                if vers is not None:
                    path = pathlib.Path(td) / f"{dname}_{ik}.npz"
                    save_npz(path, y, ds)
                    t0 = time.time()
                    pr, why = run_peer(peer_py, "fit", path)
                    if pr is None:
                        print(f"peers failed on {dname}: {why}")
                    else:
                        results[key].update(pr["methods"])
                        for m, reason in pr["skipped"].items():
                            print(f"  skipped {m}: {reason}")
                            vers.setdefault("_skipped", {})[m] = reason
                    print(f"[{dname} k={k * 1e3:g}] peers: {time.time() - t0:.1f} s "
                          f"(simulation {t_sim:.1f} s)", flush=True)

        # ---- posterior timing ----------------------------------------------------------------
        post = {}
        if not a.no_mcmc:
            ds = DATASETS["camera"]
            y = cached_set(a.data, "mcmc", ds, 5e-5, 1, 9100)
            rec = bt.Recording(y[0], frame_interval=ds["dt"], exposure=ds["w"])
            t0 = time.perf_counter()
            bt.sample_posterior(rec, n_walkers=32, n_steps=20)  # compiles both batch shapes
            t_comp = time.perf_counter() - t0
            t0, c0 = time.perf_counter(), time.process_time()
            p = bt.sample_posterior(rec, n_walkers=32, n_steps=a.mcmc_steps)
            t_run, c_run = time.perf_counter() - t0, time.process_time() - c0
            lo, hi = p.interval("k")
            post["blurtrap sample_posterior (Whittle)"] = dict(
                seconds=t_run, cpu_seconds=c_run, per_step_ms=1e3 * t_run / a.mcmc_steps,
                compile_s=t_comp,
                k_median=float(np.median(p.samples["k"])), k_halfwidth=(hi - lo) / 2,
                message="")
            print(f"blurtrap posterior 32 x {a.mcmc_steps}: {t_run:.1f} s (warm-up incl. "
                  f"compile {t_comp:.1f} s)", flush=True)
            if vers is not None:
                path = pathlib.Path(td) / "mcmc.npz"
                save_npz(path, y, ds)
                pr, why = run_peer(peer_py, "mcmc", path, 32, a.mcmc_steps)
                if pr is None:
                    print(f"peer posterior skipped: {why}")
                else:
                    post.update(pr["runs"])
                    for m, r in pr["runs"].items():
                        print(f"{m} emcee 32 x {a.mcmc_steps}: {r['seconds']:.1f} s "
                              f"{r['message']}", flush=True)
    mach["load_end"] = os.getloadavg()
    mach["wall_s"] = time.time() - t_start
    if a.raw:
        pathlib.Path(a.raw).write_text(json.dumps({
            "args": {"seeds": a.seeds, "mcmc_steps": a.mcmc_steps, "max_frames": a.max_frames,
                     "photodiode_exact_seeds": a.photodiode_exact_seeds},
            "machine": mach, "peer_versions": vers, "peer_python": peer_py, "post": post,
            "results": [[d, k, v] for (d, k), v in results.items()]}))
    write_results(out_dir, a, mach, vers, results, post, peer_py)
    try:
        make_plots(out_dir, results)
    except Exception as exc:  # pragma: no cover
        print(f"plot failed: {exc!r}")
    print(f"total wall time {mach['wall_s']:.0f} s")


# ------------------------------------------------------------------------------------------
def write_results(out_dir, a, mach, vers, results, post, peer_py, supplements=()):
    L = []
    L.append("# blurtrap against peer tools (pylake, tweezepy)\n")
    cmd = f"python benchmarks/bench_peers.py --seeds {a.seeds} --mcmc-steps {a.mcmc_steps}"
    if a.photodiode_exact_seeds is not None:
        cmd += f" --photodiode-exact-seeds {a.photodiode_exact_seeds}"
    L.append(f"Generated by `{cmd}` (also run by `benchmarks/run_all.sh`). {machine_line(mach)}; "
             f"load average at end {mach['load_end'][0]:.1f}; wall time "
             f"{mach['wall_s']:.0f} s. Shared 2-core machine: timings are medians of noisy "
             "runs.\n")
    for names, m in supplements:
        L.append(f"Rows {', '.join(names)}: measured on the same seeds in a supplementary run "
                 f"(`--blurtrap-only`), {m['date']}, load average {m['load_start'][0]:.1f} at "
                 f"start, {m['load_end'][0]:.1f} at end (commit {m['commit']}"
                 + (f"; blurtrap imported from {m['blurtrap_path']}" if m.get("blurtrap_path")
                    else "") + ").\n")
    if vers is None:
        L.append("**Peers not run**: no peer interpreter (`BLURTRAP_PEER_PYTHON`).\n")
    else:
        L.append(f"Peers (separate venv `{peer_py}`, subprocess, same traces via `.npz`): "
                 f"lumicks.pylake {vers.get('lumicks.pylake')}, tweezepy {vers.get('tweezepy')}, "
                 f"emcee {vers.get('emcee')}, numpy {vers.get('numpy')}, scipy "
                 f"{vers.get('scipy')}, autograd {vers.get('autograd')}.\n")
        for m, reason in vers.get("_skipped", {}).items():
            L.append(f"Skipped {m}: {reason}.\n")
    L.append(
        "Truth: gamma = 6 pi (0.00093 Pa s)(1.53 um) = "
        f"{GAMMA * 1e6:.5f} pN s/um, D = kT/gamma = {KT / GAMMA * 1e12:.5f} um^2/s, T = 295 K. "
        "Data: `bt.simulate(..., method=\"exact_frames\")` (exact in distribution). "
        "Columns: bias [%] of the mean (in Monte-Carlo SE), SD [%] of the estimates, SE/SD = "
        "mean reported standard error / observed SD (1 = honest error bars; its own MC "
        f"uncertainty is ~{1 / math.sqrt(2 * (a.seeds - 1)):.2f}). n = successful fits (fails). "
        "Time = median wall time per recording (blurtrap after compilation; `first` = first "
        "call incl. compile).\n")
    L.append("Peer settings (chosen to favour the peer where a choice exists): pylake "
             "`calibrate_force(x_um, bead_diameter=3.06, temperature=21.85, viscosity=0.00093, "
             "sample_rate=fs, fast_sensor=True (a pure Lorentzian, no diode filter), "
             "hydrodynamically_correct=False/True, fit_range, num_points_per_block=50)`; its k is "
             "`kappa = 2 pi gamma_0 f_c` with the *true* Stokes drag gamma_0 given to it, its "
             "gamma is kT/D from the fitted D (positions passed in um, so Rd = 1 um/V when D is "
             "right). `pylake blur+alias (private API)` = `PassiveCalibrationModel(...)."
             "_motion_blur(W)._alias_model(fs, 10)` fitted with the public "
             "`fit_power_spectrum` (not reachable from `calibrate_force`). tweezepy "
             "`PSD(x_nm, fs).mlefit(tracking_error=..., kT=4.073, viscosity=9.3e-10, "
             "radius=1530)` (Welch, 3 half-overlapping Hann segments, Lansdorp 2012 aliased + "
             "camera-averaged PSD) and `AV(x_nm, fs).mlefit(...)` (octave overlapping Allan "
             "variance, Lansdorp eq. 17); D = kT/g. Note: tweezepy's `lansdorpPSD` equals "
             "blurtrap's exact aliased blurred PSD for W = dt (checked numerically: ratio 1 to "
             "machine precision) but not for W < dt (ratio 1.19 at 300 Hz for W = dt/2, k = 0.05 "
             "pN/nm), so the W = dt camera set of the issue is tweezepy's home ground; pylake's "
             "public model has no blur, no aliasing and no noise floor.\n")
    for dname, ds in DATASETS.items():
        L.append(f"\n## Accuracy: {ds['label']}\n")
        fr = ds["fit_range"]
        L.append(f"pylake fit range {fr[0]:g}-{fr[1]:g} Hz. True f_c = "
                 + ", ".join(f"{k / (2 * math.pi * GAMMA):.1f} Hz (k = {k * 1e3:g})"
                             for k in KS)
                 + "; dt/tau = " + ", ".join(f"{ds['dt'] * k / GAMMA:.3g}" for k in KS)
                 + "; alpha = W/tau = " + ", ".join(f"{ds['w'] * k / GAMMA:.3g}" for k in KS)
                 + ".\n")
        L.append("| k [pN/nm] | method | n (fail) | k bias [%] (MC SE) | k SD [%] | k SE/SD | "
                 "gamma bias [%] (MC SE) | gamma SD [%] | gamma SE/SD | D bias [%] (MC SE) | "
                 "D SD [%] | D SE/SD | time/fit [ms] |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for k in KS:
            for m, r in results[(dname, k)].items():
                sk = stats(r["k"], r["k_err"], k)
                sg = stats(r["gamma"], r["gamma_err"], GAMMA)
                sd = stats(r["D"], r["D_err"], KT / GAMMA)
                n = int(np.isfinite(r["k"]).sum())
                tm = 1e3 * float(np.median(r["time"]))
                first = (f" (first {r['first_call_s']:.1f} s)" if "first_call_s" in r else "")
                L.append(f"| {k * 1e3:g} | {m} | {n} ({r['fails']}) | {fmt_stat(sk)} | "
                         f"{fmt_stat(sg)} | {fmt_stat(sd)} | {tm:.1f}{first} |")
        fm = {m: r["fail_messages"] for k in KS for m, r in results[(dname, k)].items()
              if r["fail_messages"]}
        if fm:
            L.append("\nFailures: " + "; ".join(f"{m}: {v}" for m, v in fm.items()) + "\n")

    # speed summary: per-recording time ratios to blurtrap default, same data
    L.append("\n## Speed: fit time per recording (median, same traces)\n")
    L.append("Wall = elapsed time; CPU = process CPU time (all threads), which is less "
             "sensitive to the other jobs sharing the 2 cores. Ratios are to blurtrap's "
             "default on the same data set.\n")
    L.append("| data set | method | wall median [ms] | wall min [ms] | CPU median [ms] | "
             "wall / blurtrap default | CPU / blurtrap default |")
    L.append("|---|---|---|---|---|---|---|")
    for dname in DATASETS:
        refm = ("blurtrap default (auto)" if "blurtrap default (auto)" in results[(dname, KS[0])]
                else next(iter(results[(dname, KS[0])])))
        ref = {f: np.median(np.concatenate([results[(dname, k)][refm][f] for k in KS]))
               for f in ("time", "cpu")}
        for m in results[(dname, KS[0])]:
            t = np.concatenate([results[(dname, k)][m]["time"] for k in KS])
            c = np.concatenate([results[(dname, k)][m]["cpu"] for k in KS])
            L.append(f"| {dname} | {m} | {1e3 * np.median(t):.1f} | {1e3 * t.min():.1f} | "
                     f"{1e3 * np.median(c):.1f} | {np.median(t) / ref['time']:.2f} | "
                     f"{np.median(c) / ref['cpu']:.2f} |")
    L.append("\nThe peers run in their own process (separate venv), so peer/blurtrap ratios "
             "are between processes on the same machine in the same run, not within one "
             "process.")
    for dname in DATASETS:
        for k in KS:
            r = results[(dname, k)]
            d, e = r.get("blurtrap default (auto)"), r.get("blurtrap exact likelihood")
            if d and e and np.median(d["cpu"]) > 0.3 * np.median(e["cpu"]):
                L.append(f"For the {dname} set at k = {k * 1e3:g} pN/nm, blurtrap's `auto` "
                         "chose the exact likelihood (Whittle leakage index >= 1, see the "
                         "result's `notes`), hence its larger time there.")
    L.append("")
    if post:
        L.append(f"\n## Posterior: 32 walkers x {a.mcmc_steps} steps, one camera trace "
                 "(k = 0.05 pN/nm, 65 536 frames)\n")
        L.append("| sampler | wall [s] | CPU [s] | per step [ms] | k median [pN/nm] | k 68 % "
                 "half-width [pN/nm] | note |")
        L.append("|---|---|---|---|---|---|---|")
        for m, r in post.items():
            note = r.get("message", "")
            if "compile_s" in r:
                note = (f"after a 20-step warm-up that compiled both batch shapes "
                        f"({r['compile_s']:.1f} s)")
            km = r.get("k_median", float("nan")) * 1e3
            kh = r.get("k_halfwidth", float("nan")) * 1e3
            L.append(f"| {m} | {r['seconds']:.1f} | {r.get('cpu_seconds', float('nan')):.1f} | "
                     f"{r['per_step_ms']:.2f} | {km:.4f} | {kh:.4f} | {note} |")
        b = post.get("blurtrap sample_posterior (Whittle)")
        tz = post.get("tweezepy PSD + tracking error")
        if b and tz:
            L.append(f"\ntweezepy PSD emcee / blurtrap sample_posterior = "
                     f"{tz['seconds'] / b['seconds']:.1f}x wall, "
                     f"{tz['cpu_seconds'] / b['cpu_seconds']:.1f}x CPU (same trace, same walkers and "
                     "steps; tweezepy fits 16 383 Welch frequencies, blurtrap 32 768 "
                     "periodogram frequencies).\n")
    L.append("\nFigures: `peers_accuracy.png` (bias +- SD of k and gamma by method), "
             "`peers_speed.png` (time per recording).\n")
    path = out_dir / "RESULTS_peers.md"
    path.write_text("\n".join(L) + "\n")
    print("\n".join(L))
    print(f"\nwrote {path}")


def make_plots(out_dir, results):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(next(iter(results.values())).keys())
    fig, axes = plt.subplots(2, 2, figsize=(14, 10), sharey="row")
    y = np.arange(len(methods))
    for j, dname in enumerate(DATASETS):
        for i, (pn, true_of) in enumerate((("k", lambda k: k), ("gamma", lambda k: GAMMA))):
            ax = axes[i, j]
            for ik, k in enumerate(KS):
                b, e = [], []
                for m in methods:
                    r = results[(dname, k)].get(m)
                    s = stats(r[pn], r[pn + "_err"], true_of(k)) if r else None
                    b.append(s["bias"] if s else np.nan)
                    e.append(s["sd"] if s else np.nan)
                ax.errorbar(b, y + (ik - 0.5) * 0.3, xerr=e, fmt="o", capsize=3,
                            label=f"k = {k * 1e3:g} pN/nm (bar: +-1 SD of one fit)")
            ax.axvline(0, color="k", lw=0.8)
            ax.set_xscale("symlog", linthresh=1, linscale=0.4)
            ticks = [-50, -20, -10, -5, -2, -1, 0, 1, 2, 5, 10, 20, 50]
            ax.set_xticks(ticks, [str(t) for t in ticks])
            ax.minorticks_off()
            ax.set_xlim(-80, 80)
            ax.grid(axis="x", color="0.9")
            ax.set_yticks(y, methods, fontsize=8)
            ax.invert_yaxis()
            ax.set_xlabel(f"{pn}: bias of the mean [%] (symlog)")
            ax.set_title(f"{pn}: {DATASETS[dname]['label']}", fontsize=8)
            ax.legend(fontsize=7, loc="lower left", framealpha=0.9)
    fig.suptitle("bias of the mean +- 1 SD of a single fit; 0 = unbiased (symlog axis)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out_dir / "peers_accuracy.png", dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(9, 6))
    for j, dname in enumerate(DATASETS):
        c = [1e3 * np.median(np.concatenate([results[(dname, k)][m]["cpu"] for k in KS]))
             for m in methods]
        t = [1e3 * np.median(np.concatenate([results[(dname, k)][m]["time"] for k in KS]))
             for m in methods]
        bars = ax.barh(y + (j - 0.5) * 0.38, c, 0.38, label=f"CPU: {DATASETS[dname]['label']}")
        ax.plot(t, y + (j - 0.5) * 0.38, "|", ms=9, mew=2, color=bars.patches[0].get_facecolor(),
                alpha=0.6, label="wall (same runs, shared machine)" if j else None)
    ax.set_xscale("log")
    ax.set_yticks(y, methods, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("median time per recording [ms] (log): bars = process CPU time, ticks = wall; "
                  "blurtrap after compilation", fontsize=8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / "peers_speed.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
