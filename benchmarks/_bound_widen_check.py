"""The errors of exact-likelihood fits with eps^2 at its bound, with and without the widened
difference step of ``_bound_errors.unconstrained_cov`` (``_FD_WIDEN_PASSES`` 8 vs 0): 60
datasets of 4096 frames from study_boundary's circulant-embedding sampler (W = 0.1 dt, eps =
2 nm, k = 0.05 pN/nm), seed 11. Prints how many fits end at the bound and in how many the
k error changed (old/new ratio). Run: ``python benchmarks/_bound_widen_check.py``."""
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import study_boundary as sb  # noqa: E402

import blurtrap as bt  # noqa: E402
from blurtrap.inference import _bound_errors as be  # noqa: E402

warnings.simplefilter("ignore")
c = sb.autocovariance(sb.K, sb.GAMMA, sb.W, sb.DT, sb.EPS2, 4096)
smp = sb.CirculantSampler(c)
rng = np.random.default_rng(11)
ys = smp.draw(rng, 60)
n_at = 0
changed = []
for i, y in enumerate(ys):
    rec = bt.Recording(y, frame_interval=sb.DT, exposure=sb.W)
    out = {}
    for passes in (8, 0):
        be._FD_WIDEN_PASSES = passes
        r = bt.calibrate(rec, method="likelihood", likelihood="exact")
        out[passes] = r
    if out[8].at_bounds:
        n_at += 1
        a, b = out[8], out[0]
        rel = abs(a.k_err / b.k_err - 1)
        changed.append((rel, b.k_err / a.k_err))
print("datasets", len(ys), "at bound", n_at)
ch = [x for x in changed if x[0] > 1e-3]
print("errors changed by > 0.1 %:", len(ch), "ratios old/new k_err:", [round(x[1], 3) for x in ch])
