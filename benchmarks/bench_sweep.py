"""Throughput of ``bt.sweep`` against a plain Python loop of ``simulate`` + ``calibrate``,
with 1 and 2 forced local (CPU) devices and with 2 ``jax.distributed`` processes.

Not a test. Run:  python benchmarks/bench_sweep.py [--traces 128] [--frames 4096]
                  [--out benchmarks]   (appends nothing: prints the section and writes
                  ``sweep_results.json``; the RESULTS_scaling.md section is pasted from it)

Each configuration runs in a fresh subprocess (the device count of a JAX process is fixed
when its backend starts): a warm-up sweep of one chunk per cell compiles every shape, then
the timed sweep (another key) runs on the same grid. The loop baseline runs in the 1-device
process, right after its sweep: for each of the first ``--loop-traces`` traces of one cell,
``simulate`` one trace, then ``calibrate`` it once per model (Whittle likelihood: the
objective ``calibrate_batch`` uses), so both rates come from the same process and minutes.
The same process then times the sweep with a second calibration method
(``methods=("whittle", "psd")``, after its own warm-up): twice the fits of the same
simulated frames.
Memory: peak RSS after the warm-up, after the timed sweeps and after sweeps of 4 and 16
times as many traces of one cell (bounded memory: the peak should not grow from the first
to the second), next to the bytes of one chunk of positions (``chunk_traces x n_frames x 8``).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import resource
import socket
import subprocess
import sys
import time
from typing import Any

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
GRID = {"k": [2e-5, 5e-5], "gamma": 2.7e-8, "exposure": [1e-4, 6.667e-4],
        "frame_interval": 6.667e-4, "tracking_std": 1e-9}
MODELS = ("naive", "standard")
#: the methods row: every model fitted by each of these calibration methods
METHODS = ("whittle", "psd")


def _rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(args):
    import jax

    if args.process is not None:
        jax.distributed.initialize(coordinator_address=f"127.0.0.1:{args.port}",
                                   num_processes=2, process_id=args.process)
    import numpy as np

    import blurtrap as bt

    bt.enable_x64()
    bt.enable_compilation_cache(args.cache)
    kw: dict[str, Any] = dict(n_frames=args.frames, models=MODELS, chunk_traces=args.chunk,
                              progress=False, gof_threshold=0.0)
    bt.sweep(GRID, n_traces=args.chunk, key=jax.random.key(0), **kw)  # compile every shape
    rss_warm = _rss_mb()
    if args.process is not None:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("timed sweep")
    wall = cpu = float("inf")
    for r in range(args.repeats):  # minimum over repeats (the machine is shared)
        c0, t0 = time.process_time(), time.perf_counter()
        res = bt.sweep(GRID, n_traces=args.traces, key=jax.random.key(1 + r), **kw)
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    n_cells = int(np.prod(res.shape[:-2]))  # the grid's axes (not model, method)
    out = {"devices": len(jax.local_devices()), "processes": jax.process_count(),
           "wall_s": wall, "cpu_s": cpu, "frames": n_cells * args.traces * args.frames,
           "fits": n_cells * args.traces * len(MODELS), "n_ok": int(res["n_ok"].sum()),
           "rss_warm_mb": rss_warm, "rss_sweep_mb": _rss_mb()}
    if args.loop:
        out.update(loop(args, bt, jax, np))
        out.update(methods_row(args, bt, jax, kw))
        one = {"k": GRID["k"][0], **{k: v for k, v in GRID.items() if k != "k"}}
        for mult in (4, 16):  # one cell, 4x then 16x the traces: the peak should not move
            bt.sweep(one, n_traces=mult * args.traces, key=jax.random.key(2), **kw)
            out[f"rss_long{mult}_mb"] = _rss_mb()
            out[f"long{mult}_frames"] = mult * args.traces * args.frames
    if jax.process_index() == 0:
        print("RESULT " + json.dumps(out), flush=True)


def loop(args, bt, jax, np):
    """The plain loop: simulate one trace, calibrate it per model (after a warm-up)."""
    k, w = GRID["k"][0], GRID["exposure"][0]

    def one(i):
        y = bt.simulate(k, GRID["gamma"], w, GRID["frame_interval"], args.frames,
                        key=jax.random.key(100 + i), method="exact_frames",
                        tracking_std=GRID["tracking_std"], dtype=np.float64)
        rec = bt.from_arrays(np.asarray(y).ravel(), frame_interval=GRID["frame_interval"],
                             exposure=w)
        return [bt.calibrate(rec, method="likelihood", likelihood="whittle", model=m)
                for m in MODELS]

    one(0)  # compile
    wall = cpu = float("inf")
    for r in range(args.repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        for i in range(args.loop_traces):
            one(1 + i + r * args.loop_traces)
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return {"loop_wall_s": wall, "loop_cpu_s": cpu,
            "loop_frames": args.loop_traces * args.frames,
            "loop_fits": args.loop_traces * len(MODELS)}


def methods_row(args, bt, jax, kw):
    """The timed sweep again with ``methods=METHODS`` (same grid, traces and keys)."""
    kw = {**kw, "methods": METHODS}
    bt.sweep(GRID, n_traces=args.chunk, key=jax.random.key(0), **kw)  # compile the PSD fits
    wall = cpu = float("inf")
    for r in range(args.repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        res = bt.sweep(GRID, n_traces=args.traces, key=jax.random.key(1 + r), **kw)
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    n_cells = len(GRID["k"]) * len(GRID["exposure"])
    return {"methods_wall_s": wall, "methods_cpu_s": cpu,
            "methods_fits": n_cells * args.traces * len(MODELS) * len(METHODS),
            "methods_n_ok": int(res["n_ok"].sum()),
            "methods_blocks": sorted({int(b) for b in res["n_blocks"][..., 1:].ravel()})}


def _env(devices):
    env = dict(os.environ)
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    env["JAX_PLATFORMS"] = "cpu"
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _result(stdout):
    return json.loads([ln for ln in stdout.splitlines() if ln.startswith("RESULT ")][-1][7:])


def launch(args):
    base = [sys.executable, __file__, "--worker", "--traces", str(args.traces), "--frames",
            str(args.frames), "--chunk", str(args.chunk), "--cache", args.cache,
            "--loop-traces", str(args.loop_traces), "--repeats", str(args.repeats)]
    rows = {}
    for name, devices, extra in (("1 device", 1, ["--loop"]), ("2 devices", 2, [])):
        r = subprocess.run(base + extra, capture_output=True, text=True, env=_env(devices))
        if r.returncode:
            sys.exit(r.stderr[-3000:])
        rows[name] = _result(r.stdout)
        print(name, rows[name], flush=True)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = str(s.getsockname()[1])
    procs = [subprocess.Popen(base + ["--process", str(i), "--port", port],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=_env(1)) for i in range(2)]
    outs = [p.communicate() for p in procs]
    if any(p.returncode for p in procs):
        sys.exit("".join(o[1][-3000:] for o in outs))
    rows["2 processes"] = _result(outs[0][0])
    print("2 processes", rows["2 processes"], flush=True)
    return rows


def table(rows, args):
    base = rows["1 device"]
    lines = [f"Grid {len(GRID['k'])} k x {len(GRID['exposure'])} W = 4 cells, models "
             f"{', '.join(MODELS)}; {args.traces} traces x {args.frames} frames per cell, "
             f"chunks of {args.chunk}; exact frame sampler, Whittle fits.", "",
             f"Minimum over {args.repeats} repeats after a compiling warm-up. Wall time is "
             "inflated by the other jobs on the 2 shared cores (compare it with the CPU "
             "time); CPU time is this process's, all threads (process 0 with 2 processes, "
             "which did half of the units).", "",
             "| run | wall [s] | CPU [s] | frames/s (wall) | fits/s (wall) | CPU per fit [ms] "
             "| speed-up vs sweep on 1 device (wall) | ok fits | peak RSS after warm-up / "
             "after sweep [MB] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        share = r["processes"]  # process 0 did 1/processes of the fits
        lines.append(f"| sweep, {name} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} | "
                     f"{r['frames'] / r['wall_s']:.3g} | {r['fits'] / r['wall_s']:.1f} | "
                     f"{1e3 * r['cpu_s'] * share / r['fits']:.2f} | "
                     f"{base['wall_s'] / r['wall_s']:.2f} | {r['n_ok']}/{r['fits']} | "
                     f"{r['rss_warm_mb']:.0f} / {r['rss_sweep_mb']:.0f} |")
    loop_rate = base["loop_fits"] / base["loop_wall_s"]
    lines.append(f"| loop simulate + calibrate, 1 device | {base['loop_wall_s']:.2f} | "
                 f"{base['loop_cpu_s']:.2f} | {base['loop_frames'] / base['loop_wall_s']:.3g} "
                 f"| {loop_rate:.1f} | {1e3 * base['loop_cpu_s'] / base['loop_fits']:.2f} | "
                 f"{loop_rate / (base['fits'] / base['wall_s']):.2f} | - | - |")
    m_rate = base["methods_fits"] / base["methods_wall_s"]
    lines.append(f"| sweep, 1 device, methods {' + '.join(METHODS)} ({METHODS[1]}: "
                 f"{'/'.join(map(str, base['methods_blocks']))} blocks) | "
                 f"{base['methods_wall_s']:.2f} | {base['methods_cpu_s']:.2f} | "
                 f"{base['frames'] / base['methods_wall_s']:.3g} | {m_rate:.1f} | "
                 f"{1e3 * base['methods_cpu_s'] / base['methods_fits']:.2f} | "
                 f"{base['wall_s'] / base['methods_wall_s']:.2f} | "
                 f"{base['methods_n_ok']}/{base['methods_fits']} | - |")
    chunk_mb = args.chunk * args.frames * 8 / 2**20
    lines += ["", f"Memory (1-device process; ru_maxrss is the peak so far): one chunk of "
              f"positions is {chunk_mb:.1f} MB; peak RSS {base['rss_sweep_mb']:.0f} MB after the "
              f"timed sweeps ({base['frames']:.3g} frames each), "
              f"{base['rss_long4_mb']:.0f} MB after a sweep of {base['long4_frames']:.3g} "
              f"frames of one cell, {base['rss_long16_mb']:.0f} MB after one of "
              f"{base['long16_frames']:.3g} frames: the last 4x more frames added "
              f"{base['rss_long16_mb'] - base['rss_long4_mb']:.1f} MB (holding them as float64 "
              f"would take {(base['long16_frames'] - base['long4_frames']) * 8 / 2**20:.0f} MB)."]
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--process", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--port", default=None, help=argparse.SUPPRESS)
    p.add_argument("--loop", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--traces", type=int, default=128, help="traces per cell")
    p.add_argument("--frames", type=int, default=4096)
    p.add_argument("--chunk", type=int, default=64)
    p.add_argument("--loop-traces", type=int, default=32)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--cache", default=str(ROOT / ".pytest_cache" / "jax-bench-sweep"))
    p.add_argument("--out", default=str(HERE))
    args = p.parse_args()
    if args.worker:
        return worker(args)
    sys.path.insert(0, str(HERE))
    from bench_peers import machine_info, machine_line

    t0 = time.perf_counter()
    rows = launch(args)
    info = machine_info()
    text = (f"{machine_line(info)}; wall time {time.perf_counter() - t0:.0f} s.\n\n"
            + table(rows, args))
    print(text)
    pathlib.Path(args.out, "sweep_results.json").write_text(
        json.dumps({"machine": info, "rows": rows, "args": vars(args)}, indent=1, default=str))


if __name__ == "__main__":
    main()
