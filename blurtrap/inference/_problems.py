"""Parameter layouts and negative log-likelihoods for single recordings and joint fits.

Parameters are shared or per-recording according to a :class:`Layout`:

- ``k="shared"``: one stiffness for all recordings;
- ``k="per_recording"``: one stiffness per recording;
- ``k="per_power"``: one stiffness per distinct laser power;
- ``k="linear_power"``: ``k_i = c P_i`` (paper section 6.3), parameter ``c`` [N/m/W].

``gamma`` and ``tracking_var`` are shared (one bead, one detector). The negative
log-likelihoods are module-level pure functions so that jitted fits are compiled once per
data shape. The fused one-pass value/gradient/Hessian of the default Whittle fit is in
``_whittle_pass`` (re-exported here: :class:`SpectralObjective` looks ``spectral_newton_pass``
up in this module at call time).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..effects.line_noise import traced_constants
from ._likelihood import arma_loglik
from ._models import TrapModel
from ._newton import AbstractObjective
from ._nodes import NodeValues
from ._whittle_pass import _binned_args as _binned_args
from ._whittle_pass import _fused_pass_applies
from ._whittle_pass import spectral_newton_pass as spectral_newton_pass
from ._whittle_pass import spectral_newton_plan as spectral_newton_plan

K_MODES = ("shared", "per_recording", "per_power", "linear_power")


class Labels(tuple):
    """Parameter names that compare (and hash) by their structure only: a k label's
    bracket (``k[P=12 mW]``, ``k[bead 3]``) counts as ``k[]``. The names are static fields
    of :class:`Layout` that no traced computation reads (only their number), so a new set of
    laser powers or recording names reuses the compiled fits of the same structure instead
    of compiling them again (2-7 s each). Never use one as a dict key across layouts."""

    def __eq__(self, other):
        return isinstance(other, tuple) and len(self) == len(other) and \
            _structure(self) == _structure(other)

    def __ne__(self, other):
        return not self == other

    def __hash__(self):
        return hash(_structure(self))


def _structure(names: tuple) -> tuple:
    """``names`` with every bracket emptied (``k[P=12 mW]`` -> ``k[]``)."""
    return tuple(n.split("[", 1)[0] + "[]" if "[" in n else n for n in names)


class Layout(eqx.Module):
    k_index: jax.Array  # per recording: which k parameter (unused for linear_power)
    power: jax.Array  # per recording laser power [W] (linear_power only)
    n_k: int = eqx.field(static=True)
    linear_power: bool = eqx.field(static=True)
    noise: bool = eqx.field(static=True)
    #: display names (:class:`Labels`: equal across laser powers, so no recompilation)
    names: tuple = eqx.field(static=True)
    k_labels: tuple = eqx.field(static=True)
    extra_names: tuple = eqx.field(static=True, default=())

    def unpack_extras(self, p) -> dict:
        """Effect parameters (after the core ones) by name."""
        n0 = len(self.names) - len(self.extra_names)
        return {name: p[n0 + i] for i, name in enumerate(self.extra_names)}

    def unpack(self, p):
        nk = 1 if self.linear_power else self.n_k
        if self.linear_power:
            k_rec = p[0] * self.power
        else:
            k_rec = p[:nk][self.k_index]
        gamma = p[nk]
        eps2 = p[nk + 1] if self.noise else jnp.zeros_like(gamma)
        return k_rec, gamma, eps2


def make_layout(recordings, k_mode: str, noise: bool, extra_names: tuple = ()) -> Layout:
    if k_mode not in K_MODES:
        raise ValueError(f"k must be one of {K_MODES}; got k = {k_mode!r}")
    n = len(recordings)
    powers = np.array(
        [np.nan if r.laser_power is None else float(r.laser_power) for r in recordings]
    )
    if k_mode in ("per_power", "linear_power") and np.any(np.isnan(powers)):
        missing = [i for i in range(n) if np.isnan(powers[i])]
        raise ValueError(
            f"k = {k_mode!r} needs laser_power on every recording; missing on recordings {missing}"
        )
    if k_mode == "shared":
        idx = np.zeros(n, dtype=np.int32)
        labels = ("k",)
    elif k_mode == "per_recording":
        idx = np.arange(n, dtype=np.int32)
        labels = tuple(f"k[{getattr(r, 'name', None) or i}]" for i, r in enumerate(recordings))
    elif k_mode == "per_power":
        uniq = np.unique(powers)
        idx = np.searchsorted(uniq, powers).astype(np.int32)
        labels = tuple(f"k[P={p * 1e3:g} mW]" for p in uniq)
    else:
        idx = np.zeros(n, dtype=np.int32)
        labels = ("c",)
    linear = k_mode == "linear_power"
    names = labels + ("gamma",) + (("tracking_var",) if noise else ()) + tuple(extra_names)
    return Layout(
        extra_names=tuple(extra_names),
        k_index=jnp.asarray(idx),
        power=jnp.asarray(np.nan_to_num(powers, nan=0.0)),
        n_k=len(labels),
        linear_power=linear,
        noise=noise,
        names=Labels(names),
        k_labels=Labels(labels),
    )


#: padded lengths are rounded up to 2^j times one of these (``bucket_length``), so that
#: recordings of nearby lengths share one compiled fit; ``None`` turns bucketing off. Plain
#: powers of two: a compilation (15-25 s on 2 cores) costs far more than fitting up to twice
#: the ordinates or frames (< 0.5 s at 2^16 frames); (1, 1.25, 1.5, 1.75) gave 2-3x more
#: compilations over one octave of lengths (benchmarks/bench_buckets.py)
BUCKET_STEPS: tuple | None = (1.0,)
#: lengths up to this are rounded up to a power of two (tiny arrays: padding is free)
_BUCKET_MIN = 64


def bucket_length(n: int) -> int:
    """The padded length for ``n`` real entries: the smallest ``2^j * s`` (``s`` in
    :data:`BUCKET_STEPS`, an integer) that is at least ``n``; ``n`` itself when bucketing is
    off. Every reduction over padded arrays gives the padding weight (or mask) 0."""
    n = int(n)
    if BUCKET_STEPS is None or n <= 1:
        return max(n, 1)
    if n <= _BUCKET_MIN:
        return 1 << (n - 1).bit_length()
    base = 1 << ((n - 1).bit_length() - 1)  # base < n <= 2 base
    return min(int(round(base * s)) for s in (*BUCKET_STEPS, 2.0) if base * s >= n)


class RecMeta(eqx.Module):
    dt: jax.Array
    w: jax.Array
    temp: jax.Array


def rec_meta(recordings) -> RecMeta:
    return RecMeta(
        dt=jnp.asarray([float(r.frame_interval) for r in recordings]),
        w=jnp.asarray([float(r.exposure) for r in recordings]),
        temp=jnp.asarray([float(r.temperature) for r in recordings]),
    )


class SpectralArgs(eqx.Module):
    """Periodogram ordinates of R recordings, padded to a common length M (weight 0 on
    padding), so that every evaluation is a broadcast over (R, M) with no gathers."""

    layout: Layout
    model: TrapModel = eqx.field(converter=traced_constants)
    meta: RecMeta
    f: jax.Array  # (R, M) [Hz]
    s2: jax.Array  # (R, M) sin^2(pi f dt)
    power: jax.Array  # (R, M) [m^2/Hz]
    weight: jax.Array  # (R, M): n_blocks (1/2 at Nyquist), 0 on padding
    log_ref: jax.Array
    block_len: jax.Array | None = None  # (R,) frames per block: exact expected periodogram
    n_ordinates: jax.Array | None = None  # (R,) real ordinates (the rest is bucket padding)
    #: the folded spectrum at its nodes and the ordinates' place between them, given
    #: (``_screen_stacked``: the fold once per evaluation, the ordinate chunks interpolating);
    #: None: folded here
    nodes: NodeValues | None = None


def _rec_params(p, a: SpectralArgs):
    """Per-recording (k, gamma, eps2, temperature) and the effects' parameters of ``p``."""
    k_rec, gamma, eps2 = a.layout.unpack(p)
    extras = a.layout.unpack_extras(p)
    temp = a.meta.temp
    if a.model.extra:
        k_rec, gamma, temp = a.model.relations(k_rec, gamma, temp, a.layout.power, extras)
    return k_rec, gamma, eps2, temp, extras


