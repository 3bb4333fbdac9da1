"""The jitted frame scan (dimensionless: positions in sigma, times in tau).

One call runs ``n`` frames for all grid points ``G`` and trajectories ``T`` at once:
``lax.scan`` over frames; inside a frame one block of standard normals (``n_rows`` rows of
``(G, T)``) is used, and an inner ``lax.scan`` over the substeps accumulates the exposure
averages (``method="exact_frames"`` draws the frame from its exact law instead: the joint law
of the exposure segments given the start, or, with one window and regular frames, the frames'
innovations form, one normal per frame, two frames per step of the scan).
Memory is O(G T n_rows) per frame plus the frame output, never O(substeps). A chunk's output
is built in the user's ``(..., T, frames)`` layout and filled in place: the scan's
``(frames, ..., T)`` output is transposed block by block (:func:`block_frames` frames at a
time, while in cache), so no full-size transpose or scaling copy follows the scan.

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

CPU performance
---------------
On CPU the scan is compiled with ``xla_cpu_prefer_vector_width=512`` (per jit, see
:func:`_jit_for_cpu`: ~1.5x faster normals), and on a single CPU device many trajectories run in
tiles of :func:`tile_size` so that a frame's random numbers stay in cache (2x at 16384
trajectories). Neither changes the numbers.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import jax.random as jr
from jax import lax
from jax.sharding import NamedSharding, PartitionSpec


class CoreConfig(NamedTuple):
    method: str  # "exact" | "euler" | "exact_frames"
    n_exp: int  # substeps inside the exposure windows (0 for exact_frames)
    n_dead: int  # substeps in the dead time (1 for exact / exact_frames)
    n_seg: int  # exposure segments (windows sorted by length)
    n_win: int  # windows reported
    jitter: bool
    force: Any  # callable or None (harmonic)
    dtype: str
    mesh: Any  # jax.sharding.Mesh or None
    unroll: int
    normal_dtype: str
    # exact_frames with one window and regular frames: the frames' innovations form
    # (``_coeffs.innovations_law``), one normal per frame; frames run in pairs, one Box-Muller
    # pair per two frames (counter: the pair's first frame), so chunks have even lengths
    innovations: bool = False

    @property
    def n_rows(self) -> int:
        """Normals drawn per frame and trajectory."""
        if self.innovations:
            return 1
        if self.method == "exact_frames":
            return 2 * self.n_seg  # the dead time is merged into the last segment's draw
        return self.n_exp + self.n_dead


def _constrain(cfg, x, spec):
    if cfg.mesh is None:
        return x
    return jax.lax.with_sharding_constraint(x, NamedSharding(cfg.mesh, PartitionSpec(*spec)))


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


# --- one frame ------------------------------------------------------------------------------

def _drift(cfg, x, P, force_params):
    if cfg.force is None:
        return -x
    sig = P["scale"][:, None]
    f_si = cfg.force(x * sig, force_params)
    return (f_si / (P["k"][:, None] * sig)).astype(x.dtype)


def _pair_rows(a, r0, r1, j0, n_pairs, fill):
    """Per-row coefficients ``a`` (G, r1 - r0, ...) laid out as (pairs, 2, G, ...), rows
    ``2 j0 ...``, with `fill` outside ``[r0, r1)``."""
    lo = r0 - 2 * j0
    pad = [(0, 0)] * a.ndim
    pad[1] = (lo, 2 * n_pairs - lo - a.shape[1])
    a = jnp.pad(a, pad, constant_values=fill)
    a = a.reshape((a.shape[0], n_pairs, 2) + a.shape[2:])
    return jnp.moveaxis(a, 0, 2)


def _scan_substeps(cfg, r, t, r0, r1, x, acc, coefs, fills, step):
    """Run `step` over rows ``[r0, r1)`` of the frame's normals, one Box-Muller pair (two rows)
    per iteration. `coefs`: per-row coefficients (G, r1 - r0, ...), padded with `fills`."""
    j0, j1 = r0 // 2, -(-r1 // 2)
    cs = tuple(_pair_rows(c, r0, r1, j0, j1 - j0, f) for c, f in zip(coefs, fills))
    dtype = x.dtype

    def body(carry, inp):
        xx, ac = carry
        rj, tj, cc = inp
        zs = pair_normals(rj, tj)
        for i in range(2):
            xx, ac = step(xx, ac, zs[i].astype(dtype), *(c[i] for c in cc))
        return (xx, ac), None

    (x, acc), _ = lax.scan(body, (x, acc), (r[j0:j1], t[j0:j1], cs), unroll=cfg.unroll)
    return x, acc


def _frame(cfg, P, force_params, keys_j, rt, x, delta, frame):
    """Frame `frame` from the start state `x` with its Box-Muller pairs ``rt = (r, t)``."""
    dtype = jnp.dtype(cfg.dtype)
    n_t = x.shape[-1]
    r, t = _unpack(rt)

    def row(i):
        z = pair_normals(r[i // 2], t[i // 2])[i % 2]
        return z.astype(dtype)

    # dead time up to the next frame start (absorbs the timing jitter)
    rdead = P["rdead"][:, None]
    if cfg.jitter:
        d_next = P["jstd"][:, None] * jitter_normals(keys_j, frame + 1, n_t, dtype)
        d = jnp.maximum(rdead + d_next - delta, 0.0)
    else:
        d_next = delta
        d = rdead

    if cfg.method == "exact_frames":
        acc = jnp.zeros((x.shape[0], cfg.n_win, n_t), dtype)
        last = cfg.n_seg - 1
        for s in range(cfg.n_seg):
            z1, z2 = row(2 * s), row(2 * s + 1)
            m = P["p"][:, s, None] * x + P["sm"][:, s, None] * z1
            acc = acc + P["M"][:, s, :, None] * m[:, None, :]
            # increments (e - 1 = em1): see _coeffs, "Decay by increments"
            em1, cx, sx = P["em1"][:, s, None], P["cx"][:, s, None], P["sx"][:, s, None]
            if s < last:
                x = x + (em1 * x + cx * z1 + sx * z2)
            else:
                # end of exposure then the dead step, in one draw: with e_d = exp(-d),
                # x' = e_d (e x + cx z1 + sx z2) + sqrt(1 - e_d^2) z3
                #    = e_d e x + e_d cx z1 + sqrt(e_d^2 sx^2 + 1 - e_d^2) z2'
                # and e_d e - 1 = e_d em1 + expm1(-d)
                ed = jnp.exp(-d)
                sd = jnp.sqrt(ed * ed * sx * sx - jnp.expm1(-2.0 * d))
                x = x + ((ed * em1 + jnp.expm1(-d)) * x + ed * cx * z1 + sd * z2)
    else:
        acc = P["Wt"][:, 0, :, None] * x[:, None, :]
        n_exp = cfg.n_exp
        coefs = (P["A"][..., None], P["B"][..., None], P["Wt"][:, 1:, :, None])
        if cfg.method == "exact":

            def sub(xx, ac, zi, a, b, w):  # a = exp(-h) - 1: by increments
                xx = xx + (a * xx + b * zi)
                return xx, ac + w * xx[:, None, :]

            fills = (0.0, 0.0, 0.0)
        else:

            def sub(xx, ac, zi, a, b, w):
                xx = xx + a * _drift(cfg, xx, P, force_params) + b * zi
                return xx, ac + w * xx[:, None, :]

            fills = (0.0, 0.0, 0.0)
        x, acc = _scan_substeps(cfg, r, t, 0, n_exp, x, acc, coefs, fills, sub)
        if cfg.method == "euler":
            nd = cfg.n_dead
            dsub = jnp.broadcast_to(d, x.shape) / nd  # (G, T): per-trajectory with jitter
            ones = jnp.ones((x.shape[0], nd, 1), dtype)

            def dead(xx, ac, zi, m):
                h = m * dsub
                return xx + h * _drift(cfg, xx, P, force_params) + jnp.sqrt(2.0 * h) * zi, ac

            x, _ = _scan_substeps(cfg, r, t, n_exp, n_exp + nd, x, jnp.zeros((), dtype),
                                  (ones,), (0.0,), dead)
        else:
            x = x + (jnp.expm1(-d) * x + jnp.sqrt(-jnp.expm1(-2.0 * d)) * row(n_exp))
    x = _constrain(cfg, x, (None, "traces"))
    out = (acc, delta) if cfg.jitter else (acc, None)
    return x, d_next, out


def _innovation_pair(cfg, P, rt, xh):
    """Frames ``2j, 2j + 1`` of the innovations form from the predictor `xh` (units of sigma)
    and one Box-Muller pair: returns the next predictor and the frames (2, G, 1, T)."""
    dtype = jnp.dtype(cfg.dtype)
    cm1, cb, s = (P[name][:, None] for name in ("icm1", "icb", "is"))
    out = []
    r, t = _unpack(rt)
    for z in pair_normals(r[0], t[0]):
        e = s * z.astype(dtype)
        out.append(xh + e)
        xh = xh + (cm1 * xh + cb * e)  # c - 1 = cm1: by increments
    xh = _constrain(cfg, xh, (None, "traces"))
    return xh, jnp.stack(out)[:, :, None, :]


def _draws(cfg, kd, f, n_t, t_offset, n_total):
    """Frame `f`'s Box-Muller pairs ``(r, t)`` for trajectories ``[t_offset, t_offset + n_t)``."""
    r, t = pair_uniforms(kd, f, -(-cfg.n_rows // 2), n_t, cfg.normal_dtype, t_offset, n_total)
    spec = (None, None, "traces")
    if jnp.dtype(cfg.normal_dtype) == jnp.float32:  # one Threefry block gives r and t
        return (_constrain(cfg, lax.complex(r, t), spec),)
    return _constrain(cfg, r, spec), _constrain(cfg, t, spec)


def _unpack(rt):
    """``(r, t)`` from :func:`_draws`' output (float32 pairs come packed as ``r + i t``)."""
    if len(rt) == 1:
        return jnp.real(rt[0]), jnp.imag(rt[0])
    return rt


def _scan_frames(cfg, n, P, force_params, kd, keys_j, x, delta, rt, frame0, t_offset,
                 n_total):
    """The frame scan over frames ``frame0 .. frame0 + n`` for trajectories
    ``[t_offset, t_offset + T)`` of ``n_total``; `rt` are frame `frame0`'s Box-Muller pairs
    (innovations form: frames ``frame0`` and ``frame0 + 1``'s pair) and frame
    ``frame0 + n``'s are returned. Returns ``(x, delta, rt, frames (n, G, n_win, T), deltas)``."""
    n_t = x.shape[-1]

    def draws(f):
        return _draws(cfg, kd, f, n_t, t_offset, n_total)

    if cfg.innovations:  # two frames per step; n is even

        def pair(carry, f):
            x, delta, rt = carry
            nxt = draws(f + 2)
            x, acc = _innovation_pair(cfg, P, rt, x)
            return (x, delta, nxt), acc

        frames = frame0 + 2 * jnp.arange(n // 2, dtype=jnp.int32)
        (x, delta, rt), acc = jax.lax.scan(pair, (x, delta, rt), frames)
        return x, delta, rt, acc.reshape((n,) + acc.shape[2:]), None

    def body(carry, f):
        x, delta, rt = carry
        nxt = draws(f + 1)  # one frame ahead: materialised once as loop state
        x, delta, out = _frame(cfg, P, force_params, keys_j, rt, x, delta, f)
        return (x, delta, nxt), out

    frames = frame0 + jnp.arange(n, dtype=jnp.int32)
    (x, delta, rt), (acc, deltas) = jax.lax.scan(body, (x, delta, rt), frames)
    return x, delta, rt, acc, deltas


_BLOCK_BYTES = 1 << 16  # bytes of one output block of frames (transposed while in cache)


def block_frames(cfg: CoreConfig, n_traj: int, n: int) -> int:
    """Frames per output block: the scan's ``(frames, ..., T)`` output is transposed to the
    user's ``(..., T, frames)`` layout block by block, while the block (~64 kB) is in cache
    (a transpose of a whole chunk costs ~6 ns per value on CPU, of a block ~1 ns)."""
    per = max(n_traj * cfg.n_win * jnp.dtype(cfg.dtype).itemsize, 1)
    b = 1 << max(3, min(6, int(math.log2(max(_BLOCK_BYTES // per, 1)))))
    return min(b, n)


def _run_tile(cfg, n, P, force_params, kd, keys_j, x, delta, frame0, t_offset, n_total,
              buf, dbuf):
    """Frames ``frame0 + j`` (``j < n``) of trajectories ``[t_offset, t_offset + T)`` of
    ``n_total``, scaled by ``P["scale"]`` and written into ``buf[:, :, t_offset + i, j]`` (and
    the jitter offsets into ``dbuf``) block by block."""
    n_t = x.shape[-1]
    nbl = block_frames(cfg, n_t, n)
    n_full, rem = divmod(n, nbl)
    scale = P["scale"][:, None, None, None]
    zero = jnp.zeros((), jnp.int32)
    t_off = jnp.asarray(t_offset, jnp.int32)

    def write(buf, dbuf, acc, deltas, f):
        blk = (jnp.moveaxis(acc, 0, -1) * scale).astype(buf.dtype)  # (G, n_win, T, nbl)
        buf = lax.dynamic_update_slice(buf, blk, (zero, zero, t_off, f))
        if cfg.jitter:
            dbuf = lax.dynamic_update_slice(dbuf, jnp.moveaxis(deltas, 0, -1), (zero, t_off, f))
        return buf, dbuf

    def block(carry, f, size):
        x, delta, rt, buf, dbuf = carry
        x, delta, rt, acc, deltas = _scan_frames(cfg, size, P, force_params, kd, keys_j, x,
                                                 delta, rt, f, t_offset, n_total)
        buf, dbuf = write(buf, dbuf, acc, deltas, f - frame0)
        return (x, delta, rt, buf, dbuf), None

    carry = (x, delta, _draws(cfg, kd, frame0, n_t, t_offset, n_total), buf, dbuf)
    # the partial block first: written after the loop, it made XLA copy the whole buffer
    if rem:
        carry, _ = block(carry, frame0, rem)
    if n_full:
        starts = frame0 + rem + nbl * jnp.arange(n_full, dtype=jnp.int32)
        carry, _ = lax.scan(lambda c, f: block(c, f, nbl), carry, starts)
    x, delta, _, buf, dbuf = carry
    return x, delta, buf, dbuf


_TILE_BYTES = 1 << 20  # a frame's (r, t) per tile of trajectories: stays in L2 cache
_TILE_MAX = 2048  # and the per-frame state (exact_frames: 16 bytes of (r, t) per trajectory)


def tile_size(cfg: CoreConfig, n_traj: int):
    """Trajectories per tile, or None. Tiles only on a single CPU device (GPUs want all
    trajectories at once), without timing jitter (its normals are drawn per whole frame), and
    only when there are more than two tiles' worth of trajectories."""
    if cfg.mesh is not None or cfg.jitter or jax.default_backend() != "cpu":
        return None
    per_traj = 2 * (-(-cfg.n_rows // 2)) * jnp.dtype(cfg.normal_dtype).itemsize
    tile = min(1 << max(8, int(math.log2(max(_TILE_BYTES // per_traj, 1)))), _TILE_MAX)
    return tile if n_traj > 2 * tile else None


def buffer_traces(cfg: CoreConfig, n_traj: int) -> int:
    """Trajectories in the output buffer of :func:`run_chunk`: `n_traj` padded to whole tiles."""
    tile = tile_size(cfg, n_traj)
    return n_traj if tile is None else n_traj + (-n_traj % tile)


def run_chunk(cfg: CoreConfig, n: int, lead: tuple, P, force_params, keys_f, keys_j, x, delta,
              frame0):
    """Run `n` frames from state ``(x, delta)`` starting at global frame index `frame0`.

    Returns ``(x, delta, frames, deltas)``: the frames times ``P["scale"]`` (sigma: positions
    in metres) in the user's layout ``lead + (buffer_traces, n)`` (`lead`: the grid shape,
    plus the windows axis, reshaped here where it is free), and the jitter offsets
    ``(G, T, n)`` (or None). The output is filled in place block by block (:func:`_run_tile`),
    so no transpose of the whole chunk follows the scan.

    On one device, many trajectories run in tiles of :func:`tile_size` (one after the other,
    each through all `n` frames), so that a frame's random numbers stay in cache; the numbers
    are the same as without tiles.
    """
    n_t = x.shape[-1]
    n_pairs = -(-cfg.n_rows // 2)
    if cfg.innovations and n % 2:
        raise ValueError(f"chunks of the innovations form have even lengths; got n = {n}")
    tile = tile_size(cfg, n_t)
    n_pad = 0 if tile is None else -n_t % tile
    if n_pairs * (n_t + n_pad) * 2 >= 2**32:
        raise ValueError(
            f"one frame needs {cfg.n_rows} x {n_t} normals, more than the 2^32 the "
            "counter-based generator supports per frame; use fewer substeps or n_traces"
        )
    kd = frame_keys(keys_f)
    dtype = jnp.dtype(cfg.dtype)
    g_n = x.shape[0]
    user_shape = tuple(lead) + (n_t + n_pad, n)
    buf = jnp.zeros((g_n, cfg.n_win, n_t + n_pad, n), dtype)
    dbuf = jnp.zeros((g_n, n_t, n), dtype) if cfg.jitter else None
    if tile is None:
        x, delta, buf, dbuf = _run_tile(cfg, n, P, force_params, kd, keys_j, x, delta, frame0,
                                        0, n_t, buf, dbuf)
        return x, delta, buf.reshape(user_shape), dbuf
    # padded trajectories reuse other counters; they are discarded
    n_b = (n_t + n_pad) // tile
    xb = jnp.moveaxis(jnp.pad(x, ((0, 0), (0, n_pad))).reshape(x.shape[0], n_b, tile), 1, 0)

    def one(buf, args):
        xt, off = args
        xt, _, buf, _ = _run_tile(cfg, n, P, force_params, kd, keys_j, xt, delta, frame0,
                                  off, n_t, buf, None)
        return buf, xt

    buf, xb = lax.scan(one, buf, (xb, jnp.arange(n_b, dtype=jnp.int32) * tile))
    x = jnp.moveaxis(xb, 0, 1).reshape(x.shape[0], n_b * tile)[:, :n_t]
    return x, delta, buf.reshape(user_shape), dbuf


def _jit_for_cpu():
    """``run_chunk`` jitted; on CPU with XLA's preferred vector width set to 512 bits, which
    makes the normals ~1.5x faster (measured on this project's AVX-512 machine, and also with
    ``xla_cpu_max_isa=AVX2``). Plain jit where the option is unknown to XLA."""
    plain = jax.jit(run_chunk, static_argnums=(0, 1, 2))
    wide = jax.jit(run_chunk, static_argnums=(0, 1, 2),
                   compiler_options={"xla_cpu_prefer_vector_width": 512})
    use_wide: list[bool | None] = [None]

    def call(*args):
        if use_wide[0] is None:
            use_wide[0] = jax.default_backend() == "cpu"
            if use_wide[0]:
                try:
                    return wide(*args)
                except jax.errors.JaxRuntimeError as err:
                    if "compile option" not in str(err):
                        raise
                    use_wide[0] = False
        return (wide if use_wide[0] else plain)(*args)

    return call


run_chunk_jit = _jit_for_cpu()
