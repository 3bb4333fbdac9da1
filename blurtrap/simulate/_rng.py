"""The simulator's random numbers: counter-mode Threefry-2x32 and Box-Muller.

Random numbers
--------------
The thermal normals of frame ``f`` depend only on the grid point's key and on ``f`` (so results
do not depend on the chunking): counter-mode Threefry-2x32 (20 rounds: the hash of
``jax.random``'s default generator, bit for bit, see :func:`threefry2x32`) keyed by 64 bits
drawn once per call from the grid point's key, with counter words ``(f, i)``, followed by the
Box-Muller transform: rows ``2j`` and ``2j + 1`` are ``r cos(theta)`` and ``r sin(theta)`` of
pair ``j``, ``r = sqrt(-2 log u)``, ``theta = 2 pi v`` (up to a fixed offset).

- float64: ``u`` has 52 random bits (``u`` in ``(0, 1]``, radius up to 8.5 sigma), ``v`` 31
  bits; two Threefry blocks per pair. ``log`` is our own (exponent split + atanh series, within
  4 ulp) because XLA's float64 ``log`` costs ~3 ns on CPU.
- float32: ``u`` has 23 bits (radius up to 5.6 sigma), ``v`` 24 significant bits; one block
  per pair.

``sin``/``cos`` are Taylor polynomials on ``[-pi/4, pi/4]`` after the quadrant split, accurate
to the dtype's rounding.

Why not ``jax.random.normal``: on CPU its float64 normals cost ~20 ns each (an inverse-erf
transform, and a rolled Threefry loop that XLA does not fuse) against ~5 ns here; NumPy's
float64 ziggurat costs ~10 ns. Two XLA CPU behaviours shape the code: a value used by two
fusions is recomputed in each (so a Box-Muller pair's bits would be hashed twice), and gathering
the cos and sin halves into one array makes a slow scalar loop. Hence each frame's
``(r, theta)`` are computed one frame ahead and carried through the frame scan (loop state is
always materialised, exactly once), and the substep scan consumes rows in pairs. In float32
one Threefry block gives both ``r`` and ``theta``; carried as two arrays, each would be computed
by its own fusion, hashing twice, so they are carried as one complex64 array ``r + i t``
(12 % faster, same numbers).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import jax.random as jr
from jax import lax

# --- random numbers ---------------------------------------------------------------------------

_ROT = ((13, 15, 26, 6), (17, 29, 16, 24))


def _rotl(x, r):
    return lax.shift_left(x, jnp.uint32(r)) | lax.shift_right_logical(x, jnp.uint32(32 - r))


def threefry2x32(k1, k2, x1, x2):
    """Threefry-2x32, 20 rounds (Salmon et al. 2011), written out so that XLA fuses it.

    Same hash as ``jax.extend.random.threefry2x32_p`` (checked bit for bit in the tests), whose
    CPU lowering is a rolled loop that XLA does not fuse with its consumers (~3x slower).
    All arguments are uint32 and broadcast together; returns the two output words.
    """
    ks = (k1, k2, k1 ^ k2 ^ jnp.uint32(0x1BD11BDA))
    x1 = x1 + ks[0]
    x2 = x2 + ks[1]
    for i in range(5):
        for r in _ROT[i % 2]:
            x1 = x1 + x2
            x2 = _rotl(x2, r) ^ x1
        x1 = x1 + ks[(i + 1) % 3]
        x2 = x2 + ks[(i + 2) % 3] + jnp.uint32(i + 1)
    return x1, x2


_LN2_HI = 6.93147180369123816490e-01  # fdlibm split of log(2): _LN2_HI * e is exact
_LN2_LO = 1.90821492927058770002e-10


def log_f64(u):
    """Natural log of float64 ``u > 0`` (finite, normal), within a few ulp.

    ``u = 2^e m`` with ``m`` in ``[sqrt(2)/2, sqrt(2))``; ``log m = 2 atanh(s)``,
    ``s = (m - 1)/(m + 1)``, ``|s| < 0.172``, by its series to ``s^23`` (truncation < 1e-18).
    """
    bits = lax.bitcast_convert_type(u, jnp.uint64)
    e = lax.shift_right_logical(bits, jnp.uint64(52)).astype(jnp.int32) - 1023
    m = lax.bitcast_convert_type(
        (bits & jnp.uint64(0x000FFFFFFFFFFFFF)) | jnp.uint64(0x3FF0000000000000), jnp.float64
    )
    big = m > math.sqrt(2.0)
    m = jnp.where(big, 0.5 * m, m)
    ef = (e + big.astype(jnp.int32)).astype(jnp.float64)
    # s = (m - 1)/(m + 1) without a divide (XLA would split the fusion at the divide and hash
    # the random bits twice): 1/w for w = m + 1 in [1.71, 2.42] by Newton from 1/2.06
    w = m + 1.0
    inv = jnp.full_like(w, 1.0 / 2.06)
    for _ in range(5):  # relative error 0.17 -> 3e-2 -> 9e-4 -> 7e-7 -> 5e-13 -> rounding
        inv = inv * (2.0 - w * inv)
    s = (m - 1.0) * inv
    s2 = s * s
    p = jnp.asarray(1.0 / 23.0, jnp.float64)
    for k in range(10, -1, -1):
        p = p * s2 + 1.0 / (2 * k + 1)
    return ef * _LN2_HI + (ef * _LN2_LO + 2.0 * s * p)


def _uniform_open(hi, lo, dtype):
    """Uniform in ``(0, 1]`` from random words: ``2 - d``, ``d`` in ``[1, 2)`` built from the
    top 52 (float64: `hi` then `lo`) or 23 (float32: `hi`) bits, exactly."""
    if dtype == jnp.float64:
        m = lax.shift_left(hi.astype(jnp.uint64), jnp.uint64(20)) | lax.shift_right_logical(
            lo, jnp.uint32(12)
        ).astype(jnp.uint64)
        d = lax.bitcast_convert_type(m | jnp.uint64(0x3FF0000000000000), jnp.float64)
    else:
        d = lax.bitcast_convert_type(
            lax.shift_right_logical(hi, jnp.uint32(9)) | jnp.uint32(0x3F800000), jnp.float32
        )
    return 2.0 - d


def pair_uniforms(kd, frame, n_pairs, n_traj, normal_dtype, t_offset=0, n_total=None):
    """Radius and angle of each Box-Muller pair of one frame: ``(r, t)``, each (n_pairs, G, T).

    `kd`: uint32 key words ``(G, 2)``; `frame`: int32 frame index (the first counter word); the
    second is ``2 (j n_total + t_offset + i)`` (``+ 1``) for pair ``j`` of trajectory ``i``, so a
    tile of trajectories ``[t_offset, t_offset + n_traj)`` of ``n_total`` gets the same numbers
    as the whole. ``t = 4 v`` in ``(0, 4)`` (the angle, see :func:`cos_sin_quarter`).
    """
    dtype = jnp.dtype(normal_dtype)
    n_total = n_traj if n_total is None else n_total
    k1 = kd[None, :, 0, None]
    k2 = kd[None, :, 1, None]
    unit = lax.broadcasted_iota(jnp.uint32, (n_pairs, 1, n_traj), 0) * jnp.uint32(n_total) + (
        lax.broadcasted_iota(jnp.uint32, (n_pairs, 1, n_traj), 2)
    ) + jnp.asarray(t_offset).astype(jnp.uint32)
    f = jnp.asarray(frame).astype(jnp.uint32)
    if dtype == jnp.float64:
        a1, a2 = threefry2x32(k1, k2, f, unit * jnp.uint32(2))
        yb, _ = threefry2x32(k1, k2, f, unit * jnp.uint32(2) + jnp.uint32(1))
        r = jnp.sqrt(-2.0 * log_f64(_uniform_open(a1, a2, dtype)))
    else:
        a1, yb = threefry2x32(k1, k2, f, unit)
        r = jnp.sqrt(jnp.asarray(-2.0, dtype) * jnp.log(_uniform_open(a1, None, dtype)))
    v = lax.bitcast_convert_type(lax.shift_right_logical(yb, jnp.uint32(1)), jnp.int32)
    t = (v.astype(dtype) + 0.5) * jnp.asarray(2.0**-29, dtype)
    return r, t


def cos_sin_quarter(t, dtype):
    """``(cos, sin)`` of ``theta = pi (t - 1/2) / 2`` for ``t`` in ``[0, 4]``: quadrant
    ``q = floor(t)``, ``theta = q pi/2 + psi`` with ``psi`` in ``[-pi/4, pi/4)`` by Taylor
    series. (A uniform ``t`` gives a uniform angle: the offset of ``-pi/4`` does not matter.)"""
    qf = jnp.floor(t)
    psi = (t - qf - 0.5) * (math.pi / 2)  # t - qf is exact
    nt = 9 if dtype == jnp.float64 else 5  # truncation < 2e-18 (float64), 3e-8 (float32)
    x2 = psi * psi
    s = jnp.asarray((-1) ** (nt - 1) / math.factorial(2 * nt - 1), dtype)
    c = jnp.asarray((-1) ** (nt - 1) / math.factorial(2 * nt - 2), dtype)
    for k in range(nt - 2, -1, -1):
        s = s * x2 + (-1) ** k / math.factorial(2 * k + 1)
        c = c * x2 + (-1) ** k / math.factorial(2 * k)
    s = psi * s
    q = qf.astype(jnp.int32) & 3  # t = 4 (float32 rounding of the top values) is t = 0
    odd = (q & 1) == 1  # rotate (cos psi, sin psi) by q quarter turns
    cq = jnp.where(odd, -s, c)
    sq = jnp.where(odd, c, s)
    neg = q >= 2
    return jnp.where(neg, -cq, cq), jnp.where(neg, -sq, sq)


def pair_normals(r, t):
    """The two standard normals ``(r cos theta, r sin theta)`` of Box-Muller pairs."""
    c, s = cos_sin_quarter(t, r.dtype)
    return r * c, r * s


def frame_keys(keys):
    """64 bits (uint32 ``(G, 2)``) from each grid key: the Threefry key of its frame stream."""
    return jax.vmap(lambda k: jr.bits(k, (2,), jnp.uint32))(keys)


def jitter_normals(keys, frame, n_traj, dtype):
    """(G, T) normals for the jitter offset of `frame` (same stream as inside the scan)."""
    return jax.vmap(lambda k: jr.normal(jr.fold_in(k, frame), (n_traj,), dtype))(keys)
