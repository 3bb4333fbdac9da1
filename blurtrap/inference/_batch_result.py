"""The result of :func:`blurtrap.calibrate_batch`: per-item values, errors and statuses."""

from __future__ import annotations

import dataclasses

import numpy as np

#: default ``gof_threshold`` of :func:`calibrate_batch` (see its docstring for the measured
#: false-alarm rate)
GOF_THRESHOLD = 1e-4


@dataclasses.dataclass(frozen=True)
class BatchCalibration:
    """Per-item results (numpy arrays of shape ``batch``; SI units)."""

    k: np.ndarray
    k_err: np.ndarray
    gamma: np.ndarray
    gamma_err: np.ndarray
    tracking_var: np.ndarray
    tracking_var_err: np.ndarray
    diffusion: np.ndarray
    success: np.ndarray  # bool: status == "ok"
    n_steps: np.ndarray
    #: per item: "ok", "not converged", "singular Fisher information" (a parameter at its
    #: bound or unidentifiable: errors are NaN), "relaxation not resolved" (tau > T/3: the
    #: bead diffuses almost freely and k is not identified), "constant trace" (no
    #: fluctuations; values NaN), or, with values and errors NaN, "invalid: ..." (NaN/inf
    #: frames, positions not in metres), "refused: ..." (dt >> tau or tracking noise swamps
    #: the motion: gamma not identifiable; a saturated (clipped) detector, or positions
    #: quantised in steps above their std: calibrate's refusals of such frames) or
    #: "inadequate: goodness of fit p = ..." (the model
    #: does not describe the spectrum, e.g. a line or drift)
    status: np.ndarray
    method: str
    model: str
    #: per item: p-value of the binned spectral goodness-of-fit test of ``calibrate``
    #: (``result.gof``), NaN where no fit was made or the spectrum has fewer than one bin
    gof_p: np.ndarray | None = None
    #: per item: its chi^2 statistic (``gof_dof`` degrees of freedom, the same for all items)
    gof_statistic: np.ndarray | None = None
    gof_dof: int = 0
    #: items with ``gof_p`` below this are "inadequate"
    gof_threshold: float = GOF_THRESHOLD
    #: per item: lag-1 correlation of the frames in standard errors (``r1 sqrt(N)``); below
    #: 5 the frames carry no temporal information and the item is refused
    lag1_z: np.ndarray | None = None
    #: per item ("ok" items only): a parameter, as a rule tracking_var, is at its lower
    #: bound 0 (``calibrate``'s ``result.at_bounds``, the same rule): its error is NaN, and
    #: the other errors are, as ``calibrate``'s, the unconstrained Cramer-Rao bound at the
    #: estimate (the inverse of the full information, the bound parameter counted as free;
    #: conservative near the bound). Conditional on the bound they were far too small: of 400
    #: simulated camera records (k = 5e-5 N/m, W = dt = 1/1500 s, 2 nm tracking noise,
    #: 65 536 frames) 43 had eps^2 at 0, and all 43 had k 5-20 conditional SE off
    at_bound: np.ndarray | None = None
    #: per item: True for an ``at_bound`` item whose full information is not positive
    #: definite, so that its errors stay *conditional* on the bound (too small; fit it
    #: with ``calibrate`` and use ``result.intervals``)
    bound_conditional: np.ndarray | None = None

    def __len__(self):
        return len(self.k)

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in out.items()}

    #: per-item columns by name (``batch["k"]``): SI arrays
    _COLUMNS = ("k", "k_err", "gamma", "gamma_err", "tracking_var", "tracking_var_err",
                "diffusion", "status", "success", "gof_p", "lag1_z", "at_bound")

    def __getitem__(self, name: str) -> np.ndarray:
        """A per-item column by name (SI): ``batch["k"]``, ``batch["gamma_err"]``,
        ``batch["D"]`` (= diffusion), ``batch["status"]`` ..."""
        key = "diffusion" if name == "D" else name
        if key not in self._COLUMNS or getattr(self, key) is None:
            raise KeyError(f"no column {name!r}; columns: "
                           f"{[c for c in self._COLUMNS if getattr(self, c) is not None]}")
        return np.asarray(getattr(self, key))

    def to_dataframe(self):
        """One row per item: values and errors in SI and lab units, status, goodness of fit.
        Needs pandas (``pip install "blurtrap[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError('to_dataframe needs pandas: pip install "blurtrap[pandas]"'
                              ) from None
        cols = {c: np.ravel(getattr(self, c)) for c in self._COLUMNS
                if getattr(self, c) is not None}
        cols["k_pN_per_nm"] = cols["k"] * 1e3
        cols["gamma_pN_s_per_um"] = cols["gamma"] * 1e6
        cols["D_um2_per_s"] = cols["diffusion"] * 1e12
        return pd.DataFrame(cols)

    def summary(self) -> str:
        """Counts by status and the median k, gamma, D of the "ok" items, in lab units."""
        status = np.ravel(self.status)
        ok = status == "ok"
        kinds, counts = np.unique([s.split(":")[0] for s in status], return_counts=True)
        lines = [f"{len(status)} items ({self.method}, model {self.model}): "
                 + ", ".join(f"{c} {k}" for k, c in zip(kinds, counts))]
        if ok.any():
            for name, fac, unit in (("k", 1e3, "pN/nm"), ("gamma", 1e6, "pN s/um"),
                                    ("diffusion", 1e12, "um^2/s")):
                v = np.ravel(getattr(self, name))[ok] * fac
                lines.append(f"  {name}: median {np.median(v):.5g} {unit} (16-84 %: "
                             f"{np.percentile(v, 16):.4g}..{np.percentile(v, 84):.4g})")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        import html

        return f"<pre>{html.escape(self.summary())}</pre>"
