"""The ``drift`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..physics import drift_psd
from . import injections
from ._base import AbstractEffect, Param, value_field


class Drift(AbstractEffect):
    r"""Random-walk drift of diffusion ``drift_diffusion`` [m^2/s] (stage/laser): increments of
    variance ``2 D_d dt`` per frame, as injected by ``blurtrap.simulate.RandomWalkDrift``.

    **Model.** A random walk is not stationary: its periodogram is not its "PSD"
    ``D_d dt^2 / (2 sin^2(pi f dt))`` (the spectrum of the increments divided by
    ``|1 - e^{-i theta}|^2``, ``blurtrap.physics._effects.drift_psd``). Summation by parts gives
    the DFT of a walk ``y`` of N frames at a Fourier frequency ``theta_j = 2 pi j/N``,
    ``j != 0``: ``Y_j = (E_j - y_{N-1}) / (1 - e^{-i theta_j})`` with ``E_j`` the DFT of the
    increments; the end-to-end displacement ``y_{N-1}`` (the record's net drift, a ramp seen
    through the periodic DFT) adds exactly as much power as the increments, so the expected
    periodogram is **exactly twice** that PSD at every ``j >= 1`` (mean subtraction only
    touches j = 0; the same holds per block). This effect therefore models
    ``E[I(f)] = D_d dt^2 / sin^2(pi f dt)``, so that ``drift_diffusion`` estimates the walk's
    diffusion coefficient. (Before this correction the fitted value was 2.2 +- 0.16 times the
    injected one over 100 records; see benchmarks/RESULTS_diagnose.md.)

    **Its uncertainty is underestimated.** Half of the drift power is the one common ramp: the
    ordinates are not independent (correlation ~0.4 between low ordinates of a pure walk), so
    ``drift_diffusion`` scatters by ~70 % between records whatever their length (the net
    displacement of one walk is a single chi^2_1 draw) while the Whittle standard error
    assumes independence. Measured over 100 records (16 384 frames, D_d = 2e-16 m^2/s):
    D_hat/D_d = 1.09 +- 0.08 (mean), SD 0.77, median 0.84; pulls (D_hat - D_d)/SE have SD 3.2,
    i.e. the reported SE is ~3x too small. Treat ``drift_diffusion`` as an order of magnitude;
    k and gamma keep calibrated errors (pull SD 0.97 and 0.99 in the same records).

    **Signature and detectability.** Excess at the lowest frequencies (~1/f^2). Detected when
    the drift power at the lowest Fourier frequencies exceeds the trap plateau
    ``2 kT gamma/k^2`` by a few times: ``D_d T^2/pi^2 >~ 10 x 2 kT gamma/k^2``
    (T = record length). Measured (benchmarks/study_diagnose.py; 16 384 frames at 1500 Hz,
    T = 10.9 s, k = 0.01 pN/nm, 1.5 um bead): D_d = 200 nm^2/s found in 10/10 records,
    2 nm^2/s in about half (D_d T^2/pi^2 ~ 10 x the plateau); the detectable D_d falls as
    1/T^2 for longer records."""

    name: ClassVar[str] = "drift"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("drift_diffusion", "m^2/s", 1e18, "nm^2/s", "drift diffusion",
                              bounds=(1e-30, 1e-8),
                              start=lambda c: 0.01 * c.variance / c.duration),)
    signature: ClassVar[str] = "excess power at the lowest frequencies (~1/f^2)"
    order: ClassVar[float] = 40.0

    #: value [m^2/s] (>= 0): simulated as ``injections.RandomWalkDrift``
    drift_diffusion: np.ndarray | None = value_field("m^2/s", ">= 0")

    def to_injection(self) -> injections.RandomWalkDrift:
        return injections.RandomWalkDrift(self._value("drift_diffusion"))

    def psd_add(self, f, dt, extras):
        # expected periodogram of a sampled random walk: twice its increment PSD (docstring)
        return 2.0 * drift_psd(f, dt, extras["drift_diffusion"])
