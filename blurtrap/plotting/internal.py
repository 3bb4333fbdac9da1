"""What the figures share with the demo (``blurtrap._demo_experiment``).

Not part of the plotting API (that is :mod:`blurtrap.plotting`) and without a stability
promise; it exists so that no module outside ``blurtrap.plotting`` imports one of its private
modules (issue 16, clean boundaries).
"""

from ._common import blur_factor_np

__all__ = ["blur_factor_np"]
