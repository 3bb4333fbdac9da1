"""Experiment design from the Fisher information of the frame process."""

from ._bounds import bound_probability as bound_probability
from ._bounds import bounded_covariance as bounded_covariance
from ._checks import NotIdentifiedError as NotIdentifiedError
from ._design import Acquisition as Acquisition
from ._design import DesignResult as DesignResult
from ._design import design as design
from ._design import relative_se as relative_se
from ._fisher import exact_information as exact_information
from ._fisher import whittle_information as whittle_information
