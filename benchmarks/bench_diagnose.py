"""Wall time and peak memory of `diagnose`, this checkout against an older one, same data.

Not a test. Run:  python benchmarks/bench_diagnose.py [--old-rev main] [--out FILE]

Cases (data simulated once here and given to both versions):

- ``camera5``: 5 camera recordings of 65 536 frames, W = dt, 1500 fps, k = 0.05 pN/nm,
  1.53 um bead radius (gamma as in the tests), eps 2 nm;
- ``series5``: the same at 5 exposures W = (0.1, 0.25, 0.5, 0.75, 1) dt, where the
  exposure_kernel candidate (a folded model without closed form) is tried;
- ``diode<N>``: one photodiode-like recording of N samples, W = 10 ns, 100 kHz, same trap,
  where detector_filter and hydrodynamics are tried;
- ``filter<N>``: the same seen through a silicon diode (8 kHz, alpha 0.4): detector_filter is
  significant and refitted with errors by ``calibrate`` (not in the default plan).

Each (version, case) runs in a fresh Python process (no persistent compilation cache) that
calls ``diagnose`` twice and reports the wall time of each call and the process's peak
resident memory (``ru_maxrss``) after loading the data and after each call. The old version
is a detached ``git worktree`` of ``--old-rev`` imported through ``PYTHONPATH``.
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

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _child import child_script, run_child  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
DT_CAM = 1 / 1500
K = 5e-5
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6

CHILD = child_script(
    "res = bt.diagnose(recs)",
    '{"adequate": bool(res.adequate), "ranking": [[c.effect, c.delta_loglik, '
    'bool(c.significant)] for c in res.ranking]}')


def simulate_case(name: str, path: pathlib.Path):
    import jax

    import blurtrap as bt

    bt.enable_x64()
    if name in ("camera5", "series5"):
        fr = [1.0] * 5 if name == "camera5" else [0.1, 0.25, 0.5, 0.75, 1.0]
        ws = [f * DT_CAM for f in fr]
        xs = [np.asarray(bt.simulate(K, GAMMA, w, DT_CAM, 65536, key=jax.random.key(10 + i),
                                     method="exact_frames", tracking_std=2e-9))[0]
              for i, w in enumerate(ws)]
        dts = [DT_CAM] * 5
    else:
        from blurtrap.simulate import PhotodiodeFilter

        filt = name.startswith("filter")
        n = int(name.removeprefix("filter" if filt else "diode"))
        inj = (PhotodiodeFilter(8e3, 0.4),) if filt else ()
        xs = [np.asarray(bt.simulate(K, GAMMA, 1e-8, 1e-5, n, key=jax.random.key(20),
                                     method="exact_frames", tracking_std=2e-9,
                                     injections=inj))[0]]
        ws, dts = [1e-8], [1e-5]
    np.savez(path, x=np.stack(xs), dt=np.asarray(dts), w=np.asarray(ws))


def old_checkout(rev: str) -> pathlib.Path:
    where = pathlib.Path(tempfile.mkdtemp(prefix="blurtrap-old-")) / "src"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(where), rev],
                   check=True, capture_output=True)
    return where


def fmt(res) -> str:
    if "error" in res:
        return f"error: {res['error'][:200]}"
    calls = "; ".join(f"call {i + 1}: {c['s']:.1f} s, peak {c['rss_gib']:.2f} GiB"
                      for i, c in enumerate(res["calls"]))
    return f"{calls} (data loaded: {res['rss_data_gib']:.2f} GiB)"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old-rev", default="main", help="git revision of the old code")
    ap.add_argument("--old-path", default=None, help="an existing checkout of the old code")
    ap.add_argument("--new", nargs="*", default=["camera5", "series5", "diode262144",
                                                 "diode524288", "diode1048576"])
    ap.add_argument("--old", nargs="*", default=["camera5:2", "series5:1", "diode65536:2",
                                                 "diode131072:1", "diode262144:1"],
                    help="CASE:CALLS run with the old code (a full 2^20 run of the old code "
                    "needs 12-18 GB and ~10 min per call)")
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--out", default=None, help="append JSON lines here")
    args = ap.parse_args()
    made = not args.old_path and bool(args.old)
    old_root = pathlib.Path(args.old_path) if args.old_path else (
        old_checkout(args.old_rev) if args.old else None)
    try:
        run_plan(args, old_root)
    finally:
        if made and old_root is not None:  # the worktree this run added
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(old_root)], capture_output=True)


def run_plan(args, old_root):
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                         capture_output=True, text=True).stdout.strip()
    import jax

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _machine import cpu_model

    print(f"# {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"jax {jax.__version__}, numpy {np.__version__}; new = {rev}, old = "
          f"{(args.old_path or args.old_rev) if args.old else 'not run'}; "
          f"load {os.getloadavg()[0]:.1f}")
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="bench-diagnose-"))
    plan = [("new", c, 2) for c in args.new]
    plan += [("old", c.split(":")[0], int(c.split(":")[1]) if ":" in c else 1)
             for c in args.old]
    for version, case, calls in plan:
        data = tmp / f"{case}.npz"
        if not data.exists():
            simulate_case(case, data)
        root = ROOT if version == "new" else old_root
        assert root is not None
        load = os.getloadavg()[0]
        res = run_child(root, data, calls, args.timeout, CHILD)
        res.update(version=version, case=case, load=load)
        print(f"{version:3s} {case:12s} load {load:4.1f}: {fmt(res)}", flush=True)
        if args.out:
            with open(args.out, "a") as fh:
                fh.write(json.dumps(res) + "\n")


if __name__ == "__main__":
    main()
