"""Old vs new (issue 16, "what must not change"): statistics and speed of two source trees.

Run:  python benchmarks/compare_redesign.py [--old PATH | --old-rev 6020907] [--cal-seeds 200]
          [--post-datasets 40] [--post-steps 800] [--diag control=10,drift=5,...]
          [--batch 1000] [--repeat 7] [--first-rounds 2] [--only stats|speed] [--out DIR]

Every measurement runs in child processes (``_redesign_worker.py``) whose ``PYTHONPATH`` is
one of the two trees ("old": ``--old`` or a ``git worktree`` of ``--old-rev`` made in a
temporary folder; "new": this checkout), so both are measured on this machine in one session.

1. Statistics on the *same* data: the old tree's simulator draws the data once (the keys of
   ``study_calibration.py``, ``study_posterior.py`` and ``study_diagnose.py``); the new tree
   draws them again and the two draws are compared (the simulator is part of what must not
   change); both trees then fit the old tree's draws with their public API:
   (a) default ``bt.calibrate`` (and ``bt.calibrate_batch``) on ``--cal-seeds`` recordings of
   65 536 frames per k (0.01, 0.05 pN/nm; W = dt = 1/1500 s, eps = 2 nm): bias, SD, SE/SD,
   95 % Wald coverage of k, gamma, eps^2 with Monte-Carlo errors; (b) ``bt.sample_posterior``
   (32 walkers, ``--post-steps`` steps) on ``--post-datasets`` recordings: 68 / 95 % credible
   interval coverage; (c) ``bt.diagnose`` on the scenarios of ``--diag`` (name=seeds):
   identification (or false-alarm) rates.
2. Speed: two timing servers (old, new) compile and warm up, then every case is timed
   interleaved (old then new, per repeat); median wall and CPU time and the median of the
   per-repeat ratios new/old. First calls (compilation included): ``--first-rounds`` fresh
   processes per tree, alternating old, new.

Writes ``DIR/compare_redesign.json`` and prints the markdown tables of RESULTS_redesign.md.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve().parent
NEW_TREE = HERE.parent
WORKER = HERE / "_redesign_worker.py"
sys.path.insert(0, str(HERE))

from _redesign_tables import (  # noqa: E402
    calib_table,
    diagnose_table,
    parity,
    posterior_table,
    speed_table,
)

DIAG = ("control=10,drift=5,drift_weak=5,tracking_noise=5,tracking_noise_weak=5,"
        "motion_blur=5,line_noise=5,line_noise_weak=5,anharmonicity=5,timing_jitter=5,"
        "power_offset=3,laser_heating=3,detector_filter=3")


def _env(tree, tag):
    env = dict(os.environ, PYTHONPATH=str(tree), REDESIGN_TAG=tag)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    return env


def job(tree, tag, *args):
    """Run one worker job to completion (niced); return its wall time."""
    t0 = time.perf_counter()
    subprocess.run(["nice", "-n", "10", sys.executable, str(WORKER), *map(str, args)],
                   env=_env(tree, tag), cwd=str(tree), check=True)
    return time.perf_counter() - t0


class Server:
    """A timing worker: JSON commands in, one JSON line out."""

    def __init__(self, tree, tag, d, n_batch):
        self.proc = subprocess.Popen(
            ["nice", "-n", "10", sys.executable, str(WORKER), "time", str(d), str(n_batch)],
            env=_env(tree, tag), cwd=str(tree), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            text=True)
        self.info = self._read()

    def _read(self):
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"timing worker exited with code {self.proc.wait()}")
        return json.loads(line)

    def ask(self, **cmd):
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self):
        self.proc.stdin.write(json.dumps({"op": "quit"}) + "\n")
        self.proc.stdin.flush()
        self.proc.wait()


INNER = {"calibrate": 10, "calibrate_keep": 10, "batch": 1, "sim_substep": 1, "sim_exact_frames": 1, "posterior": 1}


def speed(trees, d, n_batch, repeat):
    servers = {}
    for tag in ("old", "new"):  # one at a time: compilation is CPU heavy
        servers[tag] = Server(trees[tag], tag, d, n_batch)
    times = {}
    for r in range(repeat):
        for case, inner in INNER.items():
            for tag in (("old", "new") if r % 2 == 0 else ("new", "old")):
                t = servers[tag].ask(op="time", case=case, i=r * inner, inner=inner)
                times.setdefault(case, {}).setdefault(tag, []).append(t)
    info = {tag: s.info for tag, s in servers.items()}
    for s in servers.values():
        s.close()
    rows = {}
    for case, tt in times.items():
        for clock in ("t", "cpu"):
            old = [x[clock] for x in tt["old"]]
            new = [x[clock] for x in tt["new"]]
            ratios = [b / a for a, b in zip(old, new)]
            rows[f"{case}/{clock}"] = {"old": statistics.median(old),
                                       "new": statistics.median(new),
                                       "ratio": statistics.median(ratios),
                                       "lo": min(ratios), "hi": max(ratios), "n": len(ratios)}
    return {"rows": rows, "info": info, "raw": times}


def first_calls(trees, d, n_batch, rounds):
    out = {"old": [], "new": []}
    for _ in range(rounds):
        for tag in ("old", "new"):
            p = subprocess.run(["nice", "-n", "10", sys.executable, str(WORKER), "first", str(d),
                                str(n_batch)], env=_env(trees[tag], tag), cwd=str(trees[tag]),
                               check=True, capture_output=True, text=True)
            out[tag].append(json.loads(p.stdout.strip().splitlines()[-1]))
    return out


def stats(trees, d, a, res):
    gen_args = (a.cal_seeds, a.post_datasets, a.diag)
    res["wall_s"]["gen_old"] = job(trees["old"], "old", "gen", d, *gen_args)
    dn = d.parent / "new_draw"
    res["wall_s"]["gen_new"] = job(trees["new"], "new", "gen", dn, *gen_args)
    res["parity"] = parity(d, dn)
    shutil.rmtree(dn)
    for name, extra in (("calib", ()), ("posterior", (a.post_steps,)), ("diagnose", ())):
        for tag in ("old", "new"):
            res["wall_s"][f"{name}_{tag}"] = job(trees[tag], tag, name, d, *extra)
        res[name] = {tag: json.loads((d / f"{name}_{tag}.json").read_text())
                     for tag in ("old", "new")}


def _versions(tree):
    p = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"],
                       capture_output=True, text=True)
    return p.stdout.strip()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", help="source tree of the old code (default: a worktree)")
    ap.add_argument("--old-rev", default="6020907")
    ap.add_argument("--cal-seeds", type=int, default=200)
    ap.add_argument("--post-datasets", type=int, default=40)
    ap.add_argument("--post-steps", type=int, default=800)
    ap.add_argument("--diag", default=DIAG)
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--first-rounds", type=int, default=2)
    ap.add_argument("--only", choices=("stats", "speed"), default=None)
    ap.add_argument("--out", default="benchmarks/out/compare_redesign")
    a = ap.parse_args(argv)
    from _machine import cpu_model

    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        old = pathlib.Path(a.old) if a.old else pathlib.Path(tmp) / "old"
        if not a.old:
            subprocess.run(["git", "-C", str(NEW_TREE), "worktree", "add", "--detach", str(old),
                            a.old_rev], check=True, capture_output=True)
        trees = {"old": old, "new": NEW_TREE}
        d = pathlib.Path(tmp) / "data"
        res = {"argv": sys.argv, "old": _versions(old), "new": _versions(NEW_TREE),
               "machine": {"cpu": cpu_model(), "cpus": os.cpu_count(),
                           "python": platform.python_version(),
                           "load_start": os.getloadavg()},
               "wall_s": {}}
        try:
            if a.only in (None, "stats"):
                stats(trees, d, a, res)
            if a.only in (None, "speed"):
                if not (d / "calib.npy").exists():
                    res["wall_s"]["gen_old_speed"] = job(old, "old", "gen", d,
                                                         min(a.cal_seeds, 200), 0, "")
                res["speed"] = speed(trees, d, a.batch, a.repeat)
                res["first"] = first_calls(trees, d, a.batch, a.first_rounds)
        finally:
            if not a.old:
                subprocess.run(["git", "-C", str(NEW_TREE), "worktree", "remove", "--force",
                                str(old)], capture_output=True)
    import jax

    res["machine"].update(jax=jax.__version__, load_end=os.getloadavg(),
                          total_wall_s=time.perf_counter() - t_start)
    (out / "compare_redesign.json").write_text(json.dumps(res, indent=1, default=float))
    print(f"old = {res['old']}, new = {res['new']}; {res['machine']}")
    if "parity" in res:
        print("\n## Simulator: new draw vs old draw (same keys)\n")
        print(json.dumps(res["parity"]))
        print(calib_table(res["calib"]))
        print(posterior_table(res["posterior"]))
        print(diagnose_table(res["diagnose"]))
    if "speed" in res:
        print(speed_table(res["speed"], res["first"], a.batch, a.repeat))
    print(f"\nwall time per job [s]: {json.dumps(res['wall_s'])}")


if __name__ == "__main__":
    main()
