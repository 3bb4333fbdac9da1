"""Benchmark of blurtrap.simulate against a plain NumPy reference of the same algorithm.

Not a test. Run:  python benchmarks/bench_simulate.py [--quick] [--substeps 100]

Reports, in one process:
- trajectory-substeps/s of the substep simulator (method="exact") and of the NumPy reference
  (exact OU substeps, trapezoid exposure accumulation, vectorised over trajectories, one block of
  normals per frame) for N = 1, 64, 1024, 16384 trajectories, float64 and float32;
- compile time of the first call, separately;
- frames/s of method="exact_frames" against the substep simulator at the same N;
- peak resident memory of a 1e8 trajectory-substep run (measured in a fresh subprocess with
  resource.getrusage, minus the same subprocess's baseline after import and warm-up).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

K, TAU = 5e-5, 0.537e-3
GAMMA = K * TAU
W, DT = 0.5 * TAU, 1.0 * TAU


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


def _time(fn, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run_jax(n_traj, n_frames, n_sub, dtype, method="exact", unroll=1, normal_dtype=None):
    import jax

    from blurtrap.simulate import simulate

    kw = {"substeps": n_sub} if method != "exact_frames" else {}

    def call(seed):
        return jax.block_until_ready(
            simulate(K, GAMMA, W, DT, n_frames, key=jax.random.key(seed), n_traces=n_traj,
                     method=method, dtype=dtype, unroll=unroll,
                     normal_dtype=normal_dtype, **kw)
        )

    t0 = time.perf_counter()
    call(0)
    first = time.perf_counter() - t0
    steady = _time(lambda: call(1))
    return first - steady, steady


def memory_child(n_traj, n_frames, n_sub):
    import jax

    import blurtrap
    from blurtrap.simulate import simulate

    blurtrap.enable_x64()
    args = dict(substeps=n_sub, n_traces=n_traj)
    jax.block_until_ready(simulate(K, GAMMA, W, DT, 4, key=jax.random.key(0), **args))
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    x = jax.block_until_ready(simulate(K, GAMMA, W, DT, n_frames, key=jax.random.key(1), **args))
    el = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"base_MB": base / 1024, "peak_MB": peak / 1024,
                      "delta_MB": (peak - base) / 1024, "seconds": el,
                      "output_MB": x.nbytes / 2**20}))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--substeps", type=int, default=100, help="substeps per exposure")
    ap.add_argument("--quick", action="store_true", help="smaller sizes")
    ap.add_argument("--sizes", type=int, nargs="*", default=[1, 64, 1024, 16384])
    ap.add_argument("--unroll", type=int, default=1)
    ap.add_argument("--memory-substeps", type=float, default=1e8)
    ap.add_argument("--_memory_child", nargs=3, type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._memory_child:
        memory_child(*args._memory_child)
        return

    import jax

    import blurtrap

    blurtrap.enable_x64()
    n_sub = args.substeps
    per_frame = n_sub + 1  # substeps per frame (exposure + one exact dead step)
    budget = 2e6 if args.quick else 1e7  # trajectory-substeps per timed run
    print(f"# blurtrap.simulate benchmark  jax {jax.__version__}  numpy {np.__version__}  "
          f"python {platform.python_version()}  devices {jax.devices()}")
    rows = []
    for dtype in (np.float64, np.float32):
        for n in args.sizes:
            n_frames = max(4, int(budget / (n * per_frame)))
            if n == 1:
                n_frames = min(n_frames, 2000)
            work = n * n_frames * per_frame
            t_np = _time(lambda: numpy_reference(n, n_frames, n_sub, dtype), repeat=2)
            comp, t_jx = run_jax(n, n_frames, n_sub, dtype, unroll=args.unroll)
            comp32, t_jx32 = run_jax(n, n_frames, n_sub, dtype, unroll=args.unroll,
                                     normal_dtype=np.float32)
            # exact_frames: 50x more frames so the per-call overhead is amortised
            nf_f = n_frames * 50
            comp_f, t_f = run_jax(n, nf_f, n_sub, dtype, method="exact_frames")
            t_f = t_f / 50
            row = dict(dtype=np.dtype(dtype).name, N=n, frames=n_frames,
                       numpy_substeps_per_s=work / t_np, jax_substeps_per_s=work / t_jx,
                       speedup=t_np / t_jx, compile_s=comp,
                       jax_f32normals_substeps_per_s=work / t_jx32,
                       speedup_f32normals=t_np / t_jx32,
                       frames_per_s_substep=n * n_frames / t_jx,
                       frames_per_s_exact_frames=n * n_frames / t_f,
                       exact_frames_speedup=t_jx / t_f, compile_exact_frames_s=comp_f)
            rows.append(row)
            print(f"{row['dtype']:8s} N={n:6d} frames={n_frames:6d}  numpy {work / t_np:10.3e} "
                  f"jax {work / t_jx:10.3e} substep/s  x{t_np / t_jx:5.2f} "
                  f"(f32 normals x{t_np / t_jx32:5.2f})  compile {comp:5.2f} s"
                  f"  | exact_frames {n * n_frames / t_f:10.3e} frames/s "
                  f"(x{t_jx / t_f:6.1f} vs substeps)", flush=True)
    # peak memory of a 1e8 trajectory-substep run, in a fresh process
    n_traj = 1024
    n_frames = int(round(args.memory_substeps / (n_traj * per_frame)))
    out = subprocess.run(
        [sys.executable, __file__, "--_memory_child", str(n_traj), str(n_frames), str(n_sub)],
        capture_output=True, text=True, check=True, env=dict(os.environ),
    )
    mem = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"memory: {n_traj} x {n_frames} frames x {per_frame} substeps = "
          f"{n_traj * n_frames * per_frame:.3g} substeps: peak RSS {mem['peak_MB']:.0f} MB, "
          f"growth over warm baseline {mem['delta_MB']:.0f} MB, output {mem['output_MB']:.1f} MB, "
          f"{mem['seconds']:.1f} s")
    print(json.dumps({"rows": rows, "memory": mem}))


if __name__ == "__main__":
    main()
