"""Position units accepted by the loaders and exact decimal conversion to metres.

Power-of-ten units (m, mm, um, nm) are converted *in decimal* before rounding to float64:
the text ``"12.345"`` in nm becomes ``float("12.345e-9")``, the float64 nearest to the exact
value. Writing uses the shortest repr of the value in metres shifted by the same power of ten,
so save -> load reproduces every float64 bit for bit. Pixels (``px``) are multiplied by
``pixel_size_m`` (one rounding; exact round trips are not guaranteed for ``px``). Volts
(``V``, a position detector's signal before its displacement sensitivity is known) are not
a length: they are kept as they are (exponent 0), and a :class:`Recording` in volts says so
in ``position_unit``.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal

import numpy as np

# canonical unit -> decimal exponent p such that 1 unit = 10**-p m (None: needs pixel_size_m)
# ("V" is not a length: its values are kept in volts)
_DECIMAL_EXPONENT = {"m": 0, "mm": 3, "um": 6, "nm": 9, "px": None, "V": 0}
_ALIASES = {
    "µm": "um",
    "μm": "um",
    "micron": "um",
    "microns": "um",
    "v": "V",
    "volt": "V",
    "volts": "V",
}
ALLOWED_UNITS = ("m", "mm", "um", "µm", "nm", "px", "V")
#: the units of length (all but volts)
LENGTH_UNITS = ("m", "mm", "um", "nm", "px")

# A plain decimal number: sign, mantissa, optional exponent (no '_', no hex, no nan/inf).
_NUMBER = re.compile(r"\s*([+-]?)(\d+(?:\.\d*)?|\.\d+)(?:[eE]([+-]?\d+))?\s*\Z")


def canonical_unit(unit, *, what: str = "position_unit") -> str:
    """Return the canonical spelling of a position unit, or raise listing the allowed ones."""
    if isinstance(unit, str):
        u = unit.strip()
        u = _ALIASES.get(u, _ALIASES.get(u.lower(), u))
        if u in _DECIMAL_EXPONENT:
            return u
    raise ValueError(
        f"{what} = {unit!r} is not a supported position unit; expected one of "
        f"{', '.join(repr(u) for u in ALLOWED_UNITS)} ('px' also needs pixel_size_m; 'V' is "
        "a detector signal in volts)"
    )


def check_pixel_size(unit: str, pixel_size_m, *, where: str = "") -> float | None:
    """Validate ``pixel_size_m`` for ``unit`` and return it as float (None if unused)."""
    pre = f"{where}: " if where else ""
    if unit != "px":
        if pixel_size_m is None:
            return None
        raise ValueError(
            f"{pre}pixel_size_m = {pixel_size_m!r} was given but the positions are in "
            f"{unit!r}, not 'px'; pixel_size_m only converts positions in pixels (it would be "
            "ignored): remove it, or declare the positions in 'px'"
        )
    if pixel_size_m is None:
        raise ValueError(
            f"{pre}position unit 'px' needs pixel_size_m (the pixel size in metres, e.g. 1e-7)"
        )
    return _positive_scalar(pixel_size_m, pre)


def _positive_scalar(value, pre: str) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{pre}pixel_size_m must be a number in metres; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{pre}pixel_size_m must be a number in metres; got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{pre}pixel_size_m must be finite and > 0 [m]; got {v!r}")
    if v > 1e-3:
        raise ValueError(
            f"{pre}pixel_size_m = {v!r} m is larger than 1 mm: this looks like nm or um, "
            "not metres (a typical camera pixel is ~1e-7 m in the sample plane)"
        )
    return v


def to_metres(values, unit: str, pixel_size_m: float | None = None) -> np.ndarray:
    """Convert a numeric array in ``unit`` to float64 metres (a new array; volts stay volts)."""
    arr = np.array(values, dtype=np.float64, copy=True)
    p = _DECIMAL_EXPONENT[unit]
    if p is None:
        assert pixel_size_m is not None, "unit 'px' needs pixel_size_m (see check_pixel_size)"
        return arr * pixel_size_m
    if p:
        arr /= 10.0**p  # 10**p is exact in float64: one correctly rounded division
    return arr


def from_metres(values, unit: str, pixel_size_m: float | None = None) -> np.ndarray:
    """Inverse of :func:`to_metres` (float arithmetic; the CSV writer uses exact decimals)."""
    arr = np.array(values, dtype=np.float64, copy=True)
    p = _DECIMAL_EXPONENT[unit]
    if p is None:
        assert pixel_size_m is not None, "unit 'px' needs pixel_size_m (see check_pixel_size)"
        return arr / pixel_size_m
    if p:
        arr *= 10.0**p
    return arr


def parse_number(cell: str, p: int = 0) -> float | None:
    """Parse a decimal number and scale it by ``10**-p`` exactly; None if not a number.

    The result may be ``inf`` on overflow (the caller reports it as non-finite).
    """
    m = _NUMBER.match(cell)
    if m is None:
        return None
    if p == 0:
        return float(cell)
    sign, mant, exp = m.groups()
    return float(f"{sign}{mant}e{int(exp or 0) - p}")


def format_scaled(x: float, p: int) -> str:
    """Decimal text of ``x * 10**p`` that :func:`parse_number` (with ``p``) maps back to ``x``."""
    r = repr(float(x))
    if p == 0:
        return r
    return decimal_text(Decimal(r).scaleb(p))


def decimal_text(d: Decimal) -> str:
    """Positional notation for moderate exponents (``100`` not ``1E+2``), else scientific."""
    return format(d, "f") if -7 < d.adjusted() < 16 else str(d)


def decimal_exponent(unit: str) -> int | None:
    return _DECIMAL_EXPONENT[unit]
