"""Parameter layouts and negative log-likelihoods for single recordings and joint fits.

Parameters are shared or per-recording according to a :class:`Layout`:

- ``k="shared"``: one stiffness for all recordings;
- ``k="per_recording"``: one stiffness per recording;
- ``k="per_power"``: one stiffness per distinct laser power;
- ``k="linear_power"``: ``k_i = c P_i`` (paper section 6.3), parameter ``c`` [N/m/W].

``gamma`` and ``tracking_var`` are shared (one bead, one detector). The negative
log-likelihoods are module-level pure functions so that jitted fits are compiled once per
data shape.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._likelihood import arma_loglik
from ._models import TrapModel

K_MODES = ("shared", "per_recording", "per_power", "linear_power")


class Layout(eqx.Module):
    k_index: jax.Array  # per recording: which k parameter (unused for linear_power)
    power: jax.Array  # per recording laser power [W] (linear_power only)
    n_k: int = eqx.field(static=True)
    linear_power: bool = eqx.field(static=True)
    noise: bool = eqx.field(static=True)
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
        names=names,
        k_labels=labels,
    )


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
    model: TrapModel
    meta: RecMeta
    f: jax.Array  # (R, M) [Hz]
    s2: jax.Array  # (R, M) sin^2(pi f dt)
    power: jax.Array  # (R, M) [m^2/Hz]
    weight: jax.Array  # (R, M): n_blocks (1/2 at Nyquist), 0 on padding
    log_ref: jax.Array
    block_len: jax.Array | None = None  # (R,) frames per block: exact expected periodogram


def spectral_model_psd(p, a: SpectralArgs):
    k_rec, gamma, eps2 = a.layout.unpack(p)
    extras = a.layout.unpack_extras(p)
    temp = a.meta.temp
    if a.model.extra:
        k_rec, gamma, temp = a.model.relations(k_rec, gamma, temp, a.layout.power, extras)
    return a.model.psd(a.f, k_rec, gamma, eps2, a.meta.dt, a.meta.w, temp, s2=a.s2,
                       extras=extras, block_len=a.block_len)


def spectral_nll(p, a: SpectralArgs):
    """Whittle/Gamma negative log-likelihood of (blocked) periodogram ordinates of all
    recordings at once (one vectorised evaluation)."""
    psd = spectral_model_psd(p, a)
    return jnp.sum(a.weight * (jnp.log(psd) - a.log_ref + a.power / psd))


class ExactArgs(eqx.Module):
    """Frames of R recordings zero-padded to a common length (``mask`` marks real frames)."""

    layout: Layout
    model: TrapModel
    meta: RecMeta
    ys: jax.Array  # (R, N_max)
    mask: jax.Array  # (R, N_max)
    mean: str = eqx.field(static=True, default="reml")


def make_exact_args(recordings, layout, model, mean="reml") -> ExactArgs:
    n_max = max(r.n_frames for r in recordings)
    ys = np.zeros((len(recordings), n_max))
    mask = np.zeros((len(recordings), n_max))
    for i, r in enumerate(recordings):
        ys[i, : r.n_frames] = np.asarray(r.positions, dtype=float)
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
