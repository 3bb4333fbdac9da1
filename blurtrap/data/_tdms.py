"""LabVIEW TDMS recordings (:func:`load_tdms`), read with npTDMS.

npTDMS is an optional dependency (``pip install "blurtrap[tdms]"``), imported only when a file
is read, so ``import blurtrap.data`` never needs it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from ._recording import Recording
from ._trace import (
    _is_volts,
    _listing,
    build_recording,
    missing_exposure,
    numeric_trace,
    positive_number,
)
from ._units import canonical_unit

TDMS_INSTALL = 'pip install "blurtrap[tdms]"'


def _import_nptdms():
    try:
        import nptdms  # pyright: ignore[reportMissingImports]  # optional dependency
    except ImportError as e:
        raise ImportError(
            "reading TDMS files needs npTDMS, an optional dependency of blurtrap; install it with "
            f"{TDMS_INSTALL} (or pip install npTDMS)"
        ) from e
    return nptdms


def _pick(kind: str, wanted, names: list[str], where: str) -> str:
    if wanted is None:
        if len(names) == 1:
            return names[0]
        raise ValueError(
            f"{where}: {kind} not given and the file has {len(names)} {kind}s; pass {kind}=<one of "
            f"{_listing(names)}>"
        )
    if wanted not in names:
        raise ValueError(f"{where}: {kind} {wanted!r} not found; the {kind}s present are {_listing(names)}")
    return wanted


def _unit_property(props, position_unit, where: str):
    """Check the channel's ``unit_string`` property (if it names a unit) against
    `position_unit`; a disagreement is an error, never a silent choice."""
    text = props.get("unit_string")
    if not isinstance(text, str) or not text.strip():
        return None
    file_unit = "V" if _is_volts(text) else None
    if file_unit is None:
        try:
            file_unit = canonical_unit(text)
        except ValueError:
            return text.strip()  # not a length or volts: recorded, not compared
    try:
        given = "V" if _is_volts(position_unit) else canonical_unit(position_unit)
    except ValueError:
        return text.strip()  # the unit error is reported by build_recording
    if given != file_unit:
        raise ValueError(
            f"{where}: the channel's unit_string property is {text!r} but position_unit = "
            f"{position_unit!r}; they must agree"
        )
    return text.strip()


def _file_unit(props) -> str | None:
    """The unit named by the channel's ``unit_string`` property (volts or a length), or None."""
    text = props.get("unit_string")
    if not isinstance(text, str):
        return None
    if _is_volts(text):
        return "V"
    try:
        return canonical_unit(text)
    except ValueError:
        return None


def load_tdms(
    path,
    group: str | None = None,
    channel: str | None = None,
    *,
    sample_rate=None,
    position_unit: str | None = None,
    exposure=None,
    displacement_sensitivity_m_per_V=None,
    **recording_kwargs,
) -> Recording:
    """Load one channel of a LabVIEW TDMS file as a recording.

    **Arguments:**

    - `group`, `channel`: the TDMS group and channel names (either may be omitted when the
      file has only one).
    - `sample_rate` [Hz]: default ``1 / wf_increment``, the waveform's sample interval stored
      as a channel property by LabVIEW; a `sample_rate` that disagrees with it is an error.
    - `position_unit`: m, mm, um (µm), nm, px (with ``pixel_size_m``), or ``"V"`` (kept in
      volts, or converted with `displacement_sensitivity_m_per_V` [m/V]). Checked against the
      channel's ``unit_string`` property when that names a unit; None (default): that unit,
      else nm.
    - `exposure` [s]: required.
    - the remaining keywords are passed to :class:`Recording`.

    **Raises:** ``ImportError`` without npTDMS; ``ValueError`` naming the file, group and
    channel (a missing one lists those present).
    """
    nptdms = _import_nptdms()
    path = Path(os.fspath(path))
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        tdms = nptdms.TdmsFile.read(path)
    except Exception as e:  # npTDMS raises ValueError, KeyError, struct.error... on bad files
        raise ValueError(f"{path}: cannot be read as a TDMS file ({type(e).__name__}: {e})") from None
    gname = _pick("group", group, [g.name for g in tdms.groups()], str(path))
    grp = tdms[gname]
    cname = _pick("channel", channel, [c.name for c in grp.channels()], f"{path}, group {gname!r}")
    ch = grp[cname]
    where = f"{path}, group {gname!r}, channel {cname!r}"
    props = dict(ch.properties)
    values = numeric_trace(ch[:], where, "the channel")
    if values.ndim != 1:
        raise ValueError(f"{where}: the channel has shape {values.shape}; expected a 1-D trace")
    meta: dict = {"source": str(path), "group": gname, "channel": cname}
    if position_unit is None:
        position_unit = _file_unit(props) or "nm"
    unit_text = _unit_property(props, position_unit, where)
    if unit_text is not None:
        meta["unit_string"] = unit_text
    inc = props.get("wf_increment")
    file_dt = None if inc is None else positive_number(inc, "the wf_increment property", "s", where)
    if sample_rate is not None:
        rate = positive_number(sample_rate, "sample_rate", "Hz", where)
        if file_dt is not None and not math.isclose(1.0 / rate, file_dt, rel_tol=1e-9):
            raise ValueError(
                f"{where}: sample_rate = {rate!r} Hz was given but the channel's wf_increment = "
                f"{file_dt!r} s means {1.0 / file_dt!r} Hz; they disagree (remove sample_rate to "
                "use the file's, or fix the file)"
            )
        frame_interval = 1.0 / rate
        source = f"sample_rate = {rate!r} Hz"
    elif file_dt is not None:
        frame_interval = file_dt
        rate = 1.0 / file_dt
        source = f"the channel's wf_increment = {file_dt!r} (it must be in seconds)"
    else:
        raise ValueError(
            f"{where}: no sample rate: the channel has no wf_increment property (the waveform's "
            f"sample interval [s]); pass sample_rate=<Hz> (the channel's properties: "
            f"{_listing(props)})"
        )
    meta["sample_rate_Hz"] = rate
    if exposure is None:
        raise missing_exposure(where, frame_interval)
    return build_recording(
        values,
        where,
        position_unit=position_unit,
        displacement_sensitivity_m_per_V=displacement_sensitivity_m_per_V,
        frame_interval=frame_interval,
        exposure=exposure,
        times=None,
        meta=meta,
        recording_kwargs=recording_kwargs,
        interval_source=source,
    )
