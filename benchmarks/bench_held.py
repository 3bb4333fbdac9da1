"""Seconds a fit with held parameters costs (``calibrate(..., fixed=...)``, ``friction=
"stokes"``), this tree against another one, same data.

Camera frames (1500 fps, W = dt, k = 0.05 pN/nm, 1.53 um bead, eps 2 nm, blurtrap's exact
frame sampler), ``n0`` frames (exact likelihood at 16 384) and another record of ``n1``
frames (a new bucket). In one fresh process per tree, in order: the unheld fit at ``n0``
(compiles the model), gamma held +- 3 % at ``n0`` twice (first / warm), gamma held at ``n1``
(first); then with the bead radius in the metadata, ``friction="stokes"`` (gamma held at
Stokes, the bead's hydrodynamics added where they matter) at ``n0`` and at ``n1``. Per call:
wall time, number and seconds of XLA compilations (``jax.monitoring``), and k, so the trees'
results can be compared. No persistent compilation cache.

Run: ``python benchmarks/bench_held.py [--base DIR] [--lengths 16384,20000]``
(``DIR``: e.g. ``git worktree add --detach DIR <rev>``); prefix ``taskset -c 0`` for one core.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform

from _child import COUNTED_HEAD, run_source

ROOT = pathlib.Path(__file__).resolve().parents[1]

_CHILD = COUNTED_HEAD + r"""
r = 1.53e-6
gamma = 6 * np.pi * 0.00093 * r
dt = 1 / 1500
ys = {n: np.asarray(bt.simulate(5e-5, gamma, dt, dt, n, key=jax.random.key(i),
                                method="exact_frames", tracking_std=2e-9))[0]
      for i, n in enumerate((n0, n1))}
meta = {"bead_radius_m": r, "viscosity_Pa_s": 0.00093}
held = {"gamma": (gamma, 0.03 * gamma)}
calls = [("unheld", n0, {}, {}), ("held", n0, {"fixed": held}, {}),
         ("held warm", n0, {"fixed": held}, {}), ("held", n1, {"fixed": held}, {}),
         ("stokes", n0, {"friction": "stokes"}, meta), ("stokes", n1, {"friction": "stokes"}, meta)]
rows = []
for label, n, kw, md in calls:
    rec = bt.Recording(ys[n], frame_interval=dt, exposure=dt, metadata=md)
    count[0], count[1] = 0, 0.0
    t0 = time.perf_counter()
    res = bt.calibrate(rec, **kw)
    rows.append({"call": label, "n": n, "s": time.perf_counter() - t0, "compiles": count[0],
                 "compile_s": count[1], "k": float(res.k), "k_err": float(res.k_err)})
print("RESULT " + json.dumps(rows))
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", help="another tree of the package (the 'before')")
    ap.add_argument("--lengths", default="16384,20000", help="n0,n1 (frames)")
    args = ap.parse_args()
    n0, n1 = (int(s) for s in args.lengths.split(","))
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"{len(os.sched_getaffinity(0))} of {os.cpu_count()} cpus, load "
          f"{os.getloadavg()[0]:.1f}; python {platform.python_version()}")
    trees = ([("base", pathlib.Path(args.base).resolve())] if args.base else []) + [
        ("this tree", ROOT)]
    print("| tree | call | frames | s | XLA compilations | compile s | k [pN/nm] |")
    print("|---|---|---|---|---|---|---|")
    for label, tree in trees:
        out = run_source(tree, _CHILD, (json.dumps([n0, n1]),))
        if isinstance(out, dict):
            print(f"| {label} | error: {out['error'][-300:]!r} |")
            continue
        for r in out:
            print(f"| {label} | {r['call']} | {r['n']} | {r['s']:.2f} | {r['compiles']} | "
                  f"{r['compile_s']:.2f} | {r['k'] * 1e3:.6g} +- {r['k_err'] * 1e3:.2g} |")


if __name__ == "__main__":
    main()
