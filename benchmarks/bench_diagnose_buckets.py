"""Extra seconds `diagnose` costs on a photodiode record of a new length (issue 19: "a new
length costs <= 1 s extra"), this tree against another one, same data.

One photodiode-like record (100 kHz, W = 10 ns, k = 0.05 pN/nm, 1.53 um bead, eps 2 nm,
blurtrap's exact frame sampler, seed 20), its first ``n0`` samples diagnosed twice (the first
call compiles, the second is the warm time), then its first ``n1`` samples (a new
power-of-two bucket) twice. Reported per tree: the four wall times, "extra at the new
bucket" = first - warm at ``n1``, the number of XLA compilations in each call
(``jax.monitoring`` backend-compile events) and their seconds at ``n1``, and the ranking
(effect, delta log-likelihood) of the last call, so that the two trees' verdicts can be
compared. Each tree runs in its own fresh process (cwd = the tree, no persistent
compilation cache). The candidates tried here include the folded models (detector_filter,
hydrodynamics), whose screening fits were compiled per padded length.

Run: ``python benchmarks/bench_diagnose_buckets.py [--base DIR] [--lengths 65536,140000]``
(``DIR``: e.g. ``git worktree add --detach DIR <rev>``).
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
y = np.asarray(bt.simulate(5e-5, 6 * np.pi * 0.00093 * 1.53e-6, 1e-8, 1e-5, max(n0, n1),
                           key=jax.random.key(20), method="exact_frames",
                           tracking_std=2e-9))[0]
rows = []
for n in (n0, n0, n1, n1):
    rec = bt.Recording(y[:n], frame_interval=1e-5, exposure=1e-8)
    count[0], count[1] = 0, 0.0
    t0 = time.perf_counter()
    res = bt.diagnose(rec)
    rows.append({"n": n, "s": time.perf_counter() - t0, "compiles": count[0], "compile_s": count[1]})
rank = [[c.effect, None if c.delta_loglik is None else round(float(c.delta_loglik), 3)]
        for c in res.ranking]
print("RESULT " + json.dumps({"rows": rows, "ranking": rank, "adequate": bool(res.adequate)}))
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", help="another tree of the package (the 'before')")
    ap.add_argument("--lengths", default="65536,140000", help="n0,n1 (samples)")
    args = ap.parse_args()
    n0, n1 = (int(s) for s in args.lengths.split(","))
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"load {os.getloadavg()[0]:.1f}; python {platform.python_version()}")
    trees = ([("base", pathlib.Path(args.base).resolve())] if args.base else []) + [
        ("this tree", ROOT)]
    print("| tree | n0 first / warm [s] | n1 first / warm [s] | extra at n1 [s] | "
          "XLA compilations (4 calls) | XLA compile s at n1 |")
    print("|---|---|---|---|---|---|")
    rankings = {}
    for label, tree in trees:
        out = run_source(tree, _CHILD, (json.dumps([n0, n1]),))
        if "error" in out:
            print(f"| {label} | error: {out['error'][-300:]!r} |")
            continue
        r = out["rows"]
        print(f"| {label} | {r[0]['s']:.2f} / {r[1]['s']:.2f} | {r[2]['s']:.2f} / "
              f"{r[3]['s']:.2f} | {r[2]['s'] - r[3]['s']:.2f} | "
              f"{' / '.join(str(x['compiles']) for x in r)} | {r[2]['compile_s']:.2f} |")
        rankings[label] = (out["adequate"], out["ranking"])
    for label, (adequate, rank) in rankings.items():
        print(f"{label}: adequate={adequate}, ranking {rank}")


if __name__ == "__main__":
    main()
