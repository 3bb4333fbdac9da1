"""Old vs new Newton fit (issue 16: the safeguarded Newton as an optimistix minimiser).

Run:  python benchmarks/bench_newton.py [--old PATH | --old-rev REV] [--repeat 7]
      [--inner 10] [--batch 200] [--datasets 20]

Two worker processes import blurtrap from two source trees: "old" (a ``git worktree`` of
``--old-rev``, default ``main``, made in a temporary folder unless ``--old`` names a tree) and
"new" (this checkout). Both get the same data (simulated once here and handed over in an
``.npz``), compile and warm up, and are then timed *interleaved*: for each repeat, old then
new on each case, so load changes on the shared machine hit both alike. Reported per case:
the median wall time over repeats of each tree and the ratio new/old (median of the
per-repeat ratios, and its min-max). Cases:

1. ``bt.calibrate`` (default: Whittle likelihood, the fused Newton pass) on 65 536 frames;
2. ``bt.calibrate_batch`` on ``--batch`` x 65 536 frames;
3. ``bt.calibrate`` on 4096 frames (the default there is the exact likelihood, fitted by the
   finite-difference-Hessian Newton, a Python loop with a host sync per iteration before).

Estimates: ``--datasets`` recordings of each length (65 536 and 4096 frames) calibrated by
both trees, plus the batch; the largest relative difference of k, gamma, eps^2 and of their
standard errors between old and new, and the largest difference in units of the standard
error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tempfile

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
NEW_TREE = HERE.parent
sys.path.insert(0, str(HERE))

DT = W = 1.0 / 1500.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
K = 5e-5
EPS = 2e-9

WORKER = r"""
import json, sys, time
import numpy as np
import jax
import blurtrap as bt
bt.enable_x64()
d = np.load(sys.argv[1])
long, short, batch = d["long"], d["short"], d["batch"]
DT = float(d["dt"])

def cal(y):
    return bt.calibrate(bt.Recording(y, frame_interval=DT, exposure=DT))

def run(case, i=0):
    if case == "calibrate":
        return cal(long[i % len(long)])
    if case == "exact":
        return cal(short[i % len(short)])
    return bt.calibrate_batch(batch, frame_interval=DT, exposure=DT)

first = {}
for case in ("calibrate", "exact", "batch"):  # compile and warm up
    for i in range(2):
        t0 = time.perf_counter()
        run(case, i)
        first.setdefault(case, time.perf_counter() - t0)
print(json.dumps({"ready": True, "jax": jax.__version__, "first": first}), flush=True)
for line in sys.stdin:
    cmd = json.loads(line)
    if cmd["op"] == "time":
        t0, c0 = time.perf_counter(), time.process_time()
        for j in range(cmd["inner"]):
            run(cmd["case"], cmd["i"] + j)
        out = {"t": (time.perf_counter() - t0) / cmd["inner"],
               "cpu": (time.process_time() - c0) / cmd["inner"]}
    elif cmd["op"] == "estimates":
        rows = []
        for set_ in (long, short):
            for y in set_:
                r = cal(y)
                rows.append([list(map(float, r.values)), list(map(float, r.errors))])
        b = run("batch")
        out = {"single": rows, "batch": [b.k.tolist(), b.gamma.tolist(),
                                         b.tracking_var.tolist(), b.k_err.tolist(),
                                         b.gamma_err.tolist(), b.tracking_var_err.tolist()],
               "status": b.status.tolist()}
    else:
        break
    print(json.dumps(out), flush=True)
