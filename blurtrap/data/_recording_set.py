""":class:`RecordingSet`: an immutable, ordered collection of recordings."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from ._recording import Recording


class RecordingSet(Sequence):
    """An immutable sequence of :class:`Recording` (``len``, iteration, indexing, slicing).

    Mixed sets are allowed (e.g. some recordings without ``laser_power``, several
    temperatures); what is inhomogeneous is listed in :attr:`notes` rather than hidden.

    **Raises:** ``ValueError`` for an empty set, ``TypeError`` for items that are not
    recordings.
    """

    __slots__ = ("_recordings", "_notes")

    def __init__(self, recordings):
        if isinstance(recordings, Recording):
            recordings = (recordings,)
        try:
            recs = tuple(recordings)
        except TypeError:
            raise TypeError(
                f"RecordingSet expects an iterable of Recording; got {type(recordings).__name__}"
            ) from None
        if not recs:
            raise ValueError("RecordingSet needs at least one recording; got an empty sequence")
        for i, r in enumerate(recs):
            if not isinstance(r, Recording):
                raise TypeError(f"RecordingSet item {i} is a {type(r).__name__}, not a Recording")
        object.__setattr__(self, "_recordings", recs)
        object.__setattr__(self, "_notes", tuple(_consistency_notes(recs)))

    def __setattr__(self, key, value):
        raise AttributeError("RecordingSet is immutable")

    # -- sequence protocol --------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._recordings)

    def __iter__(self) -> Iterator[Recording]:
        return iter(self._recordings)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return RecordingSet(self._recordings[index])
        return self._recordings[index]

    def __eq__(self, other):
        if not isinstance(other, RecordingSet):
            return NotImplemented
        return self._recordings == other._recordings

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        body = ",\n  ".join(repr(r) for r in self._recordings)
        notes = "".join(f"\n  # {n}" for n in self._notes)
        return f"RecordingSet([\n  {body}\n]){notes}"

    # -- per-recording arrays -----------------------------------------------------------
    @property
    def exposures(self) -> np.ndarray:
        """[s], one per recording."""
        return np.array([r.exposure for r in self._recordings], dtype=np.float64)

    @property
    def frame_intervals(self) -> np.ndarray:
        """[s], one per recording."""
        return np.array([r.frame_interval for r in self._recordings], dtype=np.float64)

    @property
    def temperatures(self) -> np.ndarray:
        """[K], one per recording."""
        return np.array([r.temperature for r in self._recordings], dtype=np.float64)

    @property
    def laser_powers(self) -> np.ndarray:
        """[W], one per recording; NaN where the power is unknown."""
        return np.array(
            [np.nan if r.laser_power is None else r.laser_power for r in self._recordings],
            dtype=np.float64,
        )

    @property
    def n_frames(self) -> np.ndarray:
        return np.array([r.n_frames for r in self._recordings], dtype=np.int64)

    @property
    def names(self) -> tuple[str | None, ...]:
        return tuple(r.name for r in self._recordings)

    @property
    def notes(self) -> tuple[str, ...]:
        """Human-readable inhomogeneities found at construction (empty when uniform)."""
        return self._notes

    # -- helpers ------------------------------------------------------------------------
    def group_by_power(self) -> dict[float | None, RecordingSet]:
        """Recordings grouped by exact ``laser_power`` [W], in increasing power; recordings
        without a power are grouped under the key ``None`` (last)."""
        groups: dict[float | None, list[Recording]] = {}
        for r in self._recordings:
            groups.setdefault(r.laser_power, []).append(r)
        keys: list[float | None] = list(sorted(k for k in groups if k is not None))
        if None in groups:
            keys.append(None)
        return {k: RecordingSet(groups[k]) for k in keys}

    def require_laser_power(self) -> None:
        """Raise ``ValueError`` unless every recording has a ``laser_power``."""
        missing = [i for i, r in enumerate(self._recordings) if r.laser_power is None]
        if missing:
            raise ValueError(
                f"laser_power is missing for {len(missing)} of {len(self)} recordings "
                f"(indices {missing}, names {[self._recordings[i].name for i in missing]}); "
                "a variance-vs-power analysis needs it for all"
            )


def _consistency_notes(recs: tuple[Recording, ...]) -> list[str]:
    notes = []
    n = len(recs)
    missing = [i for i, r in enumerate(recs) if r.laser_power is None]
    if missing and len(missing) < n:
        notes.append(
            f"laser_power is missing for {len(missing)} of {n} recordings (indices {missing}); "
            "group_by_power() puts them under None"
        )
    temps = sorted({r.temperature for r in recs})
    if len(temps) > 1:
        notes.append(f"recordings have {len(temps)} different temperatures: {temps} K")
    intervals = sorted({r.frame_interval for r in recs})
    if len(intervals) > 1:
        notes.append(f"recordings have {len(intervals)} different frame intervals: {intervals} s")
    irregular = [i for i, r in enumerate(recs) if not r.is_regular]
    if irregular:
        notes.append(f"recordings {irregular} have irregular time stamps (allow_irregular=True)")
    names = [r.name for r in recs if r.name is not None]
    dups = sorted({x for x in names if names.count(x) > 1})
    if dups:
        notes.append(f"duplicate recording names: {dups}")
    return notes
