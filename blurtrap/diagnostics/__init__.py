"""Goodness of fit, residual tests, missing-effect ranking and model comparison."""

from ._diagnose import (
    Candidate as Candidate,
)
from ._diagnose import (
    Diagnosis as Diagnosis,
)
from ._diagnose import (
    compare as compare,
)
from ._diagnose import (
    diagnose as diagnose,
)
