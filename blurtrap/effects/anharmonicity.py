"""The ``anharmonicity`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

from ._base import AbstractEffect


class Anharmonicity(AbstractEffect):
    """Quartic term in the potential (U = k x^2/2 + k4 x^4/4; simulate with
    ``simulate(..., method="euler", force=quartic_force, force_params=(k, k4))``). Signature:
    non-Gaussian frame histogram (negative excess kurtosis for k4 > 0). Not part of the
    Gaussian (spectral/exact) likelihood: ``diagnose`` tests it with the kurtosis of the frames
    against its correlated-sample standard error. It cannot be added to a Gaussian model;
    the remedy is :func:`blurtrap.calibrate_anharmonic` (k, k4, gamma, eps^2 from exact moments
    of the blurred frames). With beta = k4 kT/k^2 the exact excess kurtosis of the stationary law is -0.094,
    -0.18, -0.27 at beta = 0.02, 0.05, 0.1 (var = 0.95, 0.89, 0.82 kT/k, so the harmonic fit's k
    is 5-22 % high). Measured on 16 384 camera frames (1500 fps, tau = 4 frames, SE of the
    kurtosis ~0.056): beta = 0.1 ranked first and significant in 5/5 records, beta = 0.05 in
    5/5 (5 seeds each); the harmonic fit's k or gamma was > 3 SE off in all 10. The expected
    detection limit is |excess kurtosis| ~ 3 SE, i.e. beta ~ 0.03 at this record length
    (scales as 1/sqrt(N); not measured below beta = 0.05)."""

    name: ClassVar[str] = "anharmonicity"
    kind: ClassVar[str] = "histogram"
    signature: ClassVar[str] = "non-Gaussian position histogram (kurtosis)"
    diagnose_test: ClassVar[str] = "kurtosis"
    order: ClassVar[float] = 120.0
    simulate_note: ClassVar[str] = ("it changes the force: use simulate(..., method='euler', "
                                    "force=quartic_force, force_params=(k, k4))")
