"""How blurtrap's calibration cost scales with record length and batch size (and devices).

Not a test. Run:  python benchmarks/bench_scaling.py [--full] [--out benchmarks]
                  python benchmarks/bench_scaling.py --gpu [--gpu-scale 1.0]   (GPU section)

All timings are taken after compilation, in one process, as the minimum over repeats, both as
wall-clock time and as process CPU time (all threads; much less sensitive to other jobs on a
shared machine, so the exponents are fitted to it as well); JAX results are pulled to the
host before the clock stops.

A. Latency vs record length N = 2^12 .. 2^22 (every other power without ``--full``) of the
   default ``calibrate`` (auto), the Whittle likelihood, the blocked PSD and the exact
   likelihood (up to 2^18, ``--full`` 2^20), with a numpy ``rfft`` periodogram as the
   O(N log N) reference measured in the same process. Fitted exponent ``t ~ N^p`` over
   N >= 2^16 against the exponent of N log N over the same range, and t / (N log N)
   normalised at 2^16.
B. Batch size 1 .. 10^4: ``calibrate_batch`` on B records of 4096 frames (B = 1, 10, 100,
   1000, 10 000) and of 65 536 frames (B <= 100, ``--full`` <= 1000; 10^4 x 65 536 float64
   would be 5.2 GB of input alone), per-item cost against looping ``calibrate`` with the same
   (Whittle) objective; first call (compile) separately; peak RSS.
C. Simulator throughput with 1 and 2 XLA host devices (``--xla_force_host_platform_device_count``,
   fresh subprocesses; ``simulate`` shards the traces axis over local devices).
D. ``--gpu``: on whatever accelerator JAX sees, simulator substeps/s and frames/s at N >= 1e6
   traces, ``calibrate_batch`` throughput, and a ``sweep`` of 2^20 trajectories (fits/s),
   each with its ratio to a plain numpy / scipy reference measured on the host CPU in the same
   run; written to ``RESULTS_scaling_gpu.md``.

Writes ``RESULTS_scaling.md`` and ``scaling.png`` into ``--out`` (``--gpu`` writes only the
GPU file).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import resource
import subprocess
import sys
import time
import warnings

import jax
import numpy as np

import blurtrap as bt

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_peers import machine_info, machine_line  # noqa: E402

bt.enable_x64()

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
K = 5e-5
DT = W = 1.0 / 1500.0
EPS = 2e-9
METHODS = {
    "default (auto)": {},
    "Whittle": dict(method="likelihood", likelihood="whittle"),
    "blocked PSD": dict(method="psd"),
    "exact likelihood": dict(method="likelihood", likelihood="exact"),
}


def tmin(fn, repeat):
    """(min wall time, min process CPU time) over ``repeat`` calls. CPU time (all threads)
    is much less sensitive than wall time to other jobs sharing the cores."""
    best, best_cpu = math.inf, math.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu


def sim(n_frames, n_traces, seed, k=K, w=W, dt=DT):
    return np.asarray(bt.simulate(k, GAMMA, w, dt, n_frames, key=jax.random.key(seed),
                                  method="exact_frames", tracking_std=EPS, n_traces=n_traces),
                      dtype=np.float64)


def rec(y):
    return bt.Recording(y, frame_interval=DT, exposure=W)


def rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def exponent(ns, ts, n_min=2**16):
    ns, ts = np.asarray(ns, float), np.asarray(ts, float)
    sel = (ns >= n_min) & np.isfinite(ts)
    if sel.sum() < 2:
        return float("nan"), float("nan")
    p = np.polyfit(np.log(ns[sel]), np.log(ts[sel]), 1)[0]
    p_ref = np.polyfit(np.log(ns[sel]), np.log(ns[sel] * np.log(ns[sel])), 1)[0]
    return float(p), float(p_ref)


# ------------------------------------------------------------------------------------------
def part_a(full, rep, smoke=False):
    powers = list(range(12, 23)) if full else list(range(12, 23, 2))
    if smoke:
        powers = [12, 13, 16, 17]
    exact_max = 2**20 if full else 2**18
    nmax = 2 ** powers[-1]
    ylong = sim(nmax, 1, seed=5)[0]
    rows = []
    it = iter(range(10**9))
    print("\n| N | " + " | ".join(METHODS) + " | numpy rfft periodogram | auto path |  "
          "(wall ms (CPU ms))")
    for p in powers:
        n = 2**p
        pair = [rec(ylong[:n].copy()), rec(ylong[-n:].copy())]
        row = {"N": n}
        for m, kw in METHODS.items():
            if m == "exact likelihood" and n > exact_max:
                row[m] = (float("nan"), float("nan"), float("nan"))
                continue
            t0 = time.perf_counter()
            r = bt.calibrate(pair[0], **kw)
            first = time.perf_counter() - t0
            if m == "default (auto)":
                row["path"] = r.notes[-1] if r.notes else ""
            rr = rep if n <= 2**18 else max(2, rep // 2)
            wall, cpu = tmin(lambda kw=kw: bt.calibrate(pair[next(it) % 2], **kw), rr)
            row[m] = (wall, first, cpu)
        yc = ylong[:n] - ylong[:n].mean()
        wall, cpu = tmin(lambda yc=yc: np.abs(np.fft.rfft(yc)) ** 2, max(rep, 5))
        row["numpy"] = (wall, float("nan"), cpu)
        rows.append(row)
        print(f"| {n} | " + " | ".join(f"{1e3 * row[m][0]:.2f} ({1e3 * row[m][2]:.2f})"
                                       for m in list(METHODS) + ["numpy"])
              + f" | {row.get('path', '')} |  load {os.getloadavg()[0]:.1f}", flush=True)
    return rows


def part_b(full, rep, smoke=False):
    out = []
    configs = [(4096, [1, 10, 100, 1000, 10000]),
               (65536, [1, 10, 100, 1000] if full else [1, 10, 100])]
    if smoke:
        configs = [(4096, [1, 10, 20])]
    for n, bs in configs:
        ymax = sim(n, max(bs), seed=11 + n % 7)
        # loop reference: calibrate with the same Whittle objective, one record at a time
        kw = METHODS["Whittle"]
        recs = [rec(ymax[i]) for i in range(min(20, max(bs)))]
        bt.calibrate(recs[0], **kw)
        ts, cs = [], []
        for r_ in recs:
            t0, c0 = time.perf_counter(), time.process_time()
            bt.calibrate(r_, **kw)
            ts.append(time.perf_counter() - t0)
            cs.append(time.process_time() - c0)
        loop_item, loop_cpu = float(np.median(ts)), float(np.median(cs))
        for b in bs:
            y = ymax[:b]
            try:
                t0 = time.perf_counter()
                res = bt.calibrate_batch(y, frame_interval=DT, exposure=W)
                first = time.perf_counter() - t0
                rr = 2 if b * n >= 10**7 else rep
                t, c = tmin(lambda y=y: bt.calibrate_batch(y, frame_interval=DT, exposure=W), rr)
                ok = int(np.sum(res.success))
                note = ""
            except Exception as exc:  # noqa: BLE001 - recorded as the reason for a skip
                first, t, c, ok = float("nan"), float("nan"), float("nan"), 0
                note = f"{type(exc).__name__}"
            out.append(dict(N=n, B=b, t=t, cpu=c, first=first, per_item=t / b,
                            per_item_cpu=c / b, loop_item=loop_item, loop_cpu=loop_cpu,
                            ok=ok, rss=rss_mb(), note=note))
            print(f"batch N={n} B={b}: {t:.3f} s, CPU {c:.3f} s ({1e3 * c / b:.2f} ms CPU/item; "
                  f"loop {1e3 * loop_cpu:.2f} ms CPU/item; first call {first:.1f} s; {ok}/{b} "
                  f"ok; peak RSS {rss_mb():.0f} MB; load {os.getloadavg()[0]:.1f}) {note}",
                  flush=True)
        del ymax
    return out


DEVICE_SNIPPET = r"""
import json, time, math, jax, numpy as np, blurtrap as bt
bt.enable_x64()
g = 6 * math.pi * 0.00093 * 1.53e-6
res = {"devices": len(jax.devices())}
for name, kw, nt, nf in (("exact_frames", dict(method="exact_frames"), 4096, 4096),
                         ("substeps (exact, 20/exposure)", dict(method="exact", substeps=20),
                          4096, 128)):
    def call(seed):
        return jax.block_until_ready(bt.simulate(5e-5, g, 1/1500, 1/1500, nf, n_traces=nt,
                                                 key=jax.random.key(seed), **kw))
    call(0)
    ts = []
    for _ in range(3):
        t0 = time.perf_counter()
        call(1)
        ts.append(time.perf_counter() - t0)
    best = min(ts)
    per = nt * nf * (21 if "substeps" in name else 1)
    res[name] = {"seconds": best, "per_s": per / best, "traces": nt, "frames": nf}
