"""What a user waits for in ``bt.design``: the wall time of a sequence of design calls in a
fresh process (no persistent compilation cache, the CLI's and the tests' XLA flag), for this
checkout and for an older commit (a detached ``git worktree`` imported through
``PYTHONPATH``), alternating the two so that a change in the machine's load falls on both.

Sequence (1.53 um bead in water, 2 nm tracking error): (1) k = 0.5 pN/nm at 500 fps, 60 s
(no candidate identifies gamma: an error, after the whole search); (2) k = 0.05 pN/nm at
1500 fps, 60 s, laser powers 0.5/1/2; (3) k = 0.1 pN/nm, 65 536 frames per recording,
photon-limited noise; (4) k from 0.02 to 0.2 pN/nm, 65 536 frames per recording. The best
candidate's objective of (2) to (4) is printed for both trees; (2) is repeated warm.

Run: ``python benchmarks/bench_design_compile.py --old-rev HEAD~1 [--repeats 2]``
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
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _machine import cpu_model  # noqa: E402

_CHILD = r"""
import json, time
import blurtrap as bt
from blurtrap._config import faster_compilation
faster_compilation(); bt.enable_x64()
bead = {"radius": 1.53e-6, "tracking_std": 2e-9}
out = {"s": [], "objective": []}
t = time.perf_counter()
try:
    bt.design(k=5e-4, max_fps=500, total_time=60.0, **bead)
except ValueError:
    pass
out["s"].append(time.perf_counter() - t)
powers = {"k": 5e-5, "max_fps": 1500, "total_time": 60.0, "laser_powers": (0.5, 1, 2)}
for kw in (powers, {"k": 1e-4, "max_fps": 1500, "n_frames": 65536, "photon_limited": True},
           {"k": (2e-5, 2e-4), "max_fps": 1500, "n_frames": 65536}, powers):
    t = time.perf_counter()
    res = bt.design(**kw, **bead)
    out["s"].append(time.perf_counter() - t)
    out["objective"].append(res.best.objective)
print("RESULT " + json.dumps(out))
"""


def run(tree: pathlib.Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    proc = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True,
                          text=True, cwd=tree, timeout=900)
    line = [s for s in proc.stdout.splitlines() if s.startswith("RESULT ")]
    if not line:
        raise RuntimeError(proc.stderr[-2000:])
    return json.loads(line[0][7:])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old-rev", default="HEAD~1")
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        old = pathlib.Path(tmp) / "old"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old),
                        a.old_rev], check=True, capture_output=True)
        try:
            res = {"old": [], "new": []}
            for _ in range(a.repeats):
                res["old"].append(run(old))
                res["new"].append(run(ROOT))
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)],
                           check=False)
    import jax

    print(f"machine: {cpu_model()}, {os.cpu_count()} cores; Python "
          f"{platform.python_version()}, jax {jax.__version__}; old = {a.old_rev}")
    print("| call | old s (median) | new s (median) | old / new |")
    print("|---|---|---|---|")
    names = ("1: unidentified (first call)", "2: laser powers", "3: n_frames, photon-limited",
             "4: k range", "2 again (warm)")
    for i, name in enumerate(names):
        o = statistics.median(r["s"][i] for r in res["old"])
        n = statistics.median(r["s"][i] for r in res["new"])
        print(f"| {name} | {o:.1f} | {n:.1f} | {o / n:.1f} |")
    o = sum(statistics.median(r["s"][i] for r in res["old"]) for i in range(5))
    n = sum(statistics.median(r["s"][i] for r in res["new"]) for i in range(5))
    print(f"| all five | {o:.1f} | {n:.1f} | {o / n:.1f} |")
    for tag in ("old", "new"):
        print(tag, "best objectives (2), (3), (4), (2):", res[tag][0]["objective"])


if __name__ == "__main__":
    main()
