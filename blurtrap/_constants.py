"""Physical constants (SI) shared by every layer.

Pure Python (no numpy, no jax), so that any subpackage can import it without pulling in a
numerical library: ``blurtrap.data`` is numpy only and must not import jax (DESIGN section 4).
``blurtrap.physics`` re-exports these names.
"""

BOLTZMANN = 1.380649e-23  # J/K, exact (SI 2019)
DEFAULT_TEMPERATURE = 295.0  # K
