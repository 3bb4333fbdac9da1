"""Physical constants (SI)."""

BOLTZMANN = 1.380649e-23  # J/K, exact (SI 2019)
DEFAULT_TEMPERATURE = 295.0  # K
