"""Profile intervals of a joint per-power exact fit: ``calibrate(recs, k="per_power",
likelihood="exact")`` on four recordings at different laser powers, frame intervals and
lengths (65 536 + 32 768 + 16 384 + 8192 = 122 880 frames; camera frames W = 0.5-1 dt,
tracking noise 1.5-6 nm, k = 3e-6..1.3e-4 N/m, gamma ~1e-8 N s/m, 295 K), then the time of
``res.intervals`` (the Wald-path check and the profiles of the parameters that need one).

    taskset -c 1 python benchmarks/bench_joint_profile.py --seeds 5,7,14
    PYTHONPATH=<base worktree> taskset -c 1 python benchmarks/bench_joint_profile.py ...

Frames from tests/_circulant.py (exact frame law, numpy only). Prints one line per seed
and, with ``--out``, the intervals as JSON (to compare two trees).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from _circulant import circulant_frames  # noqa: E402

import blurtrap as bt  # noqa: E402

LENGTHS = (1 << 16, 1 << 15, 1 << 14, 1 << 13)


def joint_set(seed):
    """Four recordings at four of eight laser powers, k = c P, random frame intervals
    (1/500-1/8000 s), exposures (0.5-1 dt), lengths (a permutation of LENGTHS)."""
    rng = np.random.default_rng(1000 + seed)
    powers = np.sort(rng.choice([0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.6, 0.8], 4, replace=False))
    c = 10 ** rng.uniform(-4.3, -3.7)  # k / P [N/m/W]
    gamma = 10 ** rng.uniform(-8.3, -7.7)
    eps = rng.uniform(1.5e-9, 6e-9)
    lengths = rng.permutation(LENGTHS)
    dts = rng.choice([1 / 500, 1 / 1000, 1 / 2000, 1 / 4000, 1 / 8000], 4)
    wfrac = rng.choice([1.0, 1.0, 0.5, 0.9], 4)
    recs = []
    for j in range(4):
        dt, w = float(dts[j]), float(wfrac[j] * dts[j])
        x = circulant_frames(c * powers[j], gamma, w, dt, eps * eps, int(lengths[j]), seed * 10 + j)
        recs.append(bt.Recording(x, frame_interval=dt, exposure=w, temperature=295.0,
                                 laser_power=float(powers[j])))
    return recs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="5,7,14")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    out = {}
    for seed in map(int, a.seeds.split(",")):
        t = time.perf_counter()
        res = bt.calibrate(joint_set(seed), k="per_power", likelihood="exact")
        t_fit = time.perf_counter() - t
        t = time.perf_counter()
        ivs = res.intervals
        t_iv = time.perf_counter() - t
        kinds = res.interval_kinds
        n_prof = sum(k == "profile" for k in kinds.values())
        print(f"seed {seed}: fit {t_fit:.1f} s, intervals {t_iv:.1f} s "
              f"(profiled {n_prof}/{len(kinds)})", flush=True)
        out[seed] = {n: [*map(float, ivs[n]), kinds[n]] for n in ivs}
    if a.out:
        pathlib.Path(a.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
