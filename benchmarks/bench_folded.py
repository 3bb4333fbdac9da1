"""Wall time and peak memory of ``calibrate(model="standard+detector_filter")``, this
checkout against an older one (before the folded spectrum went on log-spaced nodes), same data.

Not a test. Run:  python benchmarks/bench_folded.py [--old-rev main] [--new N ...]
[--old N:CALLS ...] [--out FILE]

Data: one photodiode-like recording of N samples (W = 10 ns, 100 kHz, k = 0.05 pN/nm,
1.53 um bead radius, eps 2 nm) seen through a silicon diode (8 kHz, alpha 0.4), simulated once
here and given to both versions. Each (version, N) runs in a fresh Python process (no
persistent compilation cache) that calls ``calibrate`` CALLS times (the first call compiles)
and reports the wall time of each call, the process's peak resident memory (``ru_maxrss``)
after loading the data and after each call, and the estimates (k, gamma, f3db with their
standard errors) so that the two versions can be compared. The old version is a detached
``git worktree`` of ``--old-rev`` imported through ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _child import child_script, run_child  # noqa: E402
from bench_diagnose import old_checkout  # noqa: E402

K = 5e-5
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6

CHILD = child_script('res = bt.calibrate(recs, model="standard+detector_filter")',
                     '{"est": {n: [float(v), float(e)] for n, v, e in zip(res.param_names, res.values, res.errors)}}')


def simulate(n: int, path: pathlib.Path):
    import jax

    import blurtrap as bt
    from blurtrap.simulate import PhotodiodeFilter

    bt.enable_x64()
    x = np.asarray(bt.simulate(K, GAMMA, 1e-8, 1e-5, n, key=jax.random.key(20),
                               method="exact_frames", tracking_std=2e-9,
                               injections=(PhotodiodeFilter(8e3, 0.4),)))[0]
    np.savez(path, x=x[None, :], dt=np.asarray([1e-5]), w=np.asarray([1e-8]))


def fmt(res) -> str:
    if "error" in res:
        return f"error: {res['error'][:300]}"
    calls = "; ".join(f"call {i + 1}: {c['s']:.1f} s, peak {c['rss_gib']:.2f} GiB"
                      for i, c in enumerate(res["calls"]))
    est = res["calls"][-1]["est"]
    lab = (f"k = {est['k'][0] * 1e3:.6f} +- {est['k'][1] * 1e3:.6f} pN/nm, "
           f"gamma = {est['gamma'][0]:.6e} +- {est['gamma'][1]:.1e} kg/s, "
           f"f3db = {est['f3db'][0]:.2f} +- {est['f3db'][1]:.2f} Hz")
    return f"{calls} (data loaded: {res['rss_data_gib']:.2f} GiB); {lab}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old-rev", default="main", help="git revision of the old code")
    ap.add_argument("--old-path", default=None, help="an existing checkout of the old code")
    ap.add_argument("--new", nargs="*", default=["131072:2", "1048576:2"], help="N:CALLS")
    ap.add_argument("--old", nargs="*", default=["131072:2"],
                    help="N:CALLS (the old code at 2^20 needs ~8x its 2^17 memory, ~23 GiB)")
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--out", default=None, help="append JSON lines here")
    args = ap.parse_args()
    made = not args.old_path and bool(args.old)
    old_root = pathlib.Path(args.old_path) if args.old_path else (
        old_checkout(args.old_rev) if args.old else None)
    try:
        run_plan(args, old_root)
    finally:
        if made and old_root is not None:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(old_root)], capture_output=True)


def run_plan(args, old_root):
    import jax
    from _machine import cpu_model

    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                         capture_output=True, text=True).stdout.strip()
    print(f"# {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"jax {jax.__version__}, numpy {np.__version__}; new = {rev}, old = "
          f"{(args.old_path or args.old_rev) if args.old else 'not run'}", flush=True)
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="bench-folded-"))
    plan = [("new", c) for c in args.new] + [("old", c) for c in args.old]
    for version, spec in plan:
        n, _, calls = spec.partition(":")
        data = tmp / f"n{n}.npz"
        if not data.exists():
            simulate(int(n), data)
        root = ROOT if version == "new" else old_root
        load = os.getloadavg()[0]
        res = run_child(root, data, int(calls or 1), args.timeout, CHILD)
        res.update(version=version, n=int(n), load=load)
        print(f"{version:3s} N = {n:>8s} load {load:4.1f}: {fmt(res)}", flush=True)
        if args.out:
            with open(args.out, "a") as fh:
                fh.write(json.dumps(res) + "\n")


if __name__ == "__main__":
    main()
