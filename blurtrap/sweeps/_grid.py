"""The parameter grid of a sweep: axes, fixed values, per-cell parameters and true values."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping

import numpy as np

from ..physics import DEFAULT_TEMPERATURE, stokes_friction, water_viscosity

#: grid names -> (SI unit, lab unit, factor SI -> lab, description)
PARAMS = {
    "k": ("N/m", "pN/nm", 1e3, "trap stiffness"),
    "gamma": ("N s/m", "pN s/um", 1e6, "friction coefficient"),
    "radius": ("m", "um", 1e6, "bead radius (gamma = 6 pi eta r)"),
    "viscosity": ("Pa s", "mPa s", 1e3, "viscosity for the bead radius"),
    "exposure": ("s", "ms", 1e3, "exposure time W"),
    "frame_interval": ("s", "ms", 1e3, "frame interval dt"),
    "tracking_std": ("m", "nm", 1e9, "tracking-noise std eps"),
    "temperature": ("K", "K", 1.0, "temperature"),
}
#: grid key whose values are labelled tuples of simulate injections (an axis of effects)
INJECTIONS = "injections"


@dataclasses.dataclass(frozen=True)
class Grid:
    """Outer product of the swept axes; fixed values broadcast to every cell."""

    dims: tuple[str, ...]
    coords: dict[str, np.ndarray]  # axis name -> values (SI; labels for injections)
    fixed: dict[str, float]
    injections: dict[str, tuple]  # label -> tuple of injections

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(self.coords[d]) for d in self.dims)

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    def cell(self, g: int) -> dict:
        """Parameters of flat cell ``g`` (row-major over ``dims``): SI floats, with
        ``gamma`` resolved from the radius if needed and ``injections`` a tuple."""
        idx = np.unravel_index(g, self.shape) if self.dims else ()
        p: dict = dict(self.fixed)
        for d, i in zip(self.dims, idx):
            p[d] = self.coords[d][i]
        p.setdefault("temperature", DEFAULT_TEMPERATURE)
        p.setdefault("tracking_std", 0.0)
        if "radius" in p:
            eta = p.get("viscosity")
            if eta is None:
                eta = float(water_viscosity(p["temperature"]))
            p["gamma"] = float(stokes_friction(p["radius"], eta))
        p["injections"] = self.injections[p[INJECTIONS]] if INJECTIONS in p else ()
        return p

    def fingerprint(self) -> list:
        """JSON-able description (used to refuse resuming a different sweep)."""
        return [list(self.dims), {d: [str(v) for v in self.coords[d]] for d in self.dims},
                {k: repr(v) for k, v in sorted(self.fixed.items())},
                {k: repr(v) for k, v in self.injections.items()}]


def _values(name, value):
    arr = np.asarray(value, dtype=np.float64) if not isinstance(value, str) else None
    if arr is None or arr.ndim > 1 or (arr.ndim == 1 and arr.size == 0):
        raise ValueError(
            f"grid[{name!r}] must be a number or a non-empty 1-D sequence of numbers "
            f"[{PARAMS[name][0]}]; got {value!r}")
    unit = PARAMS[name][0]
    bad = ~np.isfinite(arr) | (arr < 0) | ((arr == 0) & (name != "tracking_std"))
    if bad.any():
        v = arr[bad].ravel()[0]
        need = ">= 0" if name == "tracking_std" else "> 0"
        raise ValueError(f"grid[{name!r}] ({PARAMS[name][3]}) must be finite and {need} {unit}; "
                         f"got {v:.6g} {unit}")
    return arr


def make_grid(grid: Mapping) -> Grid:
    """Validate ``grid`` (name -> number or 1-D sequence; ``injections`` -> {label: tuple})."""
    if not isinstance(grid, Mapping):
        raise ValueError(f"grid must be a mapping of parameter name -> values; got {grid!r}")
    dims, coords, fixed, inj = [], {}, {}, {}
    for name, value in grid.items():
        if name == INJECTIONS:
            if not isinstance(value, Mapping) or not value:
                raise ValueError("grid['injections'] must be a non-empty mapping of label -> "
                                 f"tuple of simulate injections; got {value!r}")
            inj = {str(k): tuple(v) for k, v in value.items()}
            dims.append(name)
            coords[name] = np.asarray(list(inj), dtype=object)
            continue
        if name not in PARAMS:
            raise ValueError(f"unknown grid parameter {name!r}; expected one of "
                             f"{sorted(PARAMS) + [INJECTIONS]}")
        arr = _values(name, value)
        if arr.ndim == 0:
            fixed[name] = float(arr)
        else:
            dims.append(name)
            coords[name] = arr
    names = set(dims) | set(fixed)
    for need in ("k", "exposure", "frame_interval"):
        if need not in names:
            raise ValueError(f"grid needs {need!r} [{PARAMS[need][0]}] ({PARAMS[need][3]})")
    if ("gamma" in names) == ("radius" in names):
        raise ValueError("grid needs exactly one of 'gamma' [N s/m] and 'radius' [m] "
                         f"(gamma = 6 pi eta r); got {sorted(names & {'gamma', 'radius'})}")
    if "viscosity" in names and "radius" not in names:
        raise ValueError("grid['viscosity'] is only used with 'radius'; give gamma directly")
    g = Grid(tuple(dims), coords, fixed, inj)
    _check_cells(g)
    return g


def _check_cells(g: Grid) -> None:
    """Exposure <= frame interval in every cell (the error names the first bad cell)."""
    w = [g.coords["exposure"]] if "exposure" in g.dims else [[g.fixed["exposure"]]]
    dt = [g.coords["frame_interval"]] if "frame_interval" in g.dims else [[g.fixed["frame_interval"]]]
    for ww, dd in itertools.product(w[0], dt[0]):
        if ww > dd * (1 + 1e-12):
            raise ValueError(
                f"every grid cell needs exposure <= frame_interval; got exposure = {ww:.6g} s "
                f"with frame_interval = {dd:.6g} s")


def truths(g: Grid) -> dict[str, np.ndarray]:
    """True k, gamma and tracking variance per flat cell (SI)."""
    cells = [g.cell(i) for i in range(g.n_cells)]
    return {"k": np.array([c["k"] for c in cells]),
            "gamma": np.array([c["gamma"] for c in cells]),
            "tracking_var": np.array([c["tracking_std"] ** 2 for c in cells])}
