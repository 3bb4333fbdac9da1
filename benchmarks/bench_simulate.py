"""Benchmark of blurtrap.simulate against a plain NumPy reference of the same algorithm.

Not a test. Run:  python benchmarks/bench_simulate.py [--quick] [--cpus 1] [--repeat 5]

Reports, in one process (timings interleaved and repeated; the best of each is kept):
- trajectory-substeps/s of the substep simulator (method="exact") and of the NumPy reference
  (exact OU substeps, trapezoid exposure accumulation, vectorised over trajectories, one block of
  normals per frame) for N = 1, 64, 1024, 16384 trajectories, float64 and float32, with wall and
  CPU (process) time;
- compile time of the first call, separately (first call minus the best warm call);
- frames/s of method="exact_frames" against the substep simulator at the same N and 100
  substeps per frame (substep frames/s = substeps/s / 101);
- memory of a 1e8 trajectory-substep run, each in a fresh subprocess: resident set size after
  each stage (Python + NumPy, import jax, backend start, import blurtrap, first call = compile
  of the same chunk shape, the run) and the peak (VmHWM), plus the same for the NumPy
  reference.

``--cpus 1`` pins the process (and its subprocesses) to one CPU before JAX starts, so that both
sides run single-threaded: on a machine shared with other jobs this gives stable ratios.
Frame counts are rounded to whole chunks of simulate's default chunking (a partial last chunk
would be computed in full and discarded).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
from _machine import cpu_model

K, TAU = 5e-5, 0.537e-3
GAMMA = K * TAU
W, DT = 0.5 * TAU, 1.0 * TAU
CHUNK_BUDGET = 1 << 22  # simulate's default: about 4 M substep-trajectories per chunk
CHUNK_BUDGET_EXACT_FRAMES = 1 << 26  # ... and 2^26 / 2 frame-trajectories for exact_frames


def numpy_reference(n_traj, n_frames, n_sub, dtype, seed=0):
    """Same algorithm as method='exact' in units of sigma and tau (positions returned in sigma)."""
    rng = np.random.default_rng(seed)
    a, r = W / TAU, DT / TAU
    h = a / n_sub
    c, s = np.exp(-h), np.sqrt(-np.expm1(-2 * h))
    cd, sd = np.exp(-(r - a)), np.sqrt(-np.expm1(-2 * (r - a)))
    w = np.full(n_sub + 1, 1.0 / n_sub)
    w[0] = w[-1] = 0.5 / n_sub
    c, s, cd, sd = (dtype(v) for v in (c, s, cd, sd))
    w = w.astype(dtype)
    x = rng.standard_normal(n_traj, dtype=dtype)
    out = np.empty((n_frames, n_traj), dtype=dtype)
    for f in range(n_frames):
        z = rng.standard_normal((n_sub + 1, n_traj), dtype=dtype)
        acc = w[0] * x
        for i in range(n_sub):
            x = c * x + s * z[i]
            acc += w[i + 1] * x
        out[f] = acc
        x = cd * x + sd * z[n_sub]
    return out


def _clock(fn):
    c, t = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t, time.process_time() - c


def _chunk(n_traj, rows, total, budget=CHUNK_BUDGET):
    return max(1, min(total, budget // (n_traj * rows)))


def _whole_chunks(n_traj, rows, wanted, budget=CHUNK_BUDGET):
    """`wanted` frames rounded to whole default chunks (at least one chunk)."""
    ch = _chunk(n_traj, rows, 1 << 30, budget)
    if wanted <= ch:
        return wanted
    return ch * max(1, round(wanted / ch))


def _rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _peak_mb():
    """Peak RSS of this process image (VmHWM). Not ``getrusage().ru_maxrss``: Linux keeps that
    across fork + exec, so a child started from a large parent reports the parent's size."""
    with open("/proc/self/status") as f:
        return next(int(ln.split()[1]) for ln in f if ln.startswith("VmHWM")) / 1024


def _status_mb(field):
    with open("/proc/self/status") as f:
        return next(int(ln.split()[1]) for ln in f if ln.startswith(field + ":")) / 1024


class _AnonPoll:
    """Largest anonymous (private, not file-backed) resident memory seen, polled every 2 ms in a
    thread: the kernel keeps no high-water mark for RssAnon. File-backed pages (RssFile) are
    jaxlib's shared-library code mapped from disk, shared between processes and reclaimable."""

    def __init__(self):
        import threading

        self.peak, self._stop = _status_mb("RssAnon"), threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self):
        while not self._stop.wait(0.002):
            self.peak = max(self.peak, _status_mb("RssAnon"))

    def stop(self):
        self._stop.set()
        self._t.join()
        return max(self.peak, _status_mb("RssAnon"))


