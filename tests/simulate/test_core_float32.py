"""float32 keeps float32-relative accuracy when frames or substeps are short (dt/tau << 1).

The decay per step, c = exp(-h), rounded to float32 changes 1 - c by up to ~3e-8 / h relative,
which biases the stationary variance (-2e-4 at h = 1e-4, -1e-2 at 1e-6). The scans therefore
update by increments, x' = x + (c - 1) x + noise, with c - 1 = expm1(-h) computed in float64.
Checked deterministically: the simulator's own coefficients with the noise set to zero, started
at x = 1, must decay in float32 as in float64 over ~2 relaxation times."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from blurtrap.simulate import ExposureWindows, _core, simulate

K, TAU = 5e-5, 0.537e-3
NOISE = ("B", "istd", "sm", "cx", "sx")  # the noise coefficients of the three scans

CASES = {
    # one window: the innovations form; h = dt = 1e-4 tau, 20 000 frames
    "innovations": (1e-4, 20000, dict(method="exact_frames")),
    # a one-element ExposureWindows: the segment law
    "segment": (1e-4, 20000, dict(method="exact_frames")),
    # substeps of h = 5e-4 tau, 8 per frame
    "substeps": (4e-3, 500, dict(method="exact", substeps=8)),
}


def _decay(monkeypatch, case, dtype):
    r, n, kw = CASES[case]
    calls = []
    real = _core.run_chunk_jit
    monkeypatch.setattr(_core, "run_chunk_jit", lambda *a: calls.append(a) or real(*a))
    w = ExposureWindows([r * TAU]) if case == "segment" else r * TAU
    simulate(K, K * TAU, w, r * TAU, n, key=jax.random.key(0), n_traces=2, dtype=dtype, **kw)
    cfg, n_c, lead, P, fp, kf, kj, x, delta, f0 = calls[0]
    assert n_c >= n  # one chunk
    P = P._replace(**{name: jnp.zeros_like(v) for name, v in P._asdict().items()
                      if name in NOISE and v is not None})
    _, _, frames, _ = real(cfg, n_c, lead, P, fp, kf, kj, jnp.ones_like(x), delta, f0)
    return np.asarray(frames, np.float64).reshape(-1, n_c)[0, :n] / float(P.scale[0])


@pytest.mark.parametrize("case", list(CASES))
def test_float32_decay_follows_float64(monkeypatch, case):
    r = CASES[case][0]
    h = r / (8 if case == "substeps" else 1)
    # the test has power: float32(exp(-h)) is off by more than 1e-9 absolute
    assert abs(float(np.float32(np.exp(-h))) - np.exp(-h)) > 1e-9
    d64 = _decay(monkeypatch, case, jnp.float64)
    d32 = _decay(monkeypatch, case, jnp.float32)
    assert d64[-1] < 0.2  # ~2 relaxation times
    # by increments, float32 rounding accumulates like sqrt(steps) x 6e-8 <= 1e-5 here; the
    # rounded decay drifts like steps x |float32(c) - c| (2.6e-4 to 4.3e-4 measured)
    np.testing.assert_allclose(d32, d64, rtol=2e-5)


def test_float32_photodiode_system_decay_follows_float64():
    """The same for the exact photodiode system (PhotodiodeFilter), whose (x, z) transitions
    are stored minus the identity: exposure 1e-4 tau, dead time 1e-4 tau, filter corner at
    lam = 2 pi f_3dB tau = 3, noise set to zero, start (x, z) = (1, 1)."""
    from blurtrap.simulate import _linear

    lam, alpha, a, rd = [3.0], [0.3], [1e-4], [1e-4]
    coef = _linear.photodiode_coefficients(np.array(lam), np.array(alpha), np.array(a),
                                           np.array(rd))
    # the test has power: the float32 diagonal of the dead-time transition is off
    phi = coef["pd"][0, 0, 0] + 1.0
    assert abs(float(np.float32(phi)) - phi) > 1e-9
    n = 10000
    out = {}
    for dtype in ("float32", "float64"):
        c = {k: jnp.asarray(v if k not in ("le", "ld") else 0 * v, dtype=dtype)
             for k, v in coef.items()}
        s0 = jnp.ones((1, 2, 2), dtype)
        _, frames = _linear._chunk(n, dtype, c, s0, jax.random.key(0)[None], jnp.int32(0))
        out[dtype] = np.asarray(frames, np.float64)[0, 0]
    assert out["float64"][-1] < 0.2
    np.testing.assert_allclose(out["float32"], out["float64"], rtol=2e-5)
