"""Profile-likelihood intervals and a new record length, for the exact and the irregular-time
likelihoods: seconds of ``calibrate`` and of reading ``result.intervals``, first call and
repeat, at 3000 frames and then 5000 frames (a new power-of-two bucket: 4096 -> 8192 padded
frames).

Data: a camera at 1500 fps, W = 0.1 dt, k = 0.02 pN/nm, 1.53 um bead in water, no tracking
error (eps^2 at or near its bound 0, so all three intervals are profiled), frames drawn from
the dense OU covariance at the frame times (``tests/_irregular_gen.py``, not blurtrap's
simulator); "irregular": a wandering clock, intervals dt (1 + 0.05 N(0, 1)), loaded with
``allow_irregular=True``. "extra at the new bucket" = first call at 5000 frames minus its
repeat. Each tree runs in its own fresh subprocess (no persistent compilation cache).

Run: ``python benchmarks/bench_intervals.py [--base DIR] [--kinds exact irregular]`` where
``DIR`` holds another tree of the package (e.g. ``git worktree add --detach DIR main``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

_CHILD = r"""
import json, sys, time, warnings
import numpy as np
sys.path.insert(0, sys.argv[2])
import _irregular_gen as gen
import blurtrap as bt
warnings.simplefilter("ignore")
kind = sys.argv[1]
DT = 1 / 1500; W = 0.1 * DT; GAMMA = 6 * np.pi * 0.00093 * 1.53e-6; K = 2e-5; T = 295.0
rng = np.random.default_rng(3)
if kind == "irregular":
    s = gen.clock("wander", 5000, DT, 0.05, rng)
    s = np.concatenate([[0.0], np.cumsum(np.maximum(np.diff(s), W))])
else:
    s = DT * np.arange(5000)
y = gen.frames(s, W, K, GAMMA, T, 0.0, rng)
def rec(n):
    if kind == "irregular":
        return bt.Recording(y[:n], frame_interval=float(np.median(np.diff(s[:n]))),
                            times=s[:n], exposure=W, allow_irregular=True)
    return bt.Recording(y[:n], frame_interval=DT, exposure=W)
rows = []
for n in (3000, 5000):
    for rep in ("first", "repeat"):
        t0 = time.perf_counter()
        res = bt.calibrate(rec(n), likelihood="exact")
        t1 = time.perf_counter()
        ivs, kinds = res.intervals, res.interval_kinds
        t2 = time.perf_counter()
        rows.append({"package": bt.__file__, "n": n, "call": rep, "fit": t1 - t0,
                     "intervals": t2 - t1,
                     "profiled": sorted(k for k, v in kinds.items() if v == "profile"),
                     "k_interval": [v / res.k for v in ivs["k"]]})
print(json.dumps(rows))
"""


def run(tree, kind):
    env = dict(os.environ, PYTHONPATH=str(tree))
    env.pop("BLURTRAP_TEST_CACHE_DIR", None)
    tests = str(Path(__file__).resolve().parents[1] / "tests")
    # cwd = the tree: ``python -c`` puts the working directory first on sys.path
    out = subprocess.run([sys.executable, "-c", _CHILD, kind, tests], env=env, check=True,
                         capture_output=True, text=True, cwd=str(tree))
    rows = json.loads(out.stdout.strip().splitlines()[-1])
    assert rows[0]["package"].startswith(str(Path(tree).resolve())), rows[0]["package"]
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="another tree of the package, run first")
    ap.add_argument("--kinds", nargs="+", default=["exact", "irregular"])
    a = ap.parse_args()
    here = Path(__file__).resolve().parents[1]
    trees = ([("base", a.base)] if a.base else []) + [("this tree", here)]
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}")
    print("| likelihood | tree | 3000: fit, intervals (first / repeat) | 5000: fit, intervals "
          "(first / repeat) | extra at the new bucket | k interval / k (5000) |")
    print("|---|---|---|---|---|---|")
    for kind in a.kinds:
        for name, tree in trees:
            r = run(tree, kind)
            cell = [f"{x['fit']:.2f} + {x['intervals']:.2f} s" for x in r]
            extra = (r[2]["fit"] + r[2]["intervals"]) - (r[3]["fit"] + r[3]["intervals"])
            ki = ", ".join(f"{v:.6f}" for v in r[3]["k_interval"])
            print(f"| {kind} | {name} | {cell[0]} / {cell[1]} | {cell[2]} / {cell[3]} | "
                  f"{extra:.2f} s | {ki} |", flush=True)


if __name__ == "__main__":
    main()
