"""The ``timing_jitter`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import injections
from ._base import AbstractEffect, DataContext, value_field


class TimingJitter(AbstractEffect):
    """Irregular frame times. Its spectral signature (extra white noise) is degenerate with
    tracking noise, so ``diagnose`` identifies it from the recording's time stamps (kept with
    ``Recording(..., times=..., allow_irregular=True)``): it is reported when a time stamp
    deviates from the regular grid by more than ``timing_tolerance`` (default 1e-3 frame
    intervals). Measured (benchmarks/study_diagnose.py, 16 384 frames): jitter std 5 % of dt
    found in 5/5 records, 0.02 % of dt (largest deviation ~0.08 %, below the tolerance) in
    0/5; i.i.d. jitter is flagged once its std exceeds ~2.5e-4 dt.

    **Remedy.** ``calibrate`` fits recordings with irregular time stamps by the exact
    likelihood at the recorded frame times (a Kalman filter of the blurred trap process,
    ``blurtrap.inference._irregular``; closed-form models), so jitter, a wandering clock or
    dropped frames do not bias k and gamma (benchmarks/RESULTS_jitter.md).

    Value: ``std`` [s] (>= 0), the jitter of the frame start times; simulated as
    ``injections.TimingJitter`` (``simulate(..., return_times=True)`` returns the times)."""

    name: ClassVar[str] = "timing_jitter"
    kind: ClassVar[str] = "timestamps"
    signature: ClassVar[str] = "uneven time stamps"
    diagnose_test: ClassVar[str] = "timestamps"
    order: ClassVar[float] = 130.0

    std: np.ndarray | None = value_field("s", ">= 0")

    @classmethod
    def applies(cls, ctx: DataContext) -> bool:
        return ctx.has_times

    def to_injection(self) -> injections.TimingJitter:
        return injections.TimingJitter(self._value("std"))
