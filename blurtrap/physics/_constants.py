"""Physical constants (SI), defined once in the pure-Python ``blurtrap._constants``."""

from .._constants import BOLTZMANN as BOLTZMANN
from .._constants import DEFAULT_TEMPERATURE as DEFAULT_TEMPERATURE