def memory_child(n_traj, n_frames, n_sub, cache):
    poll = _AnonPoll()
    stages = {"python + numpy": _rss_mb()}
    import jax

    stages["import jax"] = _rss_mb()
    jax.devices()
    stages["backend start"] = _rss_mb()
    import blurtrap
    from blurtrap.simulate import simulate

    blurtrap.enable_x64()
    if cache:
        blurtrap.enable_compilation_cache(cache)
    stages["import blurtrap"] = _rss_mb()
    args = dict(substeps=n_sub, n_traces=n_traj)
    warm = _chunk(n_traj, n_sub + 1, n_frames)  # compiles the chunk shape of the real run
    jax.block_until_ready(simulate(K, GAMMA, W, DT, warm, key=jax.random.key(0), **args))
    stages["first call (compile)"] = _rss_mb()
    base_peak = _peak_mb()
    t0 = time.perf_counter()
    x = jax.block_until_ready(simulate(K, GAMMA, W, DT, n_frames, key=jax.random.key(1), **args))
    el = time.perf_counter() - t0
    stages["after the run"] = _rss_mb()
    peak = _peak_mb()
    anon = {"peak_anon_MB": poll.stop(), "file_MB": _status_mb("RssFile")}
    print(json.dumps({"stages_MB": stages, "peak_MB": peak, **anon,
                      "run_increment_MB": peak - max(base_peak, stages["first call (compile)"]),
                      "seconds": el, "output_MB": x.nbytes / 2**20,
                      "substeps": n_traj * n_frames * (n_sub + 1)}))


def numpy_memory_child(n_traj, n_frames, n_sub):
    base = _rss_mb()
    t0 = time.perf_counter()
    x = numpy_reference(n_traj, n_frames, n_sub, np.float64)
    el = time.perf_counter() - t0
    print(json.dumps({"base_MB": base, "peak_MB": _peak_mb(), "run_increment_MB": _peak_mb() - base,
                      "seconds": el, "output_MB": x.nbytes / 2**20}))


