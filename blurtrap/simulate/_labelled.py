"""Labelled output of :func:`simulate` on a broadcast grid (``simulate(..., labelled=True)``).

The grid's coordinates travel with the positions: each grid axis is named after the one
parameter that varies along it alone (``k``, ``exposure`` ...; ``grid_i`` when several do or
none does), and every parameter that varies is a coordinate on the axes it varies along.
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: simulate's broadcast parameters: name -> SI unit
UNITS = {"k": "N/m", "gamma": "N s/m", "exposure": "s", "frame_interval": "s",
         "temperature": "K", "tracking_std": "m"}


@dataclasses.dataclass(frozen=True)
class LabelledFrames:
    """Positions [m] with named axes and coordinates.

    - `values`: the positions, the array ``simulate`` returns otherwise.
    - `dims`: one name per axis: the grid axes, ``"window"`` (with
      :class:`ExposureWindows`), ``"trace"``, ``"frame"``.
    - `coords`: name -> ``(dims, values)`` (SI; see ``units``); a parameter that is the
      same over the grid has ``dims == ()``.
    - `times`: frame start times [s] with ``return_times=True``, else ``None``.
    """

    values: object
    dims: tuple[str, ...]
    coords: dict[str, tuple[tuple[str, ...], np.ndarray]]
    times: object = None

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.values.shape)  # pyright: ignore[reportAttributeAccessIssue]

    @property
    def units(self) -> dict[str, str]:
        return {name: UNITS.get(name, "s" if name == "window" else "") for name in self.coords}

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.values, dtype=dtype)

    def coord(self, name: str) -> np.ndarray:
        """The values of coordinate `name` (SI)."""
        if name not in self.coords:
            raise KeyError(f"no coordinate {name!r}; coordinates: {sorted(self.coords)}")
        return self.coords[name][1]

    def to_xarray(self):
        """An ``xarray.DataArray`` (positions [m]) with these dims and coordinates. Needs
        xarray (``pip install xarray``)."""
        try:
            import xarray as xr
        except ImportError:
            raise ImportError("to_xarray needs xarray: pip install xarray") from None
        coords = {n: xr.Variable(d, v, attrs={"units": self.units[n]})
                  for n, (d, v) in self.coords.items()}
        return xr.DataArray(np.asarray(self.values), dims=self.dims, coords=coords,
                            name="position", attrs={"units": "m"})

    def __repr__(self):
        dims = ", ".join(f"{d}: {n}" for d, n in zip(self.dims, self.shape))
        return f"LabelledFrames({dims})"


def label_frames(pos, params: dict[str, np.ndarray], shape, windows, times=None):
    """Wrap `pos` (shape ``(*shape, [windows,] traces, frames)``) with the coordinates of the
    broadcast `params` (name -> array as given, before broadcasting)."""
    nd = len(shape)
    aligned = {n: np.asarray(v, dtype=np.float64).reshape((1,) * (nd - np.ndim(v))
                                                          + np.shape(v))
               for n, v in params.items()}
    varying = {n: tuple(i for i, s in enumerate(a.shape) if s > 1) for n, a in aligned.items()}
    dims = []
    for i in range(nd):
        alone = [n for n, ax in varying.items() if ax == (i,)]
        dims.append(alone[0] if len(alone) == 1 else f"grid_{i}")
    coords = {}
    for n, a in aligned.items():
        ax = varying[n]
        if not ax:
            coords[n] = ((), a.reshape(()))
        else:
            keep = tuple(j for j in range(nd) if j not in ax)
            coords[n] = (tuple(dims[j] for j in ax), np.squeeze(a, axis=keep))
    tail = ("window",) if windows is not None else ()
    if windows is not None:
        coords["window"] = (("window",), np.asarray(windows, dtype=np.float64))
    return LabelledFrames(pos, tuple(dims) + tail + ("trace", "frame"), coords, times)
