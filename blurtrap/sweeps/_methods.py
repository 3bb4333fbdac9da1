"""The calibration methods of a sweep (its ``method`` axis): names -> ``calibrate_batch``'s
``n_blocks`` per grid cell.

- ``"whittle"``: the Whittle likelihood of the whole record (``n_blocks = 1``);
- ``"psd"``: the blocked-PSD Gamma likelihood with the default block count of
  ``calibrate(method="psd")``, evaluated at the cell's true relaxation time tau = gamma/k:
  ``min(128, N // 64, N dt / (100 tau))`` blocks, at least 1, rounded down to a power of two
  (blocks of at least 64 frames and, where the record allows, 100 tau);
- ``"psd:B"``: the blocked PSD with ``B >= 2`` blocks in every cell (at least 8 frames each).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

#: what the error messages list as the valid names
VALID = ("'whittle' (Whittle likelihood), 'psd' (blocked PSD, default block count per cell) "
         "or 'psd:B' (blocked PSD with B >= 2 blocks, e.g. 'psd:64')")


@dataclasses.dataclass(frozen=True)
class Method:
    """One calibration method: its label and block count (None: the per-cell default)."""

    name: str
    n_blocks: int | None

    def blocks(self, cell: dict, n_frames: int) -> int:
        """``n_blocks`` for ``calibrate_batch`` in grid cell ``cell`` (SI parameters)."""
        if self.n_blocks is not None:
            return self.n_blocks
        return default_blocks(n_frames, cell["frame_interval"], cell["gamma"] / cell["k"])


def default_blocks(n_frames: int, frame_interval: float, tau: float) -> int:
    """The default block count of ``calibrate(method="psd")`` (``_fit_psd``) for a record
    of ``n_frames`` frames [s apart] and relaxation time ``tau`` [s]."""
    nb = max(1, min(128, n_frames // 64, int(n_frames * frame_interval / (100.0 * tau))))
    return 1 << (nb.bit_length() - 1)


def parse_methods(methods, n_blocks, n_frames: int) -> tuple[Method, ...]:
    """Validate ``methods`` (or the older ``n_blocks``, which means ``("whittle",)`` for 1
    and ``("psd:<n_blocks>",)`` above); exactly one of them may be given."""
    if methods is not None and n_blocks is not None:
        raise ValueError(f"pass the calibration method as methods or as n_blocks, not both; "
                         f"got methods = {methods!r}, n_blocks = {n_blocks!r}")
    if methods is None:
        if n_blocks is None or (not isinstance(n_blocks, bool) and n_blocks == 1):
            methods = ("whittle",)
        elif isinstance(n_blocks, bool) or not isinstance(n_blocks, int) or n_blocks < 1:
            raise ValueError(f"n_blocks must be an integer >= 1 (1: Whittle, > 1: blocked PSD); "
                             f"got n_blocks = {n_blocks!r}")
        else:
            methods = (f"psd:{int(n_blocks)}",)
    if isinstance(methods, str) or not isinstance(methods, Sequence) or not methods:
        raise ValueError(f"methods must be a non-empty sequence of calibration method names, "
                         f"e.g. ('whittle', 'psd'); got methods = {methods!r}")
    out = tuple(_parse_one(i, m, n_frames) for i, m in enumerate(methods))
    names = [m.name for m in out]
    if len(set(names)) != len(names):
        raise ValueError(f"methods must be distinct; got {names}")
    return out


def _parse_one(i: int, name, n_frames: int) -> Method:
    if isinstance(name, str) and name == "whittle":
        return Method("whittle", 1)
    if isinstance(name, str) and name == "psd":
        return Method("psd", None)
    if isinstance(name, str) and name.startswith("psd:"):
        text = name[4:]
        nb = int(text) if text.isdigit() else 0
        if nb < 2:
            raise ValueError(f"methods[{i}] = {name!r}: the block count B of 'psd:B' must be an "
                             f"integer >= 2 (use 'whittle' for one block); got {text!r}")
        if n_frames // nb < 8:
            raise ValueError(f"methods[{i}] = {name!r} leaves {n_frames // nb} frames per block "
                             f"of n_frames = {n_frames}; need >= 8 (at most {n_frames // 8} "
                             "blocks)")
        return Method(f"psd:{nb}", nb)
    raise ValueError(f"unknown calibration method methods[{i}] = {name!r}; expected {VALID}")
