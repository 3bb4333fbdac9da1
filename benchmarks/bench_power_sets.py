"""Extra seconds a new set of laser powers costs in a process that has calibrated one set.

``calibrate(recordings, k="per_power")`` names its stiffness parameters by the powers
(``k[P=12 mW]``); the names are static fields of the parameter layout. Until session 27
they compared as plain tuples, so a second trap at other powers (the same number of
recordings, frames and parameters) compiled every fit program again; since then they
compare by structure (``_problems.Labels``) and the compiled programs are reused. In one
fresh process per variant this script calibrates a first set (compiles), then a second set
at other powers (timed) and a third at the first powers again (warm, timed), for the
Whittle, blocked-PSD and exact likelihoods (3 recordings of 4096 frames, k per power,
its 95 % intervals included). ``--plain`` gives the layout plain tuple names (the old
behaviour) in the same tree.

Run: ``python benchmarks/bench_power_sets.py``.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

_CHILD = r"""
import json, math, sys, time, numpy as np
from scipy.signal import lfilter
import blurtrap as bt
plain, kw = json.loads(sys.argv[1])
if plain:
    from blurtrap.inference import _problems
    _problems.Labels.__eq__ = tuple.__eq__
    _problems.Labels.__ne__ = tuple.__ne__
    _problems.Labels.__hash__ = tuple.__hash__
KT, GAMMA, DT = 1.380649e-23 * 295.0, 2.68e-8, 1 / 1500

def recs(powers, seed):
    rng, out = np.random.default_rng(seed), []
    for p in powers:
        k = 5e-5 * p / 0.02
        rho, sig = math.exp(-DT * k / GAMMA), math.sqrt(KT / k)
        x = lfilter([1.0], [1.0, -rho], rng.standard_normal(4096) * sig * math.sqrt(1 - rho**2))
        out.append(bt.Recording(x + 1e-9 * rng.standard_normal(4096), frame_interval=DT,
                                exposure=DT / 2, laser_power=p, temperature=295.0))
    return out

def fit(powers, seed):
    t = time.perf_counter()
    res = bt.calibrate(recs(powers, seed), k="per_power", **kw)
    res.intervals
    return time.perf_counter() - t

first = fit((0.01, 0.02, 0.04), 1)
new = fit((0.012, 0.025, 0.05), 2)
warm = fit((0.01, 0.02, 0.04), 3)
print(json.dumps({"first": first, "new_powers": new, "warm": warm}))
"""

CASES = {"whittle": {"likelihood": "whittle"}, "psd": {"method": "psd", "n_blocks": 4},
         "exact": {"likelihood": "exact"}}


def main() -> None:
    import jax
    import numpy as np

    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, python "
          f"{platform.python_version()}, jax {jax.__version__}, numpy {np.__version__}")
    print("| likelihood | names | first set [s] | new powers [s] | warm [s] | new - warm [s] |")
    print("|---|---|---|---|---|---|")
    for name, kw in CASES.items():
        for plain in (True, False):
            out = subprocess.run([sys.executable, "-c", _CHILD, json.dumps([plain, kw])],
                                 capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"| {name} | {'plain tuples' if plain else 'Labels'} | {r['first']:.2f} | "
                  f"{r['new_powers']:.2f} | {r['warm']:.2f} | {r['new_powers'] - r['warm']:.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