print("JSON" + json.dumps(res))
"""


def part_c():
    out = {}
    for d in (1, 2):
        env = dict(os.environ)
        env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") +
                            f" --xla_force_host_platform_device_count={d}").strip()
        try:
            r = subprocess.run([sys.executable, "-c", DEVICE_SNIPPET], capture_output=True,
                               text=True, env=env, timeout=900)
            line = [x for x in r.stdout.splitlines() if x.startswith("JSON")]
            out[d] = json.loads(line[-1][4:]) if line else {"error": r.stderr[-300:]}
        except subprocess.TimeoutExpired:
            out[d] = {"error": "timeout"}
        print(f"simulate with {d} host device(s): {out[d]}", flush=True)
    return out


# ------------------------------------------------------------------------------------------
def _cpu_references(scale):
    """Plain numpy / scipy throughput on the host CPU, for the accelerator's ratios: the exact
    OU substep simulator of bench_simulate in numpy (substeps/s), an AR(1) recursion with one
    normal draw per frame in numpy (frames/s; a lower bound on the work of the exact frame
    law, which draws two), and the Whittle fit in numpy + scipy L-BFGS-B of bench_calibration
    (records/s, looping over records)."""
    from bench_calibration import scipy_whittle_fit
    from bench_simulate import numpy_reference

    out = {}
    n_ref = max(2, min(2**14, int(2**20 * scale)))
    t = tmin(lambda: numpy_reference(n_ref, 16, 100, np.float32), 2)[0]
    out["numpy substeps"] = (n_ref * 16 * 101 / t, "substeps/s")
    rng = np.random.default_rng(0)

    def frames():  # AR(1), one normal per frame and trajectory
        x = rng.standard_normal(n_ref).astype(np.float32)
        y = np.empty((256, n_ref), np.float32)
        c = np.float32(math.exp(-DT * K / GAMMA))
        s = np.float32(math.sqrt(1 - c * c))
        for i in range(256):
            x = c * x + s * rng.standard_normal(n_ref).astype(np.float32)
            y[i] = x
        return y

    t = tmin(frames, 2)[0]
    out["numpy exact frames"] = (n_ref * 256 / t, "frames/s")
    for n in (4096, 65536):
        y = sim(n, 3, seed=4)
        t = tmin(lambda y=y: [scipy_whittle_fit(r, np.array([K, GAMMA, EPS**2])) for r in y],
                 2)[0]
        out[f"scipy Whittle fits, {n} frames"] = (3 / t, "records/s")
    return out


def part_gpu(scale, out_dir, mach):
    """Accelerator section: simulator substeps/s at N >= 1e6 traces, batched calibration."""
    dev = jax.devices()[0]
    L = ["# GPU / accelerator section\n", f"{machine_line(mach)}; device {dev} "
         f"({getattr(dev, 'device_kind', '')}); scale {scale}.\n"]
    n_tr = max(2, int(2**20 * scale))
    ref = _cpu_references(scale)
    L.append("CPU references, measured in this run on the host's CPU: "
             + "; ".join(f"{k} {v[0]:.3g} {v[1]}" for k, v in ref.items()) + ".\n")
    L.append("| what | size | wall [s] (min of 3, after compile) | throughput | compile [s] "
             "| ratio to the CPU reference |")
    L.append("|---|---|---|---|---|---|")
    for name, kw, nf, per_frame, unit in (
            ("simulate, exact substeps (100/exposure + dead step)",
             dict(method="exact", substeps=100, dtype=np.float32), 16, 101, "substeps/s"),
            ("simulate, exact_frames", dict(method="exact_frames", dtype=np.float32), 256, 1,
             "frames/s")):
        def call(seed, kw=kw, nf=nf):
            return jax.block_until_ready(bt.simulate(K, GAMMA, W, DT, nf, n_traces=n_tr,
                                                     key=jax.random.key(seed), **kw))
        t0 = time.perf_counter()
        call(0)
        first = time.perf_counter() - t0
        t = tmin(lambda call=call: call(1), 3)[0]
        work = n_tr * nf * per_frame
        base = ref["numpy substeps"][0] if per_frame > 1 else ref["numpy exact frames"][0]
        L.append(f"| {name}, float32 | {n_tr} traces x {nf} frames | {t:.3f} | "
                 f"{work / t:.3g} {unit} | {first - t:.1f} | {work / t / base:.3g} |")
        print(L[-1], flush=True)
    for n, b in ((4096, max(2, int(10**4 * scale))), (65536, max(2, int(10**3 * scale)))):
        y = sim(n, b, seed=3)
        t0 = time.perf_counter()
        bt.calibrate_batch(y, frame_interval=DT, exposure=W)
        first = time.perf_counter() - t0
        t = tmin(lambda y=y: bt.calibrate_batch(y, frame_interval=DT, exposure=W), 3)[0]
        base = ref[f"scipy Whittle fits, {n} frames"][0]
        L.append(f"| calibrate_batch (Whittle), float64 | {b} x {n} frames | {t:.3f} | "
                 f"{b / t:.3g} records/s | {first - t:.1f} | {b / t / base:.3g} |")
        print(L[-1], flush=True)
    # a million-trajectory sweep: simulate + calibrate streamed in chunks (one grid cell)
    n_sw, chunk = max(64, int(2**20 * scale)), max(64, min(2**14, int(2**20 * scale)))
    n_sw -= n_sw % chunk
    t0 = time.perf_counter()
    bt.sweep({"k": K, "gamma": GAMMA, "exposure": W, "frame_interval": DT, "tracking_std": EPS},
             n_frames=1024, n_traces=chunk, chunk_traces=chunk, key=jax.random.key(5),
             progress=False)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    bt.sweep({"k": K, "gamma": GAMMA, "exposure": W, "frame_interval": DT, "tracking_std": EPS},
             n_frames=1024, n_traces=n_sw, chunk_traces=chunk, key=jax.random.key(6),
             progress=False)
    t = time.perf_counter() - t0
    base = ref["scipy Whittle fits, 4096 frames"][0]
    L.append(f"| sweep (simulate + calibrate_batch, streamed), float64 | {n_sw} traces x 1024 "
             f"frames, chunks of {chunk} | {t:.3f} | {n_sw / t:.3g} fits/s, "
             f"{n_sw * 1024 / t:.3g} frames/s | {first:.1f} (first chunk) | "
             f"{n_sw / t / base:.3g} (vs scipy fits of 4096 frames) |")
    print(L[-1], flush=True)
    path = out_dir / "RESULTS_scaling_gpu.md"
    path.write_text("\n".join(L) + "\n")
    print(f"wrote {path}")


# ------------------------------------------------------------------------------------------
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="all powers of 2, bigger batches")
    ap.add_argument("--repeat", type=int, default=None)
    ap.add_argument("--skip-devices", action="store_true")
    ap.add_argument("--smoke", action="store_true",
                    help="tiny sizes (N = 2^12-2^17, batches <= 20): code paths only, for run_all.sh")
    ap.add_argument("--gpu", action="store_true", help="accelerator section only")
    ap.add_argument("--gpu-scale", type=float, default=1.0,
                    help="shrink the --gpu sizes (e.g. 0.001 for a CPU smoke test)")
    ap.add_argument("--out", default=str(pathlib.Path(__file__).parent))
    a = ap.parse_args(argv)
    out_dir = pathlib.Path(a.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore", bt.SubstepBiasWarning)
    mach = machine_info()
    print(f"# bench_scaling (full={a.full})\n{machine_line(mach)}", flush=True)
    if a.gpu:
        part_gpu(a.gpu_scale, out_dir, mach)
        return
    rep = a.repeat or (5 if a.full else 3)
    t_start = time.time()
    rows = part_a(a.full, rep, a.smoke)
    load_a = os.getloadavg()
    batch = part_b(a.full, rep, a.smoke)
    load_b = os.getloadavg()
    dev = {} if a.skip_devices else part_c()
    mach["load_end"] = os.getloadavg()
    mach["wall_s"] = time.time() - t_start
    write_results(out_dir, a, mach, rows, batch, dev, load_a, load_b)
    try:
        make_plot(out_dir, rows, batch)
    except Exception as exc:  # pragma: no cover
        print(f"plot failed: {exc!r}")
    print(f"total wall time {mach['wall_s']:.0f} s")


def write_results(out_dir, a, mach, rows, batch, dev, load_a, load_b):
    L = ["# Scaling: calibration latency vs record length and batch size\n"]
    cmd = "python benchmarks/bench_scaling.py" + (" --full" if a.full else "")
    L.append(f"Generated by `{cmd}`. {machine_line(mach)}; load average after part A "
             f"{load_a[0]:.1f}, after part B {load_b[0]:.1f}, at end {mach['load_end'][0]:.1f}; "
             f"wall time {mach['wall_s']:.0f} s. Minimum of repeats after a compiling first "
             "call; the machine is shared, so absolute times are pessimistic, ratios within a "
             "row are from the same process and minutes.\n")
    L.append("Data: one simulated camera trace (k = 0.05 pN/nm, dt = W = 1/1500 s, eps = 2 nm, "
             "exact frame sampler); each N alternates its first and last N frames.\n")
    L.append("## A. Latency vs record length\n")
    L.append("Each cell: minimum CPU time [ms] (process CPU time, all threads) and, in brackets, "
             "minimum wall time [ms]. With the load above, wall time is inflated several-fold and "
             "varies between rows; CPU time is the load-robust figure used for the exponents.\n")
    L.append("| N | " + " | ".join(METHODS) + " | numpy rfft periodogram (reference) | "
             "default path |")
    L.append("|---|" + "---|" * (len(METHODS) + 2))

    def cell(v):
        return "—" if not np.isfinite(v[0]) else f"{1e3 * v[2]:.2f} ({1e3 * v[0]:.2f})"

    for r in rows:
        L.append(f"| {r['N']} | " + " | ".join(cell(r[m]) for m in METHODS)
                 + f" | {cell(r['numpy'])} | {r.get('path', '')} |")
    ns = [r["N"] for r in rows]
    L.append("\nFitted exponent p of t ~ N^p over N >= 2^16 (N log N has p_ref over the same "
             "range) and the growth of t / (N log N) from 2^16 to the largest N measured (1.00 = "
             "exactly N log N), on CPU time and on wall time:\n")
    L.append("| method | p (CPU) | p (wall) | p_ref (N log N) | t/(N log N), largest N / 2^16, CPU "
             "| no faster than N log N (CPU)? |")
    L.append("|---|---|---|---|---|---|")
    for m in list(METHODS) + ["numpy"]:
        tc = [r[m][2] for r in rows]
        tw = [r[m][0] for r in rows]
        p, pr = exponent(ns, tc)
        pw, _ = exponent(ns, tw)
        ok = [(n, t) for n, t in zip(ns, tc) if np.isfinite(t) and n >= 2**16]
        if len(ok) >= 2:
            (n0, t0), (n1, t1) = ok[0], ok[-1]
            g = (t1 / (n1 * math.log(n1))) / (t0 / (n0 * math.log(n0)))
            gs = f"{g:.2f} (2^{int(math.log2(n1))})"
        else:
            gs = "—"
        verdict = "—" if not np.isfinite(p) else ("yes" if p <= pr + 0.05 else "**no**")
        if m == "numpy":
            verdict = "(reference: the FFT alone, memory-bound above ~2^18)"
        L.append(f"| {m if m != 'numpy' else 'numpy rfft (reference)'} | {p:.3f} | {pw:.3f} | "
                 f"{pr:.3f} | {gs} | {verdict} |")
    L.append("\nFirst call (includes compilation for that N; wall) [s]:\n")
    L.append("| N | " + " | ".join(METHODS) + " |")
    L.append("|---|" + "---|" * len(METHODS))
    for r in rows:
        L.append(f"| {r['N']} | " + " | ".join(
            "—" if not np.isfinite(r[m][1]) else f"{r[m][1]:.2f}" for m in METHODS) + " |")
    L.append("\n## B. Batch size (`calibrate_batch`, Whittle)\n")
    L.append("| frames N | batch B | wall [s] | CPU [s] | CPU per record [ms] | loop of "
             "`calibrate` (Whittle), CPU per record [ms] | batch/loop per record (CPU) | first "
             "call [s] | success | peak RSS [MB] |")
    L.append("|---|---|---|---|---|---|---|---|---|---|")
    for b in batch:
        L.append(f"| {b['N']} | {b['B']} | {b['t']:.3f} | {b['cpu']:.3f} | "
                 f"{1e3 * b['per_item_cpu']:.2f} | {1e3 * b['loop_cpu']:.2f} | "
                 f"{b['per_item_cpu'] / b['loop_cpu']:.2f} | {b['first']:.1f} | "
                 f"{b['ok']}/{b['B']} | {b['rss']:.0f} {b['note']} |")
    for n in sorted({b["N"] for b in batch}):
        sel = [b for b in batch if b["N"] == n and b["B"] >= 10 and np.isfinite(b["cpu"])]
        if len(sel) >= 2:
            p = np.polyfit(np.log([b["B"] for b in sel]), np.log([b["cpu"] for b in sel]), 1)[0]
            L.append(f"\nN = {n}: batch CPU time ~ B^{p:.2f} over B >= 10.")
    L.append("\nNot measured: 10^4 x 65 536 frames (5.2 GB of float64 input alone, plus the "
             "periodogram and per-item Newton state, on a 23 GB machine shared with other "
             "jobs); the 10^4 point uses 4096-frame records.\n")
    if dev:
        L.append("\n## C. Simulator with 1 and 2 XLA host devices\n")
        L.append("Fresh subprocess per device count (`XLA_FLAGS=--xla_force_host_platform_"
                 "device_count=D`); `simulate` shards the traces axis over the devices; float64; "
                 "min of 3 after a compiling call. Only 2 physical cores, shared.\n")
        L.append("| method | traces x frames | 1 device [/s] | 2 devices [/s] | speed-up |")
        L.append("|---|---|---|---|---|")
        names = [k for k in dev.get(1, {}) if isinstance(dev[1].get(k), dict)]
        for nm in names:
            d1, d2 = dev[1][nm], dev.get(2, {}).get(nm)
            unit = "substeps" if "substeps" in nm else "frames"
            if d2:
                L.append(f"| {nm} | {d1['traces']} x {d1['frames']} | {d1['per_s']:.3g} {unit} | "
                         f"{d2['per_s']:.3g} {unit} | {d2['per_s'] / d1['per_s']:.2f} |")
        for d, v in dev.items():
            if "error" in v:
                L.append(f"\n{d} device(s): failed: {v['error']}")
    L.append("\n## D. GPU\n")
    L.append("No GPU was lent to this task (the session's device status reported none "
             "available), so this section is not measured. To fill it on a machine with an "
             "NVIDIA GPU, from the repository root:\n")
    L.append("```\npip install -U \"jax[cuda12]\"\npython benchmarks/bench_scaling.py --gpu "
             "--out benchmarks   # writes benchmarks/RESULTS_scaling_gpu.md\n```\n")
    L.append("It measures, on the default JAX device: `simulate` substeps/s (exact substeps, "
             "100 per exposure, float32) and exact_frames frames/s at 2^20 traces, and "
             "`calibrate_batch` throughput for 10^4 x 4096 and 10^3 x 65 536 frames "
             "(records/s), each with its compile time. `--gpu --gpu-scale 0.001` runs the same "
             "code at 1/1000 size as a CPU smoke test.\n")
    L.append("\nFigure: `scaling.png` (latency vs N with N log N guide; per-record cost vs batch "
             "size).\n")
    path = out_dir / "RESULTS_scaling.md"
    path.write_text("\n".join(L) + "\n")
    print("\n".join(L))
    print(f"\nwrote {path}")


def make_plot(out_dir, rows, batch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(13, 5))
    ns = np.array([r["N"] for r in rows], float)
    for m in METHODS:
        ts = np.array([r[m][2] for r in rows])
        ok = np.isfinite(ts)
        ax[0].loglog(ns[ok], 1e3 * ts[ok], "o-", label=m)
    ax[0].loglog(ns, 1e3 * np.array([r["numpy"][2] for r in rows]), "k.--",
                 label="numpy rfft periodogram")
    i0 = int(np.argmin(np.abs(ns - 2**16)))
    t_ref = rows[i0]["Whittle"][2]
    guide = t_ref * ns * np.log(ns) / (ns[i0] * np.log(ns[i0]))
    ax[0].loglog(ns, 1e3 * guide, color="0.6", lw=3, alpha=0.5,
                 label="N log N through Whittle at 2^16")
    ax[0].set_xlabel("frames N")
    ax[0].set_ylabel("CPU time per call after compilation [ms] (min of repeats)")
    ax[0].set_title("calibrate latency vs record length", fontsize=10)
    ax[0].legend(fontsize=8)
    for n in sorted({b["N"] for b in batch}):
        sel = [b for b in batch if b["N"] == n and np.isfinite(b["cpu"])]
        ax[1].loglog([b["B"] for b in sel], [1e3 * b["per_item_cpu"] for b in sel], "o-",
                     label=f"calibrate_batch, N = {n}")
        ax[1].axhline(1e3 * sel[0]["loop_cpu"], ls=":", color=ax[1].lines[-1].get_color(),
                      label=f"loop of calibrate (Whittle), N = {n}")
    ax[1].set_xlabel("batch size B")
    ax[1].set_ylabel("CPU time per record [ms]")
    ax[1].set_title("batched calibration cost per record", fontsize=10)
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "scaling.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