def spectral_model_psd(p, a: SpectralArgs):
    k_rec, gamma, eps2, temp, extras = _rec_params(p, a)
    return a.model.psd(a.f, k_rec, gamma, eps2, a.meta.dt, a.meta.w, temp, s2=a.s2,
                       extras=extras, block_len=a.block_len, nodes=a.nodes)


def spectral_node_logp(p, a: SpectralArgs):
    """The log folded spectrum at the nodes spanning ``a.f`` (:meth:`TrapModel.node_logp`),
    shape (R, K), for a model whose spectrum goes through nodes at ``a.f``."""
    k_rec, gamma, _, temp, extras = _rec_params(p, a)
    return a.model.node_logp(a.f, k_rec, gamma, a.meta.dt, a.meta.w, temp, extras)


def _spectral_nll(p, a: SpectralArgs):
    """Whittle/Gamma negative log-likelihood of (blocked) periodogram ordinates of all
    recordings at once (one vectorised evaluation); :data:`spectral_nll` is its objective."""
    psd = spectral_model_psd(p, a)
    return jnp.sum(a.weight * (jnp.log(psd) - a.log_ref + a.power / psd))


class SpectralObjective(AbstractObjective):
    """The Whittle/Gamma negative log-likelihood ``nll(p, a)`` of :class:`SpectralArgs` as a
    Newton objective: the fused one-pass value/gradient/Hessian
    (:func:`spectral_newton_pass`) and the binned coarse data for start values where
    :func:`spectral_newton_plan` allows them, autodiff otherwise."""

    def __call__(self, p, a: SpectralArgs):
        return _spectral_nll(p, a)

    def value_grad_hess(self, x, scale, a: SpectralArgs):
        if not _fused_pass_applies(a):
            return super().value_grad_hess(x, scale, a)
        return spectral_newton_pass(x, scale, a)  # looked up at call time (tests patch it)

    def coarse_args(self, a: SpectralArgs):
        plan = spectral_newton_plan(a)
        return None if plan is None else plan[1]


