"""Host-side numpy twins of physics/periodogram formulas in calibrate: are they needed?

calibrate computes its start values (S(alpha) and rho B(alpha) inside ``moment_start``) and
the periodogram ordinates of every recording on the host. This script times numpy against
the package's JAX implementations (``physics.autocovariance_unchecked`` for S and rho B,
``inference._likelihood.block_periodogram`` for the periodogram), in float64:

1. S and rho B for one start value: numpy, eager JAX, one jitted JAX call (and its compile);
2. the periodogram: numpy, eager and jitted JAX, warm and on a record length not seen before
   (a new shape compiles the JAX primitives; numpy has nothing to compile);
3. with ``--base PATH`` (an export of the previous commit's tree): warm default ``calibrate``
   on 65 536 frames and its first call, this tree vs the base, in alternating subprocesses.

Run: ``python benchmarks/bench_host_twins.py [--n 65536] [--repeat 20] [--base DIR]``.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time

import numpy as np

_CALIBRATE = r"""
import math, time, warnings, numpy as np, jax
import blurtrap as bt
DT = 1.0 / 1500.0
rng = np.random.default_rng(0)
def ar1(n, rho):
    from scipy.signal import lfilter
    return lfilter([math.sqrt(1 - rho * rho)], [1, -rho], rng.standard_normal(n)) * 3e-8
rec = bt.Recording(ar1({n}, 0.8), frame_interval=DT, exposure=DT)
t0 = time.perf_counter(); bt.calibrate(rec); first = time.perf_counter() - t0
best = math.inf
for _ in range({rep}):
    t0 = time.perf_counter(); bt.calibrate(rec); best = min(best, time.perf_counter() - t0)
print(first, best)
"""


def _tmin(fn, rep):
    fn()
    best = math.inf
    for _ in range(rep):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _np_pgram(y, dt, nb):
    m = y.size // nb
    blocks = y[: m * nb].reshape(nb, m)
    blocks = blocks - blocks.mean(axis=1, keepdims=True)
    spec = np.fft.rfft(blocks, axis=1)[:, 1:]
    return (spec.real**2 + spec.imag**2).mean(axis=0) * dt / m


def _np_s_rhob(a, r):
    s = 1.0 - a / 3.0 + a * a / 12.0 - a**3 / 60.0 if a < 1e-3 else \
        2.0 / a * (1.0 + math.expm1(-a) / a)
    phi1 = 1.0 - a / 2.0 + a * a / 6.0 if a < 1e-6 else -math.expm1(-a) / a
    return s, phi1 * phi1 * math.exp(a - r)


def start_values(rep):
    import jax
    import jax.numpy as jnp

    from blurtrap.physics import autocovariance_unchecked

    tau, w, dt = 2e-3, 1e-3, 1e-3
    pair = jax.jit(lambda t, ww, d: autocovariance_unchecked(jnp.arange(2.0), 1.0, t, ww, d, 0.0))
    args = (np.float64(tau), np.float64(w), np.float64(dt))
    t0 = time.perf_counter()
    np.asarray(pair(*args))
    t_compile = time.perf_counter() - t0

    def eager():
        return np.asarray(autocovariance_unchecked(jnp.arange(2.0), 1.0, tau, w, dt, 0.0))

    t_np = _tmin(lambda: _np_s_rhob(w / tau, dt / tau), rep)
    t_eager = _tmin(eager, rep)
    t_jit = _tmin(lambda: np.asarray(pair(*args)).tolist(), rep)
    dev = np.max(np.abs(np.asarray(pair(*args)) / np.array(_np_s_rhob(w / tau, dt / tau)) - 1))
    print(f"S and rho B, one start value: numpy {t_np * 1e6:.2f} us, eager JAX "
          f"{t_eager * 1e6:.0f} us, jitted JAX {t_jit * 1e6:.1f} us (compile once "
          f"{t_compile * 1e3:.0f} ms); max rel. difference {dev:.1e}", flush=True)


def periodograms(n, rep):
    import jax
    import jax.numpy as jnp

    from blurtrap.inference._likelihood import block_periodogram

    jit_bp = jax.jit(block_periodogram, static_argnums=2)
    dt = 1e-3
    for nn in (n, n + 7):  # the second length is new to every compiled function
        y = np.random.default_rng(nn).standard_normal(nn)
        for nb in (1, 128):
            t0 = time.perf_counter()
            np.asarray(block_periodogram(jnp.asarray(y), dt, nb)[1])
            first_eager = time.perf_counter() - t0
            t0 = time.perf_counter()
            np.asarray(jit_bp(jnp.asarray(y), dt, nb)[1])
            first_jit = time.perf_counter() - t0
            t_np = _tmin(lambda: _np_pgram(y, dt, nb), rep)
            t_jit = _tmin(lambda: np.asarray(jit_bp(jnp.asarray(y), dt, nb)[1]), rep)
            dev = float(np.max(np.abs(np.asarray(jit_bp(jnp.asarray(y), dt, nb)[1])
                                      / _np_pgram(y, dt, nb) - 1)))
            print(f"periodogram N={nn} n_blocks={nb:3d}: warm numpy {t_np * 1e3:.2f} ms, "
                  f"jitted JAX {t_jit * 1e3:.2f} ms; first call eager JAX "
                  f"{first_eager * 1e3:.0f} ms, jitted JAX {first_jit * 1e3:.0f} ms, numpy 0 "
                  f"(nothing to compile); max rel. difference {dev:.1e}", flush=True)


def calibrate_vs_base(base, n, rep, rounds):
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    res = {"this tree": [], "base": []}
    for _ in range(rounds):
        for label, root in (("base", base), ("this tree", here)):
            env = dict(os.environ, PYTHONPATH=root)
            out = subprocess.run([sys.executable, "-c", _CALIBRATE.format(n=n, rep=rep)],
                                 capture_output=True, text=True, check=True, env=env,
                                 cwd="/tmp")
            res[label].append(tuple(float(v) for v in out.stdout.split()))
    for label, vals in res.items():
        first = min(v[0] for v in vals)
        warm = min(v[1] for v in vals)
        print(f"default calibrate, {n} frames, {label}: warm {warm * 1e3:.2f} ms (min of "
              f"{rep} x {rounds} processes), first call {first:.2f} s (min of {rounds})")
    ratio = min(v[1] for v in res["this tree"]) / min(v[1] for v in res["base"])
    first = min(v[0] for v in res["this tree"]) / min(v[0] for v in res["base"])
    print(f"this tree / base: warm {ratio:.3f}, first call {first:.3f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=65536)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--base", help="tree of the previous commit (for the calibrate timing)")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    print(f"# host twins, N = {a.n}, min of {a.repeat} warm calls; load average "
          f"{os.getloadavg()[0]:.1f}; {jax.devices()[0].platform}", flush=True)
    start_values(a.repeat)
    periodograms(a.n, a.repeat)
    if a.base:
        calibrate_vs_base(a.base, a.n, a.repeat, a.rounds)


if __name__ == "__main__":
    main()
