"""What a calibration was fitted to, kept on its result for the result's own figures, and
the small HTML table the result objects show in notebooks."""

from __future__ import annotations

import dataclasses
import html
from typing import Any


@dataclasses.dataclass(frozen=True, eq=False)
class FitInputs:
    """The recordings a fit used (after the instrument's preparation: lines subtracted,
    positions in the recordings' unit), the model it fitted and the band it fitted (``f_range``
    [Hz], ``excluded`` ranges [Hz]). Kept by reference on :class:`CalibrationResult`
    (``result.inputs``) for ``result.plot()``; never serialised (``to_dict`` leaves it out, so
    a result rebuilt from JSON has none)."""

    recordings: tuple
    model: Any
    f_range: tuple | None = None
    excluded: tuple = ()

    def __repr__(self) -> str:
        return (f"FitInputs({len(self.recordings)} recording(s), model "
                f"{getattr(self.model, 'name', self.model)!r})")


def html_table(header, rows, caption: str = "") -> str:
    """An HTML table (every cell escaped) for the ``_repr_html_`` of the result objects."""
    esc = html.escape
    head = "".join(f"<th>{esc(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in row) + "</tr>"
                   for row in rows)
    cap = f"<caption>{esc(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
