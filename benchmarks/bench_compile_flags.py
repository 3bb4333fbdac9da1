"""What ``faster_compilation`` (``--xla_cpu_use_fusion_emitters=false``) changes: the first
call (compilation + one run) and the warm run time of blurtrap's main programs, XLA's default
flags against the flag, each in its own fresh process with no persistent compilation cache.

Workloads (camera 1500 fps, k = 0.05 pN/nm, 1.53 um bead, eps 2 nm, W = dt unless said):
``calibrate`` Whittle on 65 536 frames, ``calibrate`` exact on 4096 frames, ``simulate``
(Brownian-dynamics scan and exact frames) 1000 x 4096, ``diagnose`` on 65 536 frames and on a
photodiode record (100 kHz, W = 10 ns, 65 536 samples: the folded screening fits),
``calibrate_batch`` 200 x 4096. The modes alternate (default, flag, default, flag, ...) so
that a change in the machine's load falls on both; per mode the median over the repeats.
The estimates of both modes are printed side by side (largest relative difference).

Run: ``python benchmarks/bench_compile_flags.py [--repeats 2]``
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _machine import cpu_model  # noqa: E402

FLAG = "--xla_cpu_use_fusion_emitters=false"

_CHILD = r"""
import json, time
import jax, numpy as np
import blurtrap as bt
bt.enable_x64()
gamma = 6 * np.pi * 0.00093 * 1.53e-6
out = {}
def timed(name, f, warm=3):
    t0 = time.perf_counter(); value = f(); first = time.perf_counter() - t0
    ts = []
    for _ in range(warm):
        t0 = time.perf_counter(); f(); ts.append(time.perf_counter() - t0)
    out[name] = {"first": first, "warm": min(ts), "value": value}
x = np.asarray(bt.simulate(5e-5, gamma, 1/1500, 1/1500, 65536, key=jax.random.key(0),
                           method="exact_frames", tracking_std=2e-9))[0]
rec = bt.Recording(x, frame_interval=1/1500, exposure=1/1500)
r4 = bt.Recording(x[:4096], frame_interval=1/1500, exposure=1/1500)
def fit(r, **kw):
    res = bt.calibrate(r, **kw)
    return [float(res.params[p]) for p in ("k", "gamma", "tracking_var")]
timed("calibrate, Whittle, 65 536 frames", lambda: fit(rec))
timed("calibrate, exact, 4096 frames", lambda: fit(r4, likelihood="exact"))
timed("simulate, Brownian dynamics, 1000 x 4096", lambda: float(np.asarray(bt.simulate(
    5e-5, gamma, 1/1500, 1/1500, 4096, key=jax.random.key(1), n_traces=1000)).std()))
timed("simulate, exact frames, 1000 x 4096", lambda: float(np.asarray(bt.simulate(
    5e-5, gamma, 1/1500, 1/1500, 4096, key=jax.random.key(1), n_traces=1000,
    method="exact_frames")).std()))
def diag(r):
    d = bt.diagnose(r)
    return [float(c.delta_loglik) for c in d.ranking if c.delta_loglik is not None]
timed("diagnose, camera, 65 536 frames", lambda: diag(rec), warm=2)
y = np.asarray(bt.simulate(5e-5, gamma, 1e-8, 1e-5, 65536, key=jax.random.key(20),
                           method="exact_frames", tracking_std=2e-9))[0]
timed("diagnose, photodiode, 65 536 samples",
      lambda: diag(bt.Recording(y, frame_interval=1e-5, exposure=1e-8)), warm=2)
xb = np.asarray(bt.simulate(5e-5, gamma, 1/1500, 1/1500, 4096, key=jax.random.key(2),
                            n_traces=200, method="exact_frames", tracking_std=2e-9))
def batch():
    b = bt.calibrate_batch(xb, frame_interval=1/1500, exposure=1/1500)
    return [float(v) for v in np.asarray(b["k"])[:20]]
timed("calibrate_batch, 200 x 4096", batch)
print("RESULT " + json.dumps(out))
"""


def run(flag: bool) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR", "BLURTRAP_CACHE_DIR")}
    env["PYTHONPATH"] = str(ROOT)
    if flag:
        env["XLA_FLAGS"] = FLAG
    out = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True,
                         cwd=ROOT, env=env, timeout=3600)
    if out.returncode != 0:
        raise SystemExit(out.stderr[-3000:])
    line = [s for s in out.stdout.splitlines() if s.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def _rel(a, b) -> float:
    a, b = _flat(a), _flat(b)
    if len(a) != len(b):
        return float("nan")
    return max((abs(x - y) / max(abs(x), 1e-300) for x, y in zip(a, b)), default=0.0)


def _flat(v):
    return [float(x) for x in (v if isinstance(v, list) else [v])]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    runs: dict[bool, list[dict]] = {False: [], True: []}
    for _ in range(args.repeats):
        for flag in (False, True):
            runs[flag].append(run(flag))
            print(f"done: {'flag' if flag else 'default'}", file=sys.stderr, flush=True)
    import jax

    print(f"Machine: {cpu_model()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"Python {platform.python_version()}, jax {jax.__version__}; "
          f"{args.repeats} processes per mode, medians.\n")
    print("| workload | first call, default / flag (ratio) | warm, default / flag (ratio) "
          "| estimates, largest rel. difference |")
    print("|---|---|---|---|")
    for name in runs[False][0]:
        d = {m: [r[name] for r in runs[m]] for m in (False, True)}
        first = [statistics.median(x["first"] for x in d[m]) for m in (False, True)]
        warm = [statistics.median(x["warm"] for x in d[m]) for m in (False, True)]
        diff = _rel(d[False][0]["value"], d[True][0]["value"])
        print(f"| {name} | {first[0]:.2f} / {first[1]:.2f} s ({first[0] / first[1]:.2f}x) "
              f"| {warm[0]:.3f} / {warm[1]:.3f} s ({warm[0] / warm[1]:.2f}x) | {diff:.1e} |")


if __name__ == "__main__":
    main()
