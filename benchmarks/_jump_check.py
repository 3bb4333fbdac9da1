"""Profile-likelihood intervals with the one-step bound moves of the held fits
(``_profile.jump_atols``) vs without (all 0), on the same fits: recordings of 2000 frames,
alternately regular (exact likelihood; study_boundary's circulant-embedding sampler) and at
irregular times (wandering clock, tests/_irregular_gen.py), W = 0.1 dt, eps = 2 nm, k = 0.05
pN/nm, seed 21. Prints the largest end-point difference over the interval width and the
interval time with and without. Run: ``python benchmarks/_jump_check.py [N]`` (default 24)."""
import sys
import time
import warnings
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(_HERE), str(_HERE.parent / "tests")]
import _irregular_gen as gen  # noqa: E402
import study_boundary as sb  # noqa: E402

import blurtrap as bt  # noqa: E402
from blurtrap.inference import _profile  # noqa: E402

warnings.simplefilter("ignore")
orig = _profile.jump_atols


def off(*a):
    return orig(*a) * 0.0



rng = np.random.default_rng(21)
worst, n_cmp, times, bad = 0.0, 0, {True: 0.0, False: 0.0}, []
for i in range(int(sys.argv[1]) if len(sys.argv) > 1 else 24):
    kind = "irregular" if i % 2 else "exact"
    n = 2000
    if kind == "exact":
        c = sb.autocovariance(sb.K, sb.GAMMA, sb.W, sb.DT, sb.EPS2, n)
        y = sb.CirculantSampler(c).draw(rng, 1)[0]
        rec = bt.Recording(y, frame_interval=sb.DT, exposure=sb.W)
    else:
        s = gen.clock("wander", n, sb.DT, 0.05, rng)
        y = gen.frames(s, sb.W, sb.K, sb.GAMMA, sb.T, sb.EPS2, rng)
        rec = bt.Recording(y, frame_interval=float(np.median(np.diff(s))), times=s,
                           exposure=sb.W, allow_irregular=True)
    out = {}
    for jump in (True, False):
        _profile.jump_atols = orig if jump else off
        r = bt.calibrate(rec, method="likelihood", likelihood="exact")
        t0 = time.perf_counter()
        iv = r.intervals
        times[jump] += time.perf_counter() - t0
        out[jump] = (iv, r.interval_kinds, r.at_bounds)
    for name, (lo, hi) in out[False][0].items():
        a = out[True][0][name]
        scale = max(abs(hi - lo), 1e-300)
        d = max(abs(a[0] - lo), abs(a[1] - hi)) / scale
        n_cmp += 1
        worst = max(worst, d)
        if d > 1e-3:
            bad.append((i, kind, name, a, (lo, hi)))
    print(i, kind, out[True][2], f"worst so far {worst:.2e}", flush=True)
print("end points compared", n_cmp, "worst |diff| / interval width", worst, "times jump/no", times)
print("bad", bad)
