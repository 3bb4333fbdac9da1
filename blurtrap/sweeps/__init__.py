"""Sweeps: simulate and calibrate over parameter grids, over devices and processes."""

from ._result import SweepResult as SweepResult
from ._sweep import sweep as sweep
