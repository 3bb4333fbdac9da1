"""Numba reference for the simulator throughput, next to the NumPy reference of bench_simulate.py.

Not a test. Run with an interpreter that has numba (the peer venv):

    /work/peervenv/bin/python benchmarks/bench_numba_reference.py [--sizes 1 64 1024]
                                                                 [--substeps 100] [--repeat 3]

Any other interpreter re-runs this script with ``BLURTRAP_PEER_PYTHON`` (default
``/work/peervenv/bin/python``) when numba does not import, and exits 0 with the reason when
neither has numba (so ``run_all.sh`` can list it unconditionally).

Same algorithm as ``numpy_reference`` in ``bench_simulate.py`` (imported from there, run in
this process): exact Ornstein-Uhlenbeck substeps in units of sigma and tau, exposure averaged
in the loop with trapezoid weights, one exact dead-time step per frame, float64, W = tau/2,
dt = tau, ``--substeps`` substeps per exposure (n_sub + 1 normals per frame). The numba kernel
loops over trajectories and frames with the state in a register and draws its normals in the
loop (``np.random.standard_normal()`` inside ``@njit``, numba's own generator), one thread.

Reported per N: trajectory-substeps/s = N x frames x (n_sub + 1) / best wall time (and the
process-CPU-time version), for numba and for the NumPy reference in the same process, and
their ratio. Before timing, the kernel's arithmetic is checked against a NumPy loop on the
same normals (a variant of the kernel that takes the normals as input; agreement to 1e-12),
and the in-loop-RNG kernel's frame variance is compared with the NumPy reference's.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import platform
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent


def _reexec_or_skip(reason: str) -> None:
    peer = os.environ.get("BLURTRAP_PEER_PYTHON", "/work/peervenv/bin/python")
    if (peer and pathlib.Path(peer).exists()
            and os.path.abspath(peer) != os.path.abspath(sys.executable)
            and not os.environ.get("_BLURTRAP_NUMBA_REEXEC")):
        print(f"numba not importable here ({reason}); re-running with {peer}", flush=True)
        env = dict(os.environ, _BLURTRAP_NUMBA_REEXEC="1")
        sys.exit(subprocess.run([peer, __file__, *sys.argv[1:]], env=env).returncode)
    print(f"SKIPPED: numba not importable ({reason}) and no other interpreter "
          "(set BLURTRAP_PEER_PYTHON to a venv with numba)")
    sys.exit(0)


try:
    import numba
    import numpy as np
except ImportError as exc:  # pragma: no cover - depends on the interpreter
    _reexec_or_skip(repr(exc))

sys.path.insert(0, str(HERE))
from _machine import cpu_model  # noqa: E402
from bench_simulate import DT, TAU, W, numpy_reference  # noqa: E402


def _coefficients(n_sub):
    a, r = W / TAU, DT / TAU
    h = a / n_sub
    w = np.full(n_sub + 1, 1.0 / n_sub)
    w[0] = w[-1] = 0.5 / n_sub
    return (np.exp(-h), np.sqrt(-np.expm1(-2 * h)), np.exp(-(r - a)),
            np.sqrt(-np.expm1(-2 * (r - a))), w)


@numba.njit(cache=False)
def _seed(seed):
    np.random.seed(seed)


@numba.njit(cache=False)
def numba_kernel(n_traj, n_frames, n_sub, c, s, cd, sd, w):
    out = np.empty((n_frames, n_traj))
    for j in range(n_traj):
        x = np.random.standard_normal()
        for f in range(n_frames):
            acc = w[0] * x
            for i in range(n_sub):
                x = c * x + s * np.random.standard_normal()
                acc += w[i + 1] * x
            out[f, j] = acc
            x = cd * x + sd * np.random.standard_normal()
    return out


@numba.njit(cache=False)
def numba_kernel_given(x0, z, c, s, cd, sd, w):
    """The kernel's arithmetic on given normals z[frame, substep + dead step, trajectory]."""
    n_frames, rows, n_traj = z.shape
    n_sub = rows - 1
    out = np.empty((n_frames, n_traj))
    for j in range(n_traj):
        x = x0[j]
        for f in range(n_frames):
            acc = w[0] * x
            for i in range(n_sub):
                x = c * x + s * z[f, i, j]
                acc += w[i + 1] * x
            out[f, j] = acc
            x = cd * x + sd * z[f, n_sub, j]
    return out


