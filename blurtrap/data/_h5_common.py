"""What the HDF5 loaders share: the optional h5py import, opening a file with clear errors,
and listing its datasets (for the messages of ``_h5`` and ``_bluelake``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

H5PY_INSTALL = 'pip install "blurtrap[h5py]"'


def _import_h5py():
    try:
        import h5py
    except ImportError as e:
        raise ImportError(
            "reading HDF5 files needs h5py, an optional dependency of blurtrap; install it with "
            f"{H5PY_INSTALL} (or pip install h5py)"
        ) from e
    return h5py


# -- reading HDF5 -------------------------------------------------------------------------------


def _open(h5py, path: Path):
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return h5py.File(path, "r")
    except OSError as e:
        raise ValueError(f"{path}: cannot be read as an HDF5 file ({e})") from None


def _datasets(h5py, f) -> list[str]:
    out: list[str] = []
    f.visititems(lambda name, obj: out.append(name) if isinstance(obj, h5py.Dataset) else None)
    return out


def _dataset_listing(h5py, f) -> list[str]:
    """``"<name> <shape>"`` for each dataset in the file."""
    return [f"{n} {f[n].shape}" for n in _datasets(h5py, f)]


def _attr_text(value):
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return _attr_text(value.item())
    return value
