"""Extra seconds a recording of a new length costs in a process that has calibrated once.

``calibrate`` pads the periodogram ordinates (spectral fits) and the frames (exact
likelihood) to bucket lengths (``_problems.bucket_length``: powers of two by default),
so recordings of nearby lengths share compiled programs; the default Whittle fit runs in
fixed-size ordinate chunks with its Newton loop on the host (``inference/_chunked.py``;
models with effects too, by autodiff of each chunk's sum, ``_chunked.EFFECTS``), and the exact
likelihood's pass runs in fixed-size frame chunks (``inference/_exact_chunks.py``), so a new
length compiles none of their programs at all. In one fresh process per tree this
script calibrates a first recording (compiles), repeats it (warm time), then calibrates
``--count`` recordings of other lengths and reports, per new length, the time minus the warm
time of a recording of that size (the warm time is measured on each recording by a second
call). Two cases: 50 000-70 000 frames (default likelihood: Whittle) and 3000-5000 frames
with ``likelihood="exact"`` (``--cases 0,1``, the default), 40 000-1 100 000 frames
(Whittle, ``--cases 2``: many buckets), and a model with an effect, ``standard+drift``
(Whittle, the fused pass with drift added since fd297e8, autodiff before; 50 000-70 000
frames, ``--cases 3``). No persistent compilation cache is enabled.

Run: ``python benchmarks/bench_buckets.py [--base DIR] [--count 10]`` where ``DIR`` holds
another tree of the package (e.g. ``git worktree add --detach DIR main``); each tree runs in
its own subprocess with ``PYTHONPATH`` set to it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys

_CHILD = r"""
import json, sys, time, numpy as np, jax
import blurtrap as bt
lo, hi, count, kw, steps = json.loads(sys.argv[1])
if steps != "default":
    from blurtrap.inference import _problems
    _problems.BUCKET_STEPS = None if steps is None else tuple(steps)
DT = 1.0 / 1500.0
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6
rng = np.random.default_rng(0)
lengths = [int(n) for n in rng.integers(lo, hi, count + 1)]
key = jax.random.key(0)
y_all = np.asarray(bt.simulate(2e-5, GAMMA, DT, DT, hi, key=key, method="exact_frames",
                               tracking_std=2e-9), float).ravel()
def timed(n):
    rec = bt.Recording(y_all[:n], frame_interval=DT, exposure=DT)
    t0 = time.perf_counter(); r = bt.calibrate(rec, **kw); t1 = time.perf_counter()
    bt.calibrate(rec, **kw); t2 = time.perf_counter()
    return t1 - t0, t2 - t1, float(r.k)
first, warm0, _ = timed(lengths[0])
rows = [timed(n) for n in lengths[1:]]
print(json.dumps({"lengths": lengths, "first": first, "warm_first": warm0,
                  "new": [r[0] for r in rows], "warm": [r[1] for r in rows],
                  "k": [r[2] for r in rows], "jax": jax.__version__}))
"""

CASES = [("default (Whittle), 50 000-70 000 frames", 50_000, 70_000, {}),
         ("exact, 3000-5000 frames", 3000, 5000, {"likelihood": "exact"}),
         ("default (Whittle), 40 000-1 100 000 frames", 40_000, 1_100_000, {}),
         ("standard+drift (Whittle), 50 000-70 000 frames", 50_000, 70_000,
          {"model": "standard+drift"})]


def run_tree(path, lo, hi, count, kw, steps="default"):
    env = dict(os.environ, PYTHONPATH=path, JAX_ENABLE_X64="1")
    env.pop("BLURTRAP_TEST_CACHE_DIR", None)
    # cwd = the tree: ``python -c`` puts the working directory first on sys.path
    out = subprocess.run([sys.executable, "-c", _CHILD, json.dumps([lo, hi, count, kw, steps])],
                         env=env, capture_output=True, text=True, check=True, cwd=path)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="another tree of the package (the 'before')")
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--steps", default="1,1.25,1.5,1.75;1",
                    help="bucket step sets to compare, ';'-separated (e.g. '1' = powers of 2)")
    ap.add_argument("--cases", default="0,1",
                    help="which cases to run, comma-separated indices into: "
                    + "; ".join(f"{i} = {c[0]}" for i, c in enumerate(CASES)))
    args = ap.parse_args()
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    trees = ([("before", args.base, "default")] if args.base else []) + [
        (f"after, steps {st}", here, [float(v) for v in st.split(",")])
        for st in args.steps.split(";")]
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from _machine import cpu_model

    print(f"# {cpu_model()}, {os.cpu_count()} CPUs, Python {platform.python_version()}",
          flush=True)
    for label, lo, hi, kw in [CASES[int(i)] for i in args.cases.split(",")]:
        for tree, path, steps in trees:
            r = run_tree(path, lo, hi, args.count, kw, steps)
            extra = [n - w for n, w in zip(r["new"], r["warm"])]
            print(f"{label} | {tree} | jax {r['jax']} | first {r['first']:.2f} s | warm "
                  f"{r['warm_first']:.3f} s | new lengths: extra mean {sum(extra) / len(extra):.2f} s,"
                  f" max {max(extra):.2f} s, total {sum(extra):.1f} s")
            print("   lengths", r["lengths"][1:], "extra s", [round(e, 2) for e in extra],
                  "warm s", [round(w, 3) for w in r["warm"]], flush=True)


if __name__ == "__main__":
    main()