"""


class Worker:
    def __init__(self, tree, data):
        env = dict(os.environ, PYTHONPATH=str(tree))
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER, data], cwd=str(tree),
                                     env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True)
        self.info = self._read()

    def _read(self):
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"worker exited with code {self.proc.wait()}")
        return json.loads(line)

    def ask(self, **cmd):
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self):
        self.proc.stdin.write(json.dumps({"op": "quit"}) + "\n")
        self.proc.stdin.flush()
        self.proc.wait()


def simulate(n_long, n_batch, seed=2026):
    import jax

    import blurtrap as bt

    bt.enable_x64()

    def sim(n_frames, n_traces, s):
        y = bt.simulate(K, GAMMA, W, DT, n_frames, key=jax.random.key(s),
                        method="exact_frames", tracking_std=EPS, n_traces=n_traces)
        return np.asarray(y, dtype=np.float64).reshape(n_traces, n_frames)

    return sim(65536, n_long, seed), sim(4096, n_long, seed + 1), sim(65536, n_batch, seed + 2)


def old_tree(args, tmp):
    if args.old:
        return pathlib.Path(args.old)
    path = pathlib.Path(tmp) / "old"
    subprocess.run(["git", "-C", str(NEW_TREE), "worktree", "add", "--detach", str(path),
                    args.old_rev], check=True, capture_output=True)
    return path


def timing(workers, cases, repeat, inner):
    """Interleaved: per repeat and case, old then new; single-record cases are timed as the
    mean of ``inner`` calls on different records."""
    times = {(c, clock): {"old": [], "new": []} for c in cases for clock in ("t", "cpu")}
    for r in range(repeat):
        for c in cases:
            n = 1 if c == "batch" else inner
            for name in ("old", "new"):
                t = workers[name].ask(op="time", case=c, i=r * n, inner=n)
                for clock in ("t", "cpu"):
                    times[c, clock][name].append(t[clock])
    rows = []
    for (c, clock), tt in times.items():
        old, new = tt["old"], tt["new"]
        ratios = [b / a for a, b in zip(old, new)]
        rows.append((c, clock, statistics.median(old), statistics.median(new),
                     statistics.median(ratios), min(new) / min(old), min(ratios), max(ratios)))
    return rows


def compare(est_old, est_new):
    """Largest relative differences of values and errors, and largest |diff| / SE."""
    vo = [np.asarray(r[0]) for r in est_old["single"]]
    vn = [np.asarray(r[0]) for r in est_new["single"]]
    eo = [np.asarray(r[1]) for r in est_old["single"]]
    en = [np.asarray(r[1]) for r in est_new["single"]]
    bo, bn = np.asarray(est_old["batch"]), np.asarray(est_new["batch"])
    vo.append(bo[:3].ravel())
    vn.append(bn[:3].ravel())
    eo.append(bo[3:].ravel())
    en.append(bn[3:].ravel())
    a, b, ea, eb = (np.concatenate(z) for z in (vo, vn, eo, en))
    fin = np.isfinite(a) & np.isfinite(b) & (a != 0)
    fin_e = np.isfinite(ea) & np.isfinite(eb) & (ea > 0)
    return {
        "values": int(fin.sum()),
        "max_rel_value": float(np.max(np.abs(b[fin] / a[fin] - 1))),
        "max_rel_error": float(np.max(np.abs(eb[fin_e] / ea[fin_e] - 1))),
        "max_diff_in_se": float(np.max(np.abs(b - a)[fin & fin_e] / ea[fin & fin_e])),
        "nan_mismatch": int(np.sum(np.isfinite(a) != np.isfinite(b))),
        "status_mismatch": int(sum(x != y for x, y in zip(est_old["status"],
                                                           est_new["status"]))),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", help="source tree of the old code (default: a worktree)")
    ap.add_argument("--old-rev", default="main")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--batch", type=int, default=200)
    ap.add_argument("--datasets", type=int, default=20)
    ap.add_argument("--inner", type=int, default=10,
                    help="calls per timing sample of the single-record cases")
    args = ap.parse_args(argv)
    from _machine import cpu_model

    with tempfile.TemporaryDirectory() as tmp:
        old = old_tree(args, tmp)
        try:
            rev = subprocess.run(["git", "-C", str(old), "rev-parse", "--short", "HEAD"],
                                 capture_output=True, text=True).stdout.strip()
            long, short, batch = simulate(args.datasets, args.batch)
            data = str(pathlib.Path(tmp) / "data.npz")
            np.savez(data, long=long, short=short, batch=batch, dt=DT)
            workers = {"old": Worker(old, data), "new": Worker(NEW_TREE, data)}
            rows = timing(workers, ("calibrate", "batch", "exact"), args.repeat,
                          args.inner)
            cmp = compare(workers["old"].ask(op="estimates"),
                          workers["new"].ask(op="estimates"))
            jax_version = workers["new"].info["jax"]
            first = {name: w.info["first"] for name, w in workers.items()}
            for w in workers.values():
                w.close()
        finally:
            if not args.old:
                subprocess.run(["git", "-C", str(NEW_TREE), "worktree", "remove", "--force",
                                str(old)], capture_output=True)
    import equinox
    import optimistix

    print(f"machine: {cpu_model()}, {os.cpu_count()} CPUs; Python {platform.python_version()}, "
          f"jax {jax_version}, equinox {equinox.__version__}, optimistix "
          f"{optimistix.__version__}; old = {rev}; load {os.getloadavg()[0]:.1f}")
    labels = {"calibrate": "calibrate, 65 536 frames (Whittle)",
              "batch": f"calibrate_batch, {args.batch} x 65 536",
              "exact": "calibrate, 4096 frames (exact likelihood)"}
    print(f"\n{args.repeat} interleaved repeats (single records: mean of {args.inner} calls "
          "each); wall time and process CPU time [s], medians over repeats\n")
    print("| case | clock | old | new | new/old: median of ratios | ratio of minima | "
          "ratio range |\n|---|---|---|---|---|---|---|")
    for c, clock, o, n, r, rmin, lo, hi in rows:
        print(f"| {labels[c]} | {'wall' if clock == 't' else 'CPU'} | {o:.4f} | {n:.4f} | "
              f"{r:.3f} | {rmin:.3f} | {lo:.3f}-{hi:.3f} |")
    print("\nfirst call in each worker (compilation included; one sample, not interleaved) "
          "[s]: " + ", ".join(f"{labels[c]}: old {first['old'][c]:.2f}, new "
                             f"{first['new'][c]:.2f}" for c in labels))
    print(f"\nestimates on {args.datasets} x 65 536 + {args.datasets} x 4096 recordings and "
          f"the {args.batch}-item batch ({cmp['values']} values): " + json.dumps(cmp))


if __name__ == "__main__":
    main()