#: the Whittle/Gamma negative log-likelihood ``spectral_nll(p, a)`` (a callable objective)
spectral_nll = SpectralObjective()


class ExactArgs(eqx.Module):
    """Frames of R recordings zero-padded to a common length (``mask`` marks real frames)."""

    layout: Layout
    model: TrapModel
    meta: RecMeta
    ys: jax.Array  # (R, N_max)
    mask: jax.Array  # (R, N_max)
    mean: str = eqx.field(static=True, default="reml")


def make_exact_args(recordings, layout, model, mean="reml") -> ExactArgs:
    n_max = bucket_length(max(r.n_frames for r in recordings))  # masked beyond each record
    ys = np.zeros((len(recordings), n_max))
    mask = np.zeros((len(recordings), n_max))
    for i, r in enumerate(recordings):
        y = np.asarray(r.positions, dtype=float)
        # "reml" and "profile" are exactly invariant to a constant shift: centre on the host in
        # float64 (a large offset would otherwise cost digits in the profiled quadratic form)
        ys[i, : r.n_frames] = y if mean == "zero" else y - y.mean()
        mask[i, : r.n_frames] = 1.0
    return ExactArgs(layout=layout, model=model, meta=rec_meta(recordings),
                     ys=jnp.asarray(ys), mask=jnp.asarray(mask), mean=mean)


def exact_nll(p, a: ExactArgs):
    """Exact (REML) negative log-likelihood summed over recordings (one vmapped graph)."""
    k_rec, gamma, eps2 = a.layout.unpack(p)
    c0, c1, rho = a.model.moments(k_rec, gamma, eps2, a.meta.dt, a.meta.w, a.meta.temp)

    def one(y, m, c0_, c1_, rho_):
        return arma_loglik(y, c0_, c1_, rho_, mean=a.mean, mask=m)

    return -jnp.sum(jax.vmap(one)(a.ys, a.mask, c0, c1, rho))
