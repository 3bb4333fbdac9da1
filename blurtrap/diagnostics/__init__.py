"""Goodness of fit, residual tests, missing-effect ranking and model comparison."""

from ._diagnose import (
    Candidate as Candidate,
)
from ._diagnose import (
    Diagnosis as Diagnosis,
)
from ._diagnose import (
    Selection as Selection,
)
from ._diagnose import (
    compare as compare,
)
from ._diagnose import (
    diagnose as diagnose,
)
from ._diagnose import (
    select_model as select_model,
)
