"""What experiment design shares with blurtrap's command line (not user-facing API, no
stability promise): the fewest frames a planned recording may have and the shortest total time
that gives them, so that ``blurtrap design`` can check ``--total-s`` in its own words before any
design is computed, without importing a private module of :mod:`blurtrap.design`."""

from ._checks import MIN_FRAMES, largest_candidate, total_time_needed

__all__ = ["MIN_FRAMES", "largest_candidate", "total_time_needed"]