def numpy_given(x0, z, c, s, cd, sd, w):
    x = x0.copy()
    n_frames, rows, _ = z.shape
    out = np.empty((n_frames, x.size))
    for f in range(n_frames):
        acc = w[0] * x
        for i in range(rows - 1):
            x = c * x + s * z[f, i]
            acc = acc + w[i + 1] * x
        out[f] = acc
        x = cd * x + sd * z[f, rows - 1]
    return out


def _clock(fn):
    c, t = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t, time.process_time() - c


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024])
    ap.add_argument("--substeps", type=int, default=100, help="substeps per exposure")
    ap.add_argument("--budget", type=float, default=1e7,
                    help="trajectory-substeps per timed run (bench_simulate: 1e7, --quick 2e6)")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved repeats (best kept)")
    a = ap.parse_args(argv)
    n_sub, rows = a.substeps, a.substeps + 1
    c, s, cd, sd, w = _coefficients(n_sub)
    cpu = cpu_model()
    print(f"# bench_numba_reference {datetime.datetime.now().isoformat(timespec='seconds')}; "
          f"CPU {cpu}, {os.cpu_count()} cores; Python {platform.python_version()} "
          f"({sys.executable}), numba {numba.__version__}, numpy {np.__version__}; float64, "
          f"{n_sub} substeps/exposure + 1 dead step; load average {os.getloadavg()[0]:.1f}",
          flush=True)

    # arithmetic check on the same normals (also compiles the kernels)
    rng = np.random.default_rng(1)
    z = rng.standard_normal((7, rows, 5))
    x0 = rng.standard_normal(5)
    diff = np.max(np.abs(numba_kernel_given(x0, z, c, s, cd, sd, w)
                         - numpy_given(x0, z, c, s, cd, sd, w)))
    if not diff < 1e-12:
        raise SystemExit(f"numba kernel disagrees with the NumPy loop on the same normals: "
                         f"max |diff| = {diff:.3g} (expected < 1e-12)")
    t0 = time.perf_counter()
    _seed(0)
    numba_kernel(2, 3, n_sub, c, s, cd, sd, w)
    compile_s = time.perf_counter() - t0
    # in-loop RNG: frame variance against the NumPy reference's (same distribution)
    vn = numba_kernel(256, 64, n_sub, c, s, cd, sd, w).var()
    vr = numpy_reference(256, 64, n_sub, np.float64, seed=3).var()
    print(f"check: max |numba - numpy| on the same normals {diff:.1e}; frame variance "
          f"numba {vn:.4f} vs numpy reference {vr:.4f} (sigma^2 units, 16 384 frames each); "
          f"compile {compile_s:.2f} s", flush=True)

    print("\n| N | frames | numpy substeps/s (wall) | numba substeps/s (wall) | numpy substeps/s "
          "(CPU time) | numba substeps/s (CPU time) | numba / numpy (wall) | numba / numpy "
          "(CPU time) | load |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in a.sizes:
        n_frames = max(4, int(a.budget / (n * rows)))
        if n == 1:
            n_frames = min(n_frames, 2000)
        work = n * n_frames * rows
        best = {k: (np.inf, np.inf) for k in ("numpy", "numba")}
        for rep in range(a.repeat):
            for key, fn in (
                    ("numpy", lambda: numpy_reference(n, n_frames, n_sub, np.float64, seed=rep)),
                    ("numba", lambda: numba_kernel(n, n_frames, n_sub, c, s, cd, sd, w))):
                wt, ct = _clock(fn)
                best[key] = (min(best[key][0], wt), min(best[key][1], ct))
        (t_np, c_np), (t_nb, c_nb) = best["numpy"], best["numba"]
        print(f"| {n} | {n_frames} | {work / t_np:.3e} | {work / t_nb:.3e} | "
              f"{work / c_np:.3e} | {work / c_nb:.3e} | "
              f"{t_np / t_nb:.2f} | {c_np / c_nb:.2f} | {os.getloadavg()[0]:.1f} |", flush=True)


if __name__ == "__main__":
    main()
