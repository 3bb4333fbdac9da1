"""The two samplers without a frame scan: ``method="exact_frames"`` with a
:class:`~blurtrap.simulate.PhotodiodeFilter` (position and filter state as one exact linear
Gaussian system, ``_linear``) and ``method="spectral"`` (circulant embedding of the exact
discrete PSD, ``_spectral``)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._exposure import Grid
from ._linear import simulate_photodiode
from ._scan_run import start_keys
from ._spectral import simulate_spectral


def _frames(method, photodiode, hydro, kf, gf, dtf, tf, wf, tau, n, n_traces, dtype,
           k_init, k_frames):
    """Frames (G, T, n) in units of sigma from the exact photodiode system or the spectral
    sampler (dimensionless: times in tau, frequencies in 1/tau)."""
    from ..physics import water_density, water_viscosity

    g_n = kf.shape[0]
    if method == "exact_frames":  # photodiode filter, exact joint linear system
        lam = np.full(g_n, 2.0 * np.pi * photodiode.f3db) * tau
        alpha = np.full(g_n, photodiode.alpha)
        return simulate_photodiode(lam, alpha, wf / tau, np.maximum(dtf - wf, 0.0) / tau, n,
                                   n_traces, dtype, k_init, k_frames)
    p = {"w": wf / tau}
    if photodiode is not None:
        p["f3db"] = np.full(g_n, photodiode.f3db) * tau
        p["alpha"] = np.full(g_n, photodiode.alpha)
    if hydro is not None:
        eta = (np.asarray(water_viscosity(tf), dtype=np.float64) if hydro.viscosity is None
               else np.full(g_n, hydro.viscosity))
        rho = (np.asarray(water_density(tf), dtype=np.float64) if hydro.fluid_density is None
               else np.full(g_n, hydro.fluid_density))
        r = hydro.radius
        m_star = 4.0 / 3.0 * np.pi * r**3 * (hydro.bead_density + 0.5 * rho)
        p["f_nu"] = eta / (rho * np.pi * r**2) * tau
        p["f_m"] = gf / (2.0 * np.pi * m_star) * tau
        if hydro.distance is not None:
            p["x_wall"] = np.full(g_n, r / hydro.distance)
    return simulate_spectral(p, dtf / tau, n, n_traces, dtype, k_frames)


def run_special(method, g: Grid, keys, inj, n_traces, n_frames, burn_in_frames, dtype):
    """Positions [m] (G, 1, T, n_frames) and the grid points' keys for the injections."""
    k_init, k_frames, _, k_inj, _, _ = start_keys(keys, n_traces, dtype.name, None)
    frames = _frames(method, inj.photodiode, inj.hydro, g.k, g.gamma, g.dt, g.temperature, g.w,
                     g.tau, burn_in_frames + n_frames, n_traces, dtype, k_init,
                     k_frames)[..., burn_in_frames:][:, None]
    return frames * jnp.asarray(g.sigma, dtype)[:, None, None, None], k_inj
