"""The simulated experiment of ``blurtrap demo`` (Wong & Halvorsen 2006, section 4): its
settings (:class:`DemoConfig`, :func:`quick_config`), the exposure series at every laser power,
the paper's Fig. 1 runs, added stage drift and the analytic error map of naive equipartition.

The embedded default (paper section 4): a 3.063 um polystyrene bead (radius 1.53 um) in water
at 295 K (viscosity 0.95 mPa s, gamma = 6 pi eta r), held at 4 laser powers with k = c P
(k = 0.01 ... 0.04 pN/nm), filmed by a ~1500 fps camera with a series of exposure times and
2 nm tracking error. Exposures longer than the 1/1500 s frame interval are filmed at a
frame interval equal to the exposure (the paper's 1 ms and 2 ms runs need a slower frame rate).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

BOLTZMANN = 1.380649e-23


@dataclasses.dataclass(frozen=True)
class DemoConfig:
    """Settings of the simulated experiment (SI units)."""

    radius: float = 1.53e-6  # m
    viscosity: float = 0.00095  # Pa s
    temperature: float = 295.0  # K
    powers: tuple = (0.1, 0.2, 0.3, 0.4)  # W
    c: float = 1e-4  # N/m/W  (k = c P: 0.01 ... 0.04 pN/nm)
    fps: float = 1500.0  # Hz
    exposures: tuple = (1.0e-4, 2.0e-4, 4.0e-4, 1 / 1500, 1.0e-3, 2.0e-3, 4.0e-3)  # s
    tracking_std: float = 2e-9  # m
    n_frames: int = 32768
    naive_exposures: tuple = (1.0e-3, 2.0e-3)  # s, as in the paper's Fig. 4
    power_exposures: tuple = (1.0e-3, 2.0e-3)  # s, variance-vs-power fits
    # Fig. 1 (caption): (k [N/m], tau [s]) of the three simulation settings
    fig1_settings: tuple = ((5e-5, 0.537e-3), (5e-5, 0.134e-3), (1.25e-5, 2.148e-3))
    fig1_windows: tuple = (2e-5, 5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 4e-3, 8e-3, 16e-3)
    fig1_frames: int = 20000
    posterior_steps: int = 200
    psd_models: tuple = ("naive", "naive_aliased", "standard")
    per_power_variance: bool = True  # variance vs exposure at each power (besides joint)
    exact_likelihood: bool = True
    posterior: bool = True
    seed: int = 0

    @property
    def gamma(self) -> float:
        return 6 * math.pi * self.viscosity * self.radius

    @property
    def ks(self) -> np.ndarray:
        return self.c * np.asarray(self.powers, dtype=float)

    @property
    def frame_interval(self) -> float:
        return 1.0 / self.fps

    def frame_intervals(self) -> np.ndarray:
        return np.maximum(np.asarray(self.exposures, dtype=float), self.frame_interval)


def quick_config(seed: int = 0) -> DemoConfig:
    """Small sizes for a fast check (tests, CI): fewer frames; no exact likelihood, posterior,
    per-power variance-vs-exposure or naive PSD fits (the naive equipartition rows show the
    blur bias), one variance-vs-power fit. A short run is dominated by first-call
    compilation, one per estimator and data shape."""
    return DemoConfig(n_frames=16384, fig1_frames=4000, exact_likelihood=False,
                      posterior=False, power_exposures=(2.0e-3,), psd_models=("standard",),
                      per_power_variance=False, seed=seed)


# ------------------------------------------------------------------------------------------
# simulation
# ------------------------------------------------------------------------------------------
def simulate_experiment(cfg: DemoConfig):
    """Exposure series at every power: ``{(power, exposure): Recording}`` in a RecordingSet
    ordered power-major. One ``simulate`` call (method ``exact_frames``)."""
    import jax

    from .data import Recording, RecordingSet
    from .simulate import simulate

    ws = np.asarray(cfg.exposures, dtype=float)
    dts = cfg.frame_intervals()
    # one independent stream per recording (a single key would give every grid point the
    # same random numbers: common random numbers, correlated recordings)
    keys = jax.random.split(jax.random.key(cfg.seed), len(cfg.powers) * len(ws))
    keys = keys.reshape(len(cfg.powers), len(ws))
    x = simulate(cfg.ks[:, None], cfg.gamma, ws[None, :], dts[None, :], cfg.n_frames,
                 key=keys, temperature=cfg.temperature,
                 method="exact_frames", tracking_std=cfg.tracking_std)
    x = np.asarray(x, dtype=float)  # (powers, exposures, 1, frames)
    recs = []
    for i, p in enumerate(cfg.powers):
        for j, w in enumerate(ws):
            recs.append(Recording(
                x[i, j, 0], frame_interval=float(dts[j]), exposure=float(w),
                temperature=cfg.temperature, laser_power=float(p),
                name=f"P{p * 1e3:.0f}mW_W{w * 1e3:.3f}ms",
                metadata={"simulated": True, "k_true_N_per_m": float(cfg.ks[i]),
                          "gamma_true_N_s_per_m": cfg.gamma},
            ))
    return RecordingSet(recs)


def simulate_fig1(cfg: DemoConfig):
    """The three settings of the paper's Fig. 1, all exposure windows from one trajectory
    each (``ExposureWindows``). Returns (positions (3, n_win, 1, N), ks, gammas, dt)."""
    import jax

    from .simulate import ExposureWindows, simulate

    ks = np.array([s[0] for s in cfg.fig1_settings])
    gammas = np.array([s[0] * s[1] for s in cfg.fig1_settings])
    dt = max(cfg.fig1_windows)
    keys = jax.random.split(jax.random.key(cfg.seed + 1), len(ks))
    x = simulate(ks, gammas, ExposureWindows(cfg.fig1_windows), dt, cfg.fig1_frames,
                 key=keys, temperature=cfg.temperature,
                 method="exact_frames")
    return np.asarray(x, dtype=float), ks, gammas, dt


def add_drift(rec, seed: int):
    """A copy of ``rec`` with slow stage drift (two sinusoids below 0.5 Hz, ~7 nm rms)."""
    from .data import Recording

    rng = np.random.default_rng(seed)
    t = np.arange(rec.n_frames) * rec.frame_interval
    ph = rng.uniform(0, 2 * np.pi, 2)
    drift = (8e-9 * np.sin(2 * np.pi * 0.13 * t + ph[0])
             + 5e-9 * np.sin(2 * np.pi * 0.41 * t + ph[1]))
    return Recording(np.asarray(rec.positions) + drift, frame_interval=rec.frame_interval,
                     exposure=rec.exposure, temperature=rec.temperature,
                     laser_power=rec.laser_power, name=f"{rec.name}+drift")


def naive_error_grid(cfg: DemoConfig, k_grid=None, w_grid=None):
    """Analytic relative error of naive equipartition, ``kT/var(X_m)/k - 1``, with
    ``var(X_m) = kT/k S(W k/gamma) + eps^2`` for the demo bead, over a k x W grid."""
    from .plotting.internal import blur_factor_np

    k_grid = np.geomspace(5e-6, 2e-4, 40) if k_grid is None else np.asarray(k_grid, float)
    w_grid = np.geomspace(5e-5, 5e-3, 48) if w_grid is None else np.asarray(w_grid, float)
    kt = BOLTZMANN * cfg.temperature
    kk, ww = np.meshgrid(k_grid, w_grid, indexing="ij")
    var = kt / kk * blur_factor_np(ww * kk / cfg.gamma) + cfg.tracking_std**2
    return k_grid, w_grid, kt / var / kk - 1.0
