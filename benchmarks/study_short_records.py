"""Intervals of k from records only a few relaxation times long (issue 18: a fourth
independent pass found k's interval (nan, nan) in 4 of 5 fits at T = 10 tau).

Exact stationary camera frames by circulant embedding (tests/_circulant.py; numpy, not
blurtrap's simulator): k = 5e-7 N/m, gamma of a 1.53 um bead, W = dt = 1/1500 s (tau = 80
frames), eps = 2 nm, T = ``ntau`` relaxation times; ``calibrate`` with its defaults. Prints
how many fits were refused, the Wald coverage of k (estimate +- 1.96 SE), and per interval
kind (``result.interval_kinds``) how many of the 95 % intervals cover the truth.

Run: ``python benchmarks/study_short_records.py 10 100`` (T = 10 tau, 100 seeds; ~90 s on
one core), ``... 20 100``.
"""

from __future__ import annotations

import collections
import math
import pathlib
import sys
import warnings

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from _circulant import circulant_frames  # noqa: E402

import blurtrap as bt  # noqa: E402

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1 / 1500
K = 5e-7


def main(ntau: float, seeds: int) -> None:
    bt.enable_x64()
    warnings.filterwarnings("ignore")
    n = int(ntau * GAMMA / K / DT)
    covered, kinds = collections.Counter(), collections.Counter()
    wald = fitted = refused = 0
    for seed in range(seeds):
        x = circulant_frames(K, GAMMA, DT, DT, 4e-18, n, 1000 + seed, temperature=295.0)
        try:
            r = bt.calibrate(bt.Recording(x, frame_interval=DT, exposure=DT,
                                          temperature=295.0))
        except bt.FitError:
            refused += 1
            continue
        fitted += 1
        lo, hi = r.intervals["k"]
        kind = r.interval_kinds["k"]
        kinds[kind] += 1
        covered[kind] += lo <= K <= hi
        wald += abs(r.k - K) <= 1.96 * r.k_err
    print(f"T = {ntau:g} tau ({n} frames): fitted {fitted}, refused {refused}; Wald coverage "
          f"{wald / max(fitted, 1):.3f}; covered/fits by interval kind: "
          + ", ".join(f"{k}: {covered[k]}/{kinds[k]}" for k in kinds))


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 10.0,
         int(sys.argv[2]) if len(sys.argv) > 2 else 100)
