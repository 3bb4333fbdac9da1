"""Shared helpers for the figures: lab units, parameter extraction, model spectra.

Plots are drawn in lab units (nm, pN/nm, pN s/um, ms, Hz, um^2/s, mW) and always say so in
their axis labels; everything passed in is SI (as everywhere in the Python API).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, cast

import numpy as np

from .._constants import BOLTZMANN, DEFAULT_TEMPERATURE
from ..effects import lab_units

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

# name -> (factor from SI, lab unit, pretty label); `c` is k per laser power
_SYMBOLS = {"k": "k", "c": "c = k/P", "gamma": "gamma", "diffusion": "D",
            "tracking_var": "eps^2", "tau": "tau", "corner_frequency": "f_c", "exposure": "W",
            "frame_interval": "dt", "position": "x", "laser_power": "P"}
# (factor from SI, lab unit, symbol), from the package's one table of lab units
LAB_UNITS = {name: (*lab_units(name), sym) for name, sym in _SYMBOLS.items()}

NM = 1e9
NM2 = 1e18
MS = 1e3


def lab(name: str):
    """(factor, unit, label) of a parameter name such as ``k``, ``k[P=100 mW]`` or ``gamma``."""
    base = name.split("[")[0]
    if base in LAB_UNITS:
        fac, unit, label = LAB_UNITS[base]
        return fac, unit, label + name[len(base):]
    return 1.0, "SI", name


def new_figure(nrows=1, ncols=1, *, figsize=None, ax=None, fig=None, **kw):
    """The figure and axes to draw into.

    - `ax` given: draw into it (its figure is returned; one-axes plots only).
    - `fig` given: add the subplots to that (empty) figure.
    - neither: a new figure made with pyplot, so that Jupyter's inline backend displays it
      at the end of the cell and scripts can ``plt.show()`` it; a caller that only saves it
      closes it with ``plt.close(fig)`` (or :func:`blurtrap.plotting.save`).
    """
    if ax is not None:
        if nrows * ncols != 1:
            raise ValueError(f"this figure has {nrows} x {ncols} axes: pass fig=, not ax=")
        return ax.figure, ax
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=figsize, layout="constrained")
    elif fig.axes:
        raise ValueError("fig must be an empty figure (it already has axes); pass ax= to draw "
                         "into an existing axes")
    kw.setdefault("squeeze", True)
    axes = fig.subplots(nrows, ncols, **kw)
    return fig, axes


def new_axes(*, figsize=None, ax=None) -> tuple[Figure, Axes]:
    """:func:`new_figure` for a one-axes plot: the figure and its single axes."""
    fig, axes = new_figure(figsize=figsize, ax=ax)
    return fig, cast("Axes", axes)


def save(fig, path, **kw):
    """Save `fig` to `path` (``fig.savefig(path, **kw)``) and close it, so that a script or
    the CLI that only writes figures keeps none open in pyplot."""
    fig.savefig(path, **kw)
    close(fig)


def close(fig):
    """Release a figure made by a plotting function (no-op if pyplot does not manage it)."""
    import sys

    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:
        plt.close(fig)


def is_result(obj) -> bool:
    return hasattr(obj, "param_names") and hasattr(obj, "k_per_recording")


def trap_params(params, index: int = 0):
    """``(k [N/m], gamma [N s/m], tracking_var [m^2], temperature [K])`` from a
    ``CalibrationResult`` (``index`` picks the recording when k varies), a mapping with keys
    ``k``, ``gamma`` (optional ``tracking_var``, ``temperature``) or a tuple
    ``(k, gamma[, tracking_var])``."""
    if is_result(params):
        k = float(np.asarray(params.k_per_recording)[index])
        g = float(params.gamma)
        e2 = float(params.tracking_var)
        t = float(params.temperature)
    elif isinstance(params, Mapping):
        k = float(params["k"])
        g = float(params.get("gamma", math.nan))
        e2 = float(params.get("tracking_var", 0.0))
        t = float(params.get("temperature", DEFAULT_TEMPERATURE))
    else:
        seq = tuple(params)
        if len(seq) < 2:
            raise ValueError(
                "params must be a CalibrationResult, a mapping with 'k' [N/m] and 'gamma' "
                f"[N s/m], or a tuple (k, gamma[, tracking_var]); got {params!r}"
            )
        k, g = float(seq[0]), float(seq[1])
        e2 = float(seq[2]) if len(seq) > 2 else 0.0
        t = DEFAULT_TEMPERATURE
    if not (k > 0):
        raise ValueError(f"k must be > 0 [N/m]; got k = {k!r}")
    return k, g, e2, t


def model_name(params) -> str:
    if is_result(params):
        return str(params.model)
    if isinstance(params, Mapping):
        return str(params.get("model", "standard"))
    return "standard"


def blur_factor_np(alpha):
    """S(alpha) in numpy (series below 1e-3, expm1 above)."""
    a = np.asarray(alpha, dtype=float)
    small = a < 1e-3
    safe = np.where(small, 1.0, a)
    big = 2.0 / safe * (1.0 + np.expm1(-safe) / safe)
    ser = 1.0 - a / 3.0 + a * a / 12.0 - a**3 / 60.0
    return np.where(small, ser, big)


def sample_variance_se_np(n, k, gamma, exposure, frame_interval, temperature, tracking_var=0.0):
    """Standard error of the sample variance of n correlated frames, long-record form
    ``sqrt((2/n) (C(0)^2 + 2 sum_{m>=1} C(m)^2))`` with ``C(m) = sigma2 B rho^m`` (DESIGN
    items 5 and 10), in numpy (broadcasts over `exposure`)."""
    sigma2 = kT(temperature) / k
    tau = gamma / k
    a = np.asarray(exposure, dtype=float) / tau
    half = np.maximum(a / 2, 1e-300)
    b = np.where(a < 1e-6, 1.0 + a * a / 12.0, (np.sinh(half) / half) ** 2)
    rho = math.exp(-frame_interval / tau)
    c0 = sigma2 * blur_factor_np(a) + tracking_var
    c1 = sigma2 * b * rho
    return np.sqrt(2.0 / n * (c0**2 + 2.0 * c1**2 / (1.0 - rho**2)))


def model_psd(params, recording, f, model=None, index: int = 0, block_len=None):
    """Two-sided model PSD [m^2/Hz] of a fitted model for ``recording`` at ``f`` [Hz].

    ``model`` defaults to the model of a ``CalibrationResult`` (``naive``, ``naive_aliased``,
    ``blur``, ``standard``), else ``standard``. With ``block_len`` (frames per periodogram
    block) a closed-form aliased model gives the exact *expected periodogram* of such a block
    (finite-block leakage included, as the spectral fits use), so that data/model of a
    blocked periodogram has mean 1 also for blocks only a few relaxation times long."""
    import jax.numpy as jnp

    from .._config import x64_context
    from ..inference import get_model

    k, g, e2, t = trap_params(params, index)
    mdl = get_model(model or model_name(params))
    extras = {}
    if is_result(params):  # effect parameters (drift_diffusion, line_amplitude, ...)
        extras = {p.name: params.params[p.name] for p in mdl.extra_params
                  if p.name in params.params}
    with x64_context(True):
        f2 = jnp.asarray(np.asarray(f, dtype=float)[None, :])
        one = lambda v: jnp.asarray([float(v)])  # noqa: E731
        bl = (one(block_len) if block_len is not None and mdl.alias and mdl.closed_form
              else None)
        p = mdl.psd(f2, one(k), one(g), jnp.asarray(e2), one(recording.frame_interval),
                    one(recording.exposure), one(t),
                    extras={n: jnp.asarray(v) for n, v in extras.items()}, block_len=bl)
        return np.asarray(p, dtype=float)[0]


def blocked_psd(recording, n_blocks=None):
    """Blocked periodogram exactly as ``calibrate(method="psd")`` computes it.

    Returns ``(f [Hz], two-sided P [m^2/Hz], n_blocks)``."""
    from ..inference.internal import np_periodogram as _np_periodogram

    n = recording.n_frames
    nb = n_blocks if n_blocks is not None else max(1, min(128, n // 64))
    f, p, _ = _np_periodogram(recording.positions, float(recording.frame_interval), int(nb))
    return f, p, int(nb)


def fit_n_blocks(fit, recording, n_blocks):
    if n_blocks is not None:
        return int(n_blocks)
    extras = getattr(fit, "extras", None) or {}
    if "n_blocks" in extras:
        return int(extras["n_blocks"])
    return max(1, min(128, recording.n_frames // 64))


def gamma_pdf(x, shape: float):
    """Density of Gamma(shape, scale 1/shape) (mean 1), numpy only."""
    x = np.asarray(x, dtype=float)
    out = np.zeros_like(x)
    pos = x > 0
    xs = x[pos]
    logp = shape * math.log(shape) - math.lgamma(shape) + (shape - 1) * np.log(xs) - shape * xs
    out[pos] = np.exp(logp)
    return out


def normal_pdf(x, mean, std):
    x = np.asarray(x, dtype=float)
    return np.exp(-0.5 * ((x - mean) / std) ** 2) / (std * math.sqrt(2 * math.pi))


def kT(temperature=DEFAULT_TEMPERATURE):
    return BOLTZMANN * float(temperature)


FIT_STYLE = {
    "standard": dict(color="C3", ls="-", lw=1.8,
                     label="blur-corrected, aliased + noise (standard)"),
    "blur": dict(color="C3", ls="-", lw=1.8, label="blur-corrected, aliased (blur)"),
    "naive": dict(color="C0", ls="--", lw=1.5, label="naive Lorentzian (naive)"),
    "naive_aliased": dict(color="C2", ls=":", lw=1.8, label="naive aliased (naive_aliased)"),
}
