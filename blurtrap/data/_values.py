"""Plain-value checks shared by the containers and loaders: scalars, numeric arrays, and
JSON-compatible (frozen) metadata."""

from __future__ import annotations

import math
import types

import numpy as np


def fmt_g(x) -> str:
    return f"{x:.6g}"


def freeze(obj, path: str = "metadata"):
    """Copy metadata into an immutable-ish, JSON-compatible form."""
    if isinstance(obj, (dict, types.MappingProxyType)):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise ValueError(f"{path} keys must be strings; got key {k!r}")
            out[k] = freeze(v, f"{path}[{k!r}]")
        return types.MappingProxyType(out)
    if isinstance(obj, (list, tuple)):
        return tuple(freeze(v, f"{path}[{i}]") for i, v in enumerate(obj))
    if isinstance(obj, np.ndarray):
        return freeze(obj.tolist(), path)
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, (str, bool, int, float)):
        return obj
    raise ValueError(
        f"{path} = {obj!r} has type {type(obj).__name__}; metadata values must be str, "
        "int, float, bool, None, lists or dicts of these (so that they can be saved)"
    )


def thaw(obj):
    """JSON-serialisable plain copy of frozen metadata."""
    if isinstance(obj, (dict, types.MappingProxyType)):
        return {k: thaw(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [thaw(v) for v in obj]
    return obj


def scalar(name: str, value, unit: str) -> float:
    if isinstance(value, bool) or value is None:
        raise ValueError(f"{name} must be a number [{unit}]; got {value!r}")
    try:
        arr = np.asarray(value)
    except Exception:  # pragma: no cover - exotic objects
        raise ValueError(f"{name} must be a number [{unit}]; got {value!r}") from None
    if arr.ndim != 0 or arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be a real scalar [{unit}]; got {value!r}")
    v = float(arr)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite [{unit}]; got {name} = {v!r}")
    return v



def numeric_array(values, name: str, unit: str) -> np.ndarray:
    """``values`` as an integer or float array; text, booleans, complex numbers and objects
    that are not numbers are a ``ValueError`` naming `name`, never a silent cast."""
    try:
        arr = np.asarray(values)
    except Exception as e:
        raise ValueError(f"{name} could not be converted to an array: {e}") from None
    kind = arr.dtype.kind
    flat = arr.reshape(-1)
    text = kind in "US" or (kind == "O" and any(isinstance(v, (str, bytes)) for v in flat))
    if text:
        first = next((v for v in flat if isinstance(v, (str, bytes, np.str_, np.bytes_))), None)
        raise ValueError(
            f"{name} must be numeric [{unit}]; got text (an array of dtype {arr.dtype}, e.g. "
            f"{str(first)[:40]!r}). Convert the values to numbers first (np.asarray(values, "
            "dtype=float)), or read the file with load_csv, which parses them"
        )
    if kind == "b":
        raise ValueError(f"{name} must be numeric [{unit}]; got a boolean array")
    if kind == "c":
        raise ValueError(f"{name} must be real [{unit}]; got a complex array")
    if kind not in "iuf":
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            bad = next((v for v in flat if not isinstance(v, (int, float, np.number))), None)
            raise ValueError(
                f"{name} must be numeric [{unit}]; got an array of dtype {arr.dtype} holding "
                f"{type(bad).__name__} {bad!r:.40}"
            ) from None
    return arr

