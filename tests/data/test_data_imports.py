"""Layering of blurtrap.data: numpy only; of blurtrap, only the pure-Python blurtrap._constants
(DESIGN sec. 4: blurtrap.physics imports jax, so data may not import it)."""

import ast
from pathlib import Path

import pytest

import blurtrap.data

DATA_DIR = Path(blurtrap.data.__file__).parent
FILES = sorted(DATA_DIR.glob("*.py"))
FORBIDDEN_TOP = {"jax", "jaxlib", "equinox", "optimistix", "matplotlib", "emcee"}
ALLOWED_RELATIVE = {"_constants"}  # from .._constants import ...


def imports(path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield 0, a.name
        elif isinstance(node, ast.ImportFrom):
            yield node.level, node.module or ""


def test_files_found():
    assert {p.name for p in FILES} >= {"__init__.py", "_recording.py", "_csv.py"}


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_no_forbidden_imports(path):
    for level, module in imports(path):
        top = module.split(".")[0]
        if level == 0:
            assert top not in FORBIDDEN_TOP, f"{path.name} imports {module}"
            if top == "blurtrap":
                assert module.split(".")[1] == "_constants", f"{path.name} imports {module}"
        elif level >= 2:
            assert top in ALLOWED_RELATIVE, f"{path.name} imports {'.' * level}{module}"


def test_public_names():
    for name in [
        "Recording",
        "RecordingSet",
        "load",
        "load_csv",
        "load_manifest",
        "save_manifest",
        "load_npz",
        "save_npz",
        "from_arrays",
    ]:
        assert hasattr(blurtrap.data, name)


def test_using_the_loaders_imports_no_jax(tmp_path):
    """Not only the import: building, saving and loading recordings in every format stays
    numpy only (a fresh interpreter, so that no other test's jax import is seen)."""
    import subprocess
    import sys

    code = f"""
import sys, numpy as np
from pathlib import Path
import blurtrap as bt
from blurtrap.data import from_arrays, load, load_csv, save_manifest, save_npz
tmp = Path({str(tmp_path)!r})
x = np.random.default_rng(0).normal(0, 20.0, (2, 300))
s = from_arrays(x, frame_interval=1e-3, exposure=1e-4, position_unit="nm", times=np.arange(300) * 1e-3)
save_npz(s, tmp / "s.npz"); save_manifest(s, tmp / "m.json")
assert load(tmp / "s.npz") == s and len(load(tmp / "m.json")) == 2
assert load_csv(next(tmp.glob("*.csv")), exposure=1e-4).n_frames == 300
bt.Recording(x[0] * 1e-9, frame_interval=1e-3, exposure=1e-4)
try:
    bt.Recording(x[0], frame_interval=1e-3, exposure=1e-4)
except ValueError:
    pass
bad = sorted(m for m in sys.modules if m.split(".")[0] in {sorted(FORBIDDEN_TOP)!r})
print(bad)
sys.exit(1 if bad else 0)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
