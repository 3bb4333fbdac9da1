"""Goodness of fit, residual tests, missing-effect ranking and model comparison."""

from ._diagnose import (
    Candidate as Candidate,
    Diagnosis as Diagnosis,
    compare as compare,
    diagnose as diagnose,
)
