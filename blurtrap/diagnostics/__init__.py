"""Goodness of fit, residual tests, missing-effect ranking and model comparison."""

from ._diagnose import (
    diagnose as diagnose,
)
from ._results import (
    Candidate as Candidate,
)
from ._results import (
    Diagnosis as Diagnosis,
)
from ._results import (
    Selection as Selection,
)
from ._select import (
    compare as compare,
)
from ._select import (
    select_model as select_model,
)