def _child(args, extra_env=None):
    env = dict(os.environ, **(extra_env or {}))
    out = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True,
                         check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _machine():
    return f"{cpu_model()}, {os.cpu_count()} CPUs, affinity {sorted(os.sched_getaffinity(0))}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--substeps", type=int, default=100, help="substeps per exposure")
    ap.add_argument("--quick", action="store_true", help="smaller sizes")
    ap.add_argument("--sizes", type=int, nargs="*", default=[1, 64, 1024, 16384])
    ap.add_argument("--dtypes", nargs="*", default=["float64", "float32"])
    ap.add_argument("--repeat", type=int, default=3, help="interleaved repeats (best kept)")
    ap.add_argument("--cpus", type=int, default=0, help="pin to this many CPUs (0: all)")
    ap.add_argument("--memory-substeps", type=float, default=1e8)
    ap.add_argument("--no-memory", action="store_true")
    ap.add_argument("--json", help="also write the results to this file")
    ap.add_argument("--_memory_child", nargs=3, type=int, help=argparse.SUPPRESS)
    ap.add_argument("--_numpy_memory_child", nargs=3, type=int, help=argparse.SUPPRESS)
    ap.add_argument("--_cache", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._memory_child:
        memory_child(*args._memory_child, args._cache)
        return
    if args._numpy_memory_child:
        numpy_memory_child(*args._numpy_memory_child)
        return
    if args.cpus:
        os.sched_setaffinity(0, sorted(os.sched_getaffinity(0))[: args.cpus])

    import jax

    import blurtrap
    from blurtrap.simulate import simulate

    blurtrap.enable_x64()
    n_sub = args.substeps
    rows = n_sub + 1  # normals per frame: exposure substeps + one exact dead step
    budget = 2e6 if args.quick else 1e7  # trajectory-substeps per timed substep run
    info = {"date": datetime.datetime.now().isoformat(timespec="seconds"),
            "machine": _machine(), "python": platform.python_version(),
            "jax": jax.__version__, "numpy": np.__version__, "devices": str(jax.devices()),
            "loadavg_start": os.getloadavg()}
    print(f"# blurtrap.simulate benchmark {info}", flush=True)

    def jax_call(n, n_frames, dtype, method, seed):
        kw = {"substeps": n_sub} if method == "exact" else {}
        return jax.block_until_ready(
            simulate(K, GAMMA, W, DT, n_frames, key=jax.random.key(seed), n_traces=n,
                     method=method, dtype=dtype, **kw))

    rows_out = []
    for dname in args.dtypes:
        dtype = np.dtype(dname).type
        for n in args.sizes:
            n_frames = max(4, int(budget / (n * rows)))
            if n == 1:
                n_frames = min(n_frames, 2000)
            n_frames = _whole_chunks(n, rows, n_frames)
            nf_f = _whole_chunks(n, 2, 50 * n_frames, CHUNK_BUDGET_EXACT_FRAMES)  # exact_frames: 50x the frames
            work = n * n_frames * rows
            first = _clock(lambda: jax_call(n, n_frames, dtype, "exact", 0))[0]
            first_f = _clock(lambda: jax_call(n, nf_f, dtype, "exact_frames", 0))[0]
            best = {k: (np.inf, np.inf) for k in ("numpy", "jax", "frames")}
            for rep in range(args.repeat):
                for key, fn in (
                    ("numpy", lambda: numpy_reference(n, n_frames, n_sub, dtype, seed=rep)),
                    ("jax", lambda: jax_call(n, n_frames, dtype, "exact", rep + 1)),
                    ("frames", lambda: jax_call(n, nf_f, dtype, "exact_frames", rep + 1)),
                ):
                    w, c = _clock(fn)
                    best[key] = (min(best[key][0], w), min(best[key][1], c))
            (t_np, c_np), (t_jx, c_jx), (t_f, c_f) = best["numpy"], best["jax"], best["frames"]
            fr_sub = n * n_frames / t_jx
            fr_f = n * nf_f / t_f
            row = dict(dtype=dname, N=n, frames=n_frames, frames_exact_frames=nf_f,
                       numpy_substeps_per_s=work / t_np, jax_substeps_per_s=work / t_jx,
                       speedup=t_np / t_jx, speedup_cpu_time=c_np / c_jx,
                       compile_s=first - t_jx, compile_exact_frames_s=first_f - t_f,
                       frames_per_s_substep=fr_sub, frames_per_s_exact_frames=fr_f,
                       exact_frames_vs_substep=fr_f / fr_sub,
                       exact_frames_vs_substep_cpu_time=(n * nf_f / c_f) / (n * n_frames / c_jx),
                       exact_frames_vs_numpy_frames=fr_f / (n * n_frames / t_np),
                       loadavg=os.getloadavg()[0])
            rows_out.append(row)
            print(f"{dname:8s} N={n:6d} frames={n_frames:5d}  numpy {work / t_np:9.3e}  "
                  f"simulate {work / t_jx:9.3e} substeps/s  x{t_np / t_jx:5.2f} "
                  f"(cpu-time x{c_np / c_jx:5.2f})  compile {first - t_jx:4.1f} s  | "
                  f"exact_frames {fr_f:9.3e} frames/s = x{fr_f / fr_sub:5.1f} substep "
                  f"(cpu-time x{row['exact_frames_vs_substep_cpu_time']:5.1f}), "
                  f"compile {first_f - t_f:4.1f} s  [load {row['loadavg']:.1f}]", flush=True)
    result = {"info": info, "rows": rows_out}
    if not args.no_memory:
        n_traj = 1024
        n_frames = _whole_chunks(n_traj, rows, int(round(args.memory_substeps / (n_traj * rows))))
        margs = [str(n_traj), str(n_frames), str(n_sub)]
        mem = _child(["--_memory_child", *margs])
        cache = tempfile.mkdtemp(prefix="blurtrap_bench_cache_")
        try:
            _child(["--_memory_child", *margs, "--_cache", cache])  # fill the compile cache
            mem_cached = _child(["--_memory_child", *margs, "--_cache", cache])
        finally:
            shutil.rmtree(cache, ignore_errors=True)
        mem_np = _child(["--_numpy_memory_child", *margs])
        result["memory"] = {"fresh": mem, "warm_compile_cache": mem_cached, "numpy": mem_np}
        for label, m in (("fresh process", mem), ("warm compile cache", mem_cached)):
            st = ", ".join(f"{k} {v:.0f}" for k, v in m["stages_MB"].items())
            print(f"memory ({label}), {m['substeps']:.3g} substeps: peak RSS "
                  f"{m['peak_MB']:.0f} MB (anonymous {m['peak_anon_MB']:.0f} MB, file-backed "
                  f"jaxlib code {m['file_MB']:.0f} MB); run increment {m['run_increment_MB']:.0f} MB; "
                  f"output {m['output_MB']:.1f} MB; {m['seconds']:.1f} s; RSS by stage [MB]: {st}")
        print(f"memory (NumPy reference, same run): peak RSS {mem_np['peak_MB']:.0f} MB, increment "
              f"{mem_np['run_increment_MB']:.0f} MB over {mem_np['base_MB']:.0f} MB, "
              f"{mem_np['seconds']:.1f} s")
    info["loadavg_end"] = os.getloadavg()
    print(json.dumps(result))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
