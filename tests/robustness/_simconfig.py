"""The simulate configuration shared by test_determinism.py and test_no_recompile.py, so that
both use the same compiled programs; the camera frames and recordings of the chunked-fit
tests (test_buckets.py, test_exact_chunks.py, test_held_chunks.py) and their check of
per-chunk passes against autodiff of the whole objective."""

import equinox as eqx
import jax
import numpy as np

import blurtrap as bt
from blurtrap.inference import _chunked
from blurtrap.inference._newton import SafeguardedNewton, autodiff_pass
from blurtrap.simulate import RandomWalkDrift, TimingJitter

DT = 1.0 / 1500.0  # camera: frame interval = exposure [s]
GAMMA = 6 * np.pi * 0.00093 * 1.53e-6  # 3.06 um bead in water [N s/m]


def sim(key, k=2e-5, gamma=GAMMA, exposure=DT, frame_interval=DT, tracking_std=2e-9, **kw):
    """Positions and time stamps as bytes: tracking noise, a random-walk drift and timing
    jitter, two traces of 512 frames."""
    args = dict(n_frames=512, n_traces=2, method="exact_frames", return_times=True,
                injections=(RandomWalkDrift(1e-15), TimingJitter(1e-6)))
    args.update(kw)
    pos, t = bt.simulate(k, gamma, exposure, frame_interval, key=key, tracking_std=tracking_std,
                         **args)
    return np.asarray(pos).tobytes() + np.asarray(t).tobytes()


def frames(n, seed, k=2e-5):
    """``n`` camera frames (W = dt = DT, eps 2 nm) from blurtrap's exact frame sampler."""
    x = bt.simulate(k, GAMMA, DT, DT, n, key=jax.random.key(seed), method="exact_frames",
                    tracking_std=2e-9)
    return np.asarray(x, dtype=np.float64).ravel()


def rec(y, **kw):
    return bt.Recording(y, frame_interval=DT, exposure=DT, **kw)


def assert_chunk_sums_are_the_whole(obj, reference, chunks, x, scale, a):
    """The pass of the objective ``obj`` summed over ``chunks`` equals JAX autodiff of the
    plain function ``reference`` on all of ``a`` at ``x`` (value, gradient and Hessian, to
    1e-11 of the largest entry)."""
    acc = _chunked._start(SafeguardedNewton(rtol=1e-9, atol=1e-9), x)[1]
    for c in chunks:
        acc = _chunked._chunk_pass(obj, x, scale, c, acc)
    ref = eqx.filter_jit(autodiff_pass(reference))(x, scale, a)
    for got, want in zip(acc, ref):
        got, want = np.asarray(got), np.asarray(want)
        assert np.max(np.abs(got - want)) < 1e-11 * np.max(np.abs(want)), (got, want)
