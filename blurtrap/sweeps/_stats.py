"""Streaming statistics of the fits of a sweep: per chunk, then merged in chunk order.

Each chunk of trajectories of a cell gives, per model, method and parameter, the count, mean
and sum of squared deviations (two passes over the chunk), the mean standard error and the
number of 95 % Wald intervals that cover the true value. Chunks are merged with the pairwise
update of Chan, Golub & LeVeque (1979), ``M2 = M2_a + M2_b + delta^2 n_a n_b / n``, always in
chunk order, so the result does not depend on how the chunks were spread over devices or
processes.
"""

from __future__ import annotations

import numpy as np

#: fitted parameters whose statistics are kept, in this order (BatchCalibration fields)
FITTED = ("k", "gamma", "tracking_var")
#: the status kinds of ``calibrate_batch`` (the text before ":"); anything else is "other"
STATUSES = ("ok", "not converged", "singular Fisher information", "relaxation not resolved",
            "constant trace", "invalid", "refused", "inadequate", "other")
#: two-sided 95 % normal quantile
Z95 = 1.959963984540054

#: per-parameter accumulators (float64 arrays of shape cells x fits x parameters; a sweep's
#: fits are its (model, method) pairs, model-major)
PARAM_FIELDS = ("n", "mean", "m2", "n_se", "mean_se", "n_cover")
#: per-cell accumulators (cells x fits [x statuses])
CELL_FIELDS = ("n_items", "n_at_bound", "status")


def empty(n_cells: int, n_fits: int) -> dict[str, np.ndarray]:
    shape = (n_cells, n_fits, len(FITTED))
    acc: dict[str, np.ndarray] = {f: np.zeros(shape) for f in PARAM_FIELDS}
    acc["n_items"] = np.zeros((n_cells, n_fits))
    acc["n_at_bound"] = np.zeros((n_cells, n_fits))
    acc["status"] = np.zeros((n_cells, n_fits, len(STATUSES)))
    return acc


def _status_kind(s: str) -> int:
    kind = s.split(":")[0].strip()
    return STATUSES.index(kind) if kind in STATUSES else len(STATUSES) - 1


def chunk_stats(batch, truth: dict[str, float]) -> dict[str, np.ndarray]:
    """Statistics of one ``BatchCalibration`` (one cell, model, method and chunk): the fields
    of :func:`empty` for a single cell and fit (leading shape dropped)."""
    ok = np.asarray(batch.success, dtype=bool)
    out: dict[str, np.ndarray] = {f: np.zeros(len(FITTED)) for f in PARAM_FIELDS}
    for j, name in enumerate(FITTED):
        v = np.asarray(getattr(batch, name), dtype=np.float64)[ok]
        e = np.asarray(getattr(batch, name + "_err"), dtype=np.float64)[ok]
        if not (v.any() or e.any()):  # not a parameter of the model (eps^2 of "naive")
            continue
        n = v.size
        if n:
            mean = v.sum() / n
            out["n"][j], out["mean"][j] = n, mean
            out["m2"][j] = np.sum((v - mean) ** 2)
        has = np.isfinite(e) & (e > 0)
        if has.any():
            out["n_se"][j] = has.sum()
            out["mean_se"][j] = e[has].sum() / has.sum()
            out["n_cover"][j] = np.sum(np.abs(v[has] - truth[name]) <= Z95 * e[has])
    out["n_items"] = np.asarray(ok.size, dtype=np.float64)
    at = batch.at_bound
    out["n_at_bound"] = np.asarray(0 if at is None else np.sum(np.asarray(at, dtype=bool)),
                                   dtype=np.float64)
    out["status"] = np.bincount([_status_kind(str(s)) for s in batch.status],
                                minlength=len(STATUSES)).astype(np.float64)
    return out


def _merge_mean(n_a, mean_a, n_b, mean_b):
    n = n_a + n_b
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(n > 0, n_b / np.where(n > 0, n, 1.0), 0.0)
    delta = mean_b - mean_a
    return n, mean_a + delta * frac, delta


def merge(acc: dict[str, np.ndarray], new: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``acc`` updated by the statistics ``new`` of the next chunk (same shapes)."""
    out = dict(acc)
    n, out["mean"], delta = _merge_mean(acc["n"], acc["mean"], new["n"], new["mean"])
    with np.errstate(invalid="ignore", divide="ignore"):
        cross = np.where(n > 0, delta**2 * acc["n"] * new["n"] / np.where(n > 0, n, 1.0), 0.0)
    out["m2"] = acc["m2"] + new["m2"] + cross
    out["n"] = n
    out["n_se"], out["mean_se"], _ = _merge_mean(acc["n_se"], acc["mean_se"], new["n_se"],
                                                 new["mean_se"])
    for f in ("n_cover", "n_items", "n_at_bound", "status"):
        out[f] = acc[f] + new[f]
    return out


def summarise(acc: dict[str, np.ndarray], true: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Derived statistics per cell and fit (model, method): ``mean_*``, ``bias_*`` [%],
    ``sd_*``, ``se_*`` (mean SE), ``sd_se_*`` (SD / mean SE), ``coverage_*`` (of the 95 % Wald
    interval), with counts ``n_ok``, ``n_items``, ``n_at_bound`` and ``n_<status>``."""
    data: dict[str, np.ndarray] = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        for j, name in enumerate(FITTED):
            n = acc["n"][..., j]
            mean = np.where(n > 0, acc["mean"][..., j], np.nan)
            t = true[name][:, None]
            data[f"mean_{name}"] = mean
            data[f"true_{name}"] = np.broadcast_to(t, mean.shape).copy()
            data[f"bias_{name}"] = np.where(t != 0, 100.0 * (mean - t) / t, np.nan)
            sd = np.sqrt(np.where(n > 1, acc["m2"][..., j] / (n - 1), np.nan))
            se = np.where(acc["n_se"][..., j] > 0, acc["mean_se"][..., j], np.nan)
            data[f"sd_{name}"] = sd
            data[f"se_{name}"] = se
            data[f"sd_se_{name}"] = sd / se
            data[f"coverage_{name}"] = np.where(acc["n_se"][..., j] > 0,
                                                acc["n_cover"][..., j] / acc["n_se"][..., j],
                                                np.nan)
    data["n_ok"] = acc["status"][..., 0].astype(np.int64)
    data["n_items"] = acc["n_items"].astype(np.int64)
    data["n_at_bound"] = acc["n_at_bound"].astype(np.int64)
    for i, s in enumerate(STATUSES[1:], start=1):
        data["n_" + s.replace(" ", "_")] = acc["status"][..., i].astype(np.int64)
    return data
