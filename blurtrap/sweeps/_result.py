"""Labelled result of a sweep: coordinates per axis, statistics with the grid's shape."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from ..effects import lab_units
from ._grid import INJECTIONS, PARAMS, Grid

#: axes of labels (not numbers): no lab unit, not an x axis of ``plot``
LABEL_AXES = ("model", "method", INJECTIONS)
#: counts that are not failures (the others ``n_<status>`` are, in ``summary``)
_NOT_FAILURES = ("n_items", "n_ok", "n_at_bound", "n_blocks")


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """Per grid cell, model and method: statistics of the fits of a :func:`sweep` (SI units).

    - `dims`: axis names, the grid's axes in order, then ``"model"`` and ``"method"``.
    - `coords`: axis name -> values (SI; labels for ``model``, ``method`` and
      ``injections``).
    - `data`: statistic name -> array of shape ``shape``. For ``p`` in ``k``, ``gamma``,
      ``tracking_var``: ``mean_p``, ``true_p``, ``bias_p`` [% of the true value; NaN where it
      is 0], ``sd_p``, ``se_p`` (mean SE), ``sd_se_p``, ``coverage_p`` (fraction of 95 %
      Wald intervals covering the true value); counts ``n_items``, ``n_ok``, ``n_at_bound``
      and ``n_<status>`` (``n_not_converged``, ``n_inadequate``, ``n_refused`` ...);
      ``n_blocks``, the block count the method used in the cell (1: Whittle).
    - `fixed`: the parameters held fixed over the grid (SI).
    - `attrs`: n_frames, n_traces, chunk_traces, chunks_done, n_chunks, simulate_method,
      processes.
    """

    dims: tuple[str, ...]
    coords: dict[str, np.ndarray]
    data: dict[str, np.ndarray]
    fixed: dict[str, float]
    attrs: dict

    @classmethod
    def from_stats(cls, grid: Grid, models, methods, flat: dict[str, np.ndarray], attrs: dict):
        """From per-cell statistics of shape (cells, models x methods), model-major."""
        shape = grid.shape + (len(models), len(methods))
        coords = dict(grid.coords)
        coords["model"] = np.asarray(models, dtype=object)
        coords["method"] = np.asarray(methods, dtype=object)
        data = {k: np.asarray(v).reshape(shape) for k, v in flat.items()}
        return cls(grid.dims + ("model", "method"), coords, data, dict(grid.fixed),
                   dict(attrs))

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(self.coords[d]) for d in self.dims)

    @property
    def complete(self) -> bool:
        return self.attrs.get("chunks_done") == self.attrs.get("n_chunks")

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.data:
            raise KeyError(f"no statistic {name!r}; statistics: {sorted(self.data)}")
        return self.data[name]

    def to_dict(self) -> dict:
        return {"dims": list(self.dims),
                "coords": {k: np.asarray(v).tolist() for k, v in self.coords.items()},
                "data": {k: np.asarray(v).tolist() for k, v in self.data.items()},
                "fixed": dict(self.fixed), "attrs": dict(self.attrs)}

    def _rows(self):
        for idx in itertools.product(*(range(n) for n in self.shape)):
            yield idx, {d: self.coords[d][i] for d, i in zip(self.dims, idx)}

    def to_dataframe(self):
        """One row per cell, model and method: the coordinates (SI) and every statistic. Needs
        pandas (``pip install "blurtrap[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError('to_dataframe needs pandas: pip install "blurtrap[pandas]"'
                              ) from None
        rows = []
        for idx, labels in self._rows():
            rows.append({**labels, **{k: v[idx] for k, v in self.data.items()}})
        return pd.DataFrame(rows, columns=list(self.dims) + list(self.data))

    def to_xarray(self):
        """An ``xarray.Dataset`` with the grid's dimensions and coordinates (SI; units in
        the attributes). Needs xarray (``pip install xarray``). Select a method with a dict,
        ``ds.sel({"method": "psd"})``: the keyword ``method`` of ``sel`` is xarray's own."""
        try:
            import xarray as xr
        except ImportError:
            raise ImportError("to_xarray needs xarray: pip install xarray") from None
        coords = {}
        for d in self.dims:
            attrs = {"units": PARAMS[d][0]} if d in PARAMS else {}
            values = self.coords[d]
            if d in LABEL_AXES:
                values = np.asarray([str(v) for v in values])
            coords[d] = xr.Variable(d, values, attrs=attrs)
        ds = xr.Dataset({k: (self.dims, v) for k, v in self.data.items()}, coords=coords,
                        attrs={**{k: str(v) for k, v in self.attrs.items()},
                               **{f"fixed_{k}": v for k, v in self.fixed.items()}})
        return ds

    def summary(self, params=("k", "gamma")) -> str:
        """A table in lab units: per cell, model and method, the coordinates, then for each
        fitted parameter its mean, bias [%], SD/SE and 95 % coverage, and the failures."""
        head = [_lab_label(d) for d in self.dims]
        for p in params:
            fac, unit = lab_units(p)
            head += [f"{p} mean [{unit}]", f"{p} bias [%]", f"{p} SD/SE", f"{p} cover"]
        head += ["ok/items", "failures"]
        lines = [_fixed_line(self.fixed, self.attrs), " | ".join(head)]
        fail = [k for k in self.data if k.startswith("n_") and k not in _NOT_FAILURES]
        for idx, labels in self._rows():
            cells = [_lab_value(d, v) for d, v in labels.items()]
            for p in params:
                fac, _ = lab_units(p)
                cells += [f"{self.data['mean_' + p][idx] * fac:.5g}",
                          f"{self.data['bias_' + p][idx]:+.2f}",
                          f"{self.data['sd_se_' + p][idx]:.3f}",
                          f"{self.data['coverage_' + p][idx]:.3f}"]
            cells.append(f"{self.data['n_ok'][idx]}/{self.data['n_items'][idx]}")
            bad = [f"{self.data[k][idx]} {k[2:].replace('_', ' ')}" for k in fail
                   if self.data[k][idx]]
            cells.append(", ".join(bad) or "-")
            lines.append(" | ".join(cells))
        if not self.complete:
            lines.append(f"(partial: {self.attrs['chunks_done']} of {self.attrs['n_chunks']} "
                         "chunks)")
        return "\n".join(lines)

    def __repr__(self):
        dims = ", ".join(f"{d}: {n}" for d, n in zip(self.dims, self.shape))
        return (f"SweepResult({dims}; {self.attrs.get('n_traces')} traces x "
                f"{self.attrs.get('n_frames')} frames per cell)")

    def plot(self, x: str, y: str = "bias_k", *, ax=None):
        """Plot statistic `y` against grid axis `x` (lab units), one line per combination of
        the other axes. Returns the figure."""
        if x not in self.dims or x in LABEL_AXES:
            raise ValueError(f"x must be a numeric grid axis, one of "
                             f"{[d for d in self.dims if d not in LABEL_AXES]}; got x = {x!r}")
        if y not in self.data:
            raise ValueError(f"y must be a statistic, one of {sorted(self.data)}; got y = {y!r}")
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5, 3.5))
        axis = self.dims.index(x)
        vals = np.moveaxis(self.data[y], axis, -1)
        others = [d for d in self.dims if d != x]
        fac = PARAMS[x][2]
        for idx in itertools.product(*(range(len(self.coords[d])) for d in others)):
            label = ", ".join(_lab_value(d, self.coords[d][i]) for d, i in zip(others, idx))
            ax.plot(np.asarray(self.coords[x], float) * fac, vals[idx], "o-", label=label)
        ax.set_xlabel(_lab_label(x))
        ax.set_ylabel(y + (" [%]" if y.startswith("bias_") else ""))
        if y.startswith("bias_"):
            ax.axhline(0.0, color="0.6", lw=0.8)
        if others:
            ax.legend(fontsize="small")
        return ax.figure


def _lab_label(d):
    return f"{d} [{PARAMS[d][1]}]" if d in PARAMS else d


def _lab_value(d, v):
    return f"{float(v) * PARAMS[d][2]:.4g}" if d in PARAMS else str(v)


def _fixed_line(fixed, attrs):
    parts = [f"{d} = {_lab_value(d, v)} {PARAMS[d][1]}" for d, v in fixed.items()]
    return (f"{attrs.get('n_traces')} recordings x {attrs.get('n_frames')} frames per cell; "
            + ", ".join(parts))
